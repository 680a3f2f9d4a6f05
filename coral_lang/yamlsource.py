"""YAML loading that remembers where each value came from.

Profiles are written by people; a mistake should be reported as
``romeo.yaml:12:9: commands.DEPTH.params[0].max: expected a number``. PyYAML's node
tree carries line marks, so we build plain Python values from it and keep a map from
each value's path to its line and column.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import yaml

from coral_lang.diagnostics import ProfileError, did_you_mean

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


def load_yaml(text: str, file: str) -> YamlDocument:
    """Parse ``text`` safely (plain data only) and record positions of every path."""
    try:
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
    return _scalar(node)


def _scalar(node: yaml.ScalarNode) -> Plain:
    loader = yaml.SafeLoader("")
    try:
        value = loader.construct_object(node, deep=True)
    finally:
        loader.dispose()
    if isinstance(value, str | int | float | bool) or value is None:
        return value
    return str(value)


def expect_keys(
    document: YamlDocument,
    mapping: dict[str, Plain],
    path: str,
    required: Iterable[str],
    optional: Iterable[str],
) -> None:
    """Refuse missing required keys and unknown keys (likely typos) in ``mapping``."""
    required = list(required)
    allowed = set(required) | set(optional)
    for key in required:
        if key not in mapping:
            raise document.error(path, f"missing required field '{key}'")
    for key in mapping:
        if key not in allowed:
            child = f"{path}.{key}" if path else key
            raise document.error(child, f"unknown field '{key}'{did_you_mean(key, allowed)}")
