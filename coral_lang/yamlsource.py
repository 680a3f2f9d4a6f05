"""YAML loading that remembers where each value came from.

Profiles are written by people; a mistake should be reported as
``romeo.yaml:12:9: commands.DEPTH.params[0].max: expected a number``. PyYAML's node
tree carries line marks, so we build plain Python values from it and keep a map from
each value's path to its line and column.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import ParamSpec, TypeVar

import yaml

from coral_lang.diagnostics import ProfileError, did_you_mean

_P = ParamSpec("_P")
_T = TypeVar("_T")

Plain = dict[str, "Plain"] | list["Plain"] | str | int | float | bool | None

# libyaml's parser when PyYAML was built with it: the same nodes and marks, about ten
# times faster than the pure-Python one (the bundled profile is read on every run).
# Its wording of syntax errors differs a little; both name the line and column.
_LOADER: type[yaml.SafeLoader] | type[yaml.CSafeLoader] = getattr(
    yaml, "CSafeLoader", yaml.SafeLoader
)


@dataclass
class YamlDocument:
    """A loaded YAML document plus the source position of every path in it."""

    file: str
    data: Plain
    positions: dict[str, tuple[int, int]] = field(default_factory=dict)

    def error(self, path: str, message: str) -> ProfileError:
        """A `ProfileError` for ``path``, with line and column when known."""
        position = self.positions.get(path)
        where = f"{self.file}:{position[0]}:{position[1]}" if position else self.file
        return ProfileError(where, path, message)


MAX_YAML_CHARS = 1_000_000
"""Largest YAML document (in characters) coral reads: profiles are a few KB."""

MAX_YAML_DEPTH = 100
"""Deepest nesting of mappings and lists accepted; profiles need four or five levels,
and a document nested thousands deep is an attack on the recursive tree builder."""

_STANDARD = "tag:yaml.org,2002:"
_ALLOWED_TAGS = frozenset(
    {None, "!", *(_STANDARD + t for t in ("str", "int", "float", "bool", "null", "map", "seq"))}
)
_INTEGER_LIMIT = 2**63
"""Whole numbers in a profile are bounds and counts; anything this large is a mistake
(and a 5,000-digit one would make Python's int() raise)."""
_MAX_INT_CHARS = 40  # longer than any int below _INTEGER_LIMIT, with signs and underscores


def load_yaml(text: str, file: str) -> YamlDocument:
    """Parse ``text`` safely (plain data only) and record positions of every path.

    Refused, with ``file:line:col``: anchors and aliases (a 1 KB "billion laughs"
    document expands to gigabytes), nesting deeper than `MAX_YAML_DEPTH`, any tag but
    the standard scalar and collection ones (``!!python/name`` and friends are refused,
    not silently read as text), and documents over `MAX_YAML_CHARS` characters.
    """
    if len(text) > MAX_YAML_CHARS:
        raise ProfileError(
            file, "", f"too large: {len(text)} characters (at most {MAX_YAML_CHARS})"
        )
    try:
        _screen(text, file)
        node = yaml.compose(text, Loader=_LOADER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{file}:{mark.line + 1}:{mark.column + 1}" if mark is not None else file
        problem = getattr(exc, "problem", None) or str(exc)
        raise ProfileError(where, "", f"not valid YAML: {problem}") from None
    document = YamlDocument(file=file, data=None)
    if node is None:
        return document
    document.data = _build(node, "", document)
    return document


def _screen(text: str, file: str) -> None:
    """Refuse what `load_yaml` refuses, from the parser's event stream, before any tree.

    The events come from the (iterative) parser: no alias is ever expanded and no deep
    recursion happens before the document is known to be plain, shallow data.
    """
    depth = 0
    for event in yaml.parse(text, Loader=_LOADER):
        mark = event.start_mark
        where = f"{file}:{mark.line + 1}:{mark.column + 1}" if mark is not None else file
        if isinstance(event, yaml.AliasEvent):
            raise ProfileError(
                where, "", f"aliases (*{event.anchor}) are not supported: write the value out"
            )
        if isinstance(event, yaml.NodeEvent) and event.anchor is not None:
            raise ProfileError(
                where, "", f"anchors (&{event.anchor}) are not supported: write values out"
            )
        tag: str | None = getattr(event, "tag", None)
        if tag is not None and tag not in _ALLOWED_TAGS:
            shown = "!!" + tag.removeprefix(_STANDARD) if tag.startswith(_STANDARD) else tag
            raise ProfileError(
                where, "", f"tag '{shown}' is not supported: profiles hold plain data only"
            )
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise ProfileError(where, "", f"nested deeper than {MAX_YAML_DEPTH} levels")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def _build(node: yaml.Node, path: str, document: YamlDocument) -> Plain:
    document.positions[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.MappingNode):
        result: dict[str, Plain] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise document.error(path, "mapping keys must be plain names")
            key = str(key_node.value)
            child = f"{path}.{key}" if path else key
            if key in result:
                document.positions[child] = (
                    key_node.start_mark.line + 1,
                    key_node.start_mark.column + 1,
                )
                raise document.error(child, f"key '{key}' appears twice")
            result[key] = _build(value_node, child, document)
        return result
    if isinstance(node, yaml.SequenceNode):
        return [_build(item, f"{path}[{i}]", document) for i, item in enumerate(node.value)]
    assert isinstance(node, yaml.ScalarNode)
    return _scalar(node, path, document)


def _scalar(node: yaml.ScalarNode, path: str, document: YamlDocument) -> Plain:
    if node.tag == _STANDARD + "int" and len(node.value) > _MAX_INT_CHARS:
        raise document.error(path, f"number too long: {_clip(node.value)}")
    loader = yaml.SafeLoader("")
    try:
        value = loader.construct_object(node, deep=True)
    except (ValueError, OverflowError, yaml.YAMLError) as exc:
        # An impossible date (2001-13-45), a 5,000-digit integer: a message, no traceback.
        reason = getattr(exc, "problem", None) or str(exc).split("\n")[0][:100]
        raise document.error(path, f"cannot read value '{_clip(node.value)}': {reason}") from None
    finally:
        loader.dispose()
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        if not -_INTEGER_LIMIT < value < _INTEGER_LIMIT:
            raise document.error(path, f"number too large: {_clip(node.value)}")
        return value
    if isinstance(value, float):
        if math.isinf(value) and "inf" not in node.value.lower():
            raise document.error(path, f"number out of range: {_clip(node.value)}")
        return value
    return str(value)


def _clip(text: str, width: int = 40) -> str:
    """``text`` cut to ``width`` characters for a message."""
    return text if len(text) <= width else text[:width] + "..."


class Problems:
    """The errors found so far while checking a document.

    A checker runs each independent part through `check`: a part that fails records
    its errors and yields None, and the rest goes on, so one run reports every mistake
    of a profile, not only the first (`raise_any` raises them together). Parts that
    depend on a failed one are skipped rather than reported again.
    """

    def __init__(self) -> None:
        self.errors: list[ProfileError] = []

    def check(self, part: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs) -> _T | None:
        """``part(*args, **kwargs)``, or None with its errors recorded."""
        try:
            return part(*args, **kwargs)
        except ProfileError as exc:
            self.errors.extend(exc.errors)
            return None

    def add(self, error: ProfileError) -> None:
        """Record ``error`` (and those it carries)."""
        self.errors.extend(error.errors)

    def raise_any(self) -> None:
        """Raise one `ProfileError` carrying every error recorded, if there is one."""
        if self.errors:
            raise ProfileError.collected(self.errors)


def expect_keys(
    document: YamlDocument,
    mapping: dict[str, Plain],
    path: str,
    required: Iterable[str],
    optional: Iterable[str],
) -> None:
    """Refuse missing required keys and unknown keys (likely typos) in ``mapping``,
    every one of them in one `ProfileError`."""
    required = list(required)
    allowed = set(required) | set(optional)
    problems = Problems()
    for key in required:
        if key not in mapping:
            problems.add(document.error(path, f"missing required field '{key}'"))
    for key in mapping:
        if key not in allowed:
            child = f"{path}.{key}" if path else key
            problems.add(
                document.error(child, f"unknown field '{key}'{did_you_mean(key, allowed)}")
            )
    problems.raise_any()
