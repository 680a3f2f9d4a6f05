"""Model Checking Contest property files (``<property-set xmlns="http://mcc.lip6.fr/">``).

Each MCC query file holds ``<property>`` elements with an ``<id>`` and a ``<formula>``;
`read_properties` turns them into `MccProperty` records whose ``query`` is a
`coral_lang.formula` tree (or, for UpperBounds, a `PlaceBound`), so the same checkers
decide MCC formulas and mission assertions.

Elements read (namespace ``http://mcc.lip6.fr/``, or none):

* path quantifiers and temporal operators: ``all-paths``, ``exists-path``, ``globally``,
  ``finally``, ``next``, ``until`` (with ``before`` and ``reach``);
* boolean connectives: ``negation``, ``conjunction``, ``disjunction``, ``true``,
  ``false``;
* atoms: ``integer-le`` (and the older ``integer-lt``, ``-ge``, ``-gt``, ``-eq``,
  ``-ne``) over ``integer-constant`` and ``tokens-count`` (the sum of the tokens of the
  listed places; a place listed twice counts once), ``is-fireable`` (at least one of
  the listed transitions is enabled), ``deadlock``;
* ``place-bound`` at the root of a formula: an UpperBounds query.

The XML goes through defusedxml's expat driver (no DTD, entities or external
references). Everything is iterative: formulas nest as deep as the file does. Any
fault is an `MccXmlError` naming the file, the line, the element and the property id.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any
from xml.sax import SAXParseException

from defusedxml import DefusedXmlException

from coral_lang.diagnostics import CoralError, did_you_mean
from coral_lang.formula import (
    All,
    And,
    Compare,
    Const,
    Deadlock,
    Exists,
    Finally,
    Fireable,
    Formula,
    Globally,
    IntConst,
    IntExpr,
    Next,
    Not,
    Or,
    Tokens,
    Until,
)
from coral_lang.net import Net
from coral_lang.safexml import SafeExpatParser

__all__ = [
    "MCC_NAMESPACE",
    "MccProperty",
    "MccXmlError",
    "PlaceBound",
    "parse_properties",
    "read_properties",
]

MCC_NAMESPACE = "http://mcc.lip6.fr/"

_COMPARISONS = {
    "integer-le": "<=",
    "integer-lt": "<",
    "integer-ge": ">=",
    "integer-gt": ">",
    "integer-eq": "==",
    "integer-ne": "!=",
}
_UNARY = {"negation", "all-paths", "exists-path", "globally", "finally", "next"}
_NARY = {"conjunction", "disjunction"}


class MccXmlError(CoralError, ValueError):
    """An MCC property file could not be read.

    The message starts with ``file:line:`` and names the offending element and, when
    known, the property id: not XML, an element coral does not know, a place or
    transition the net does not have, a property without ``<id>`` or ``<formula>``.
    """


@dataclass(frozen=True)
class PlaceBound:
    """UpperBounds query: the most tokens ``places`` hold together in a reachable
    marking."""

    places: tuple[str, ...]

    def __str__(self) -> str:
        return f"bound({', '.join(self.places)})"


@dataclass(frozen=True)
class MccProperty:
    """One ``<property>`` of a query file.

    Attributes:
        id: its ``<id>``, the name the ``FORMULA`` line prints.
        query: the formula, or a `PlaceBound` for UpperBounds.
        line: line of the ``<property>`` element in ``file``.
        file: the file it was read from.
    """

    id: str
    query: Formula | PlaceBound
    line: int
    file: str


@dataclass(slots=True)
class _Element:
    tag: str
    namespace: str
    line: int
    children: list[_Element] = field(default_factory=list)
    chunks: list[str] = field(default_factory=list)

    @property
    def text(self) -> str:
        return "".join(self.chunks).strip()


class _Builder:
    """Element tree with line numbers, straight from expat events."""

    def __init__(self) -> None:
        self.root = _Element("#document", "", 0)
        self.expat: Any = None
        self._stack = [self.root]

    def start(self, name: str, attrs: dict[str, str]) -> None:
        namespace, _, local = name.rpartition(" ")
        element = _Element(local, namespace, self.expat.CurrentLineNumber)
        self._stack[-1].children.append(element)
        self._stack.append(element)

    def end(self, name: str) -> None:
        self._stack.pop()

    def data(self, content: str) -> None:
        self._stack[-1].chunks.append(content)


def read_properties(path: str | os.PathLike[str], net: Net | None = None) -> list[MccProperty]:
    """The properties of an MCC query file, in file order.

    Args:
        path: the ``.xml`` file.
        net: when given, every place and transition named must be one of its.

    Raises:
        MccXmlError: the file cannot be read or is not a valid MCC property file.
    """
    name = os.fspath(path)
    try:
        with open(path, "rb") as handle:
            data = handle.read()
    except OSError as exc:
        raise MccXmlError(f"{name}: cannot read: {exc.strerror or exc}") from None
    return parse_properties(data, name, net)


def parse_properties(
    data: bytes | str, file: str = "<queries>", net: Net | None = None
) -> list[MccProperty]:
    """`read_properties` on a document already in memory (``file`` names it in
    messages)."""
    root = _parse_xml(data, file)
    return _Reader(file, net).read(root)


def _parse_xml(data: bytes | str, file: str) -> _Element:
    builder = _Builder()
    parser = SafeExpatParser(builder)
    try:
        parser.feed(data)
        parser.close()
    except SAXParseException as exc:
        raise MccXmlError(
            f"{file}:{exc.getLineNumber()}: not well-formed XML: {exc.getMessage()}"
        ) from None
    except DefusedXmlException as exc:
        raise MccXmlError(
            f"{file}:{parser.getLineNumber()}: refused unsafe XML construct: {exc}"
        ) from None
    except RecursionError:  # pragma: no cover - expat itself does not recurse
        raise MccXmlError(f"{file}: the XML nests too deeply") from None
    if not builder.root.children:
        raise MccXmlError(f"{file}: empty document")
    return builder.root.children[0]


class _Reader:
    def __init__(self, file: str, net: Net | None) -> None:
        self.file = file
        self.places = None if net is None else set(net.place_names)
        self.transitions = None if net is None else {t.name for t in net.transitions}
        self.property_id = ""

    def error(self, element: _Element, message: str) -> MccXmlError:
        where = f" (property '{self.property_id}')" if self.property_id else ""
        return MccXmlError(f"{self.file}:{element.line}: {message}{where}")

    def read(self, root: _Element) -> list[MccProperty]:
        self.check_namespace(root)
        if root.tag != "property-set":
            raise self.error(root, f"root element is <{root.tag}>, expected <property-set>")
        out: list[MccProperty] = []
        seen: dict[str, int] = {}
        for element in root.children:
            if element.tag != "property":
                raise self.error(element, f"unexpected <{element.tag}> in <property-set>")
            prop = self.read_property(element)
            if prop.id in seen:
                raise self.error(
                    element, f"duplicate property id '{prop.id}' (first on line {seen[prop.id]})"
                )
            seen[prop.id] = prop.line
            out.append(prop)
        return out

    def check_namespace(self, element: _Element) -> None:
        if element.namespace not in ("", MCC_NAMESPACE):
            raise self.error(
                element,
                f"<{element.tag}> is in namespace '{element.namespace}', expected"
                f" '{MCC_NAMESPACE}'",
            )

    def read_property(self, element: _Element) -> MccProperty:
        self.property_id = ""
        ids = [c for c in element.children if c.tag == "id"]
        if not ids or not ids[0].text:
            raise self.error(element, "<property> has no <id>")
        self.property_id = ids[0].text
        formulas = [c for c in element.children if c.tag == "formula"]
        if len(formulas) != 1:
            what = "no <formula>" if not formulas else "more than one <formula>"
            raise self.error(element, f"<property> has {what}")
        body = self.only_child(formulas[0])
        query: Formula | PlaceBound
        if body.tag == "place-bound":
            query = PlaceBound(self.names(body, "place"))
        else:
            query = self.formula(body)
        prop = MccProperty(self.property_id, query, element.line, self.file)
        self.property_id = ""
        return prop

    def only_child(self, element: _Element) -> _Element:
        if len(element.children) != 1:
            raise self.error(
                element,
                f"<{element.tag}> must hold exactly one element, not {len(element.children)}",
            )
        return element.children[0]

    def names(self, element: _Element, tag: str) -> tuple[str, ...]:
        """The distinct ``<place>``/``<transition>`` names listed under ``element``."""
        known = self.places if tag == "place" else self.transitions
        found: list[str] = []
        for child in element.children:
            if child.tag != tag:
                raise self.error(child, f"unexpected <{child.tag}> in <{element.tag}>")
            name = child.text
            if not name:
                raise self.error(child, f"empty <{tag}> in <{element.tag}>")
            if known is not None and name not in known:
                raise self.error(
                    child, f"unknown {tag} '{name}' in <{element.tag}>{did_you_mean(name, known)}"
                )
            if name not in found:
                found.append(name)
        if not found:
            raise self.error(element, f"<{element.tag}> lists no <{tag}>")
        return tuple(found)

    def formula(self, top: _Element) -> Formula:
        """Post-order, with an explicit stack: no recursion however deep the file."""
        done: dict[int, Formula | IntExpr] = {}
        stack: list[tuple[_Element, bool]] = [(top, False)]
        while stack:
            element, expanded = stack.pop()
            if not expanded:
                self.check_namespace(element)
                stack.append((element, True))
                stack.extend((c, False) for c in reversed(self.operands(element)))
                continue
            done[id(element)] = self.build(element, done)
        result = done[id(top)]
        if isinstance(result, Tokens | IntConst):
            raise self.error(top, f"<{top.tag}> is an integer, not a formula")
        return result

    def operands(self, element: _Element) -> list[_Element]:
        """The child elements ``build`` needs built first."""
        tag = element.tag
        if tag in _UNARY:
            return [self.only_child(element)]
        if tag in _NARY:
            if not element.children:
                raise self.error(element, f"<{tag}> has no operand")
            return element.children
        if tag in _COMPARISONS:
            if len(element.children) != 2:
                raise self.error(element, f"<{tag}> needs two operands")
            return element.children
        if tag == "until":
            parts = {c.tag: c for c in element.children}
            if sorted(parts) != ["before", "reach"] or len(element.children) != 2:
                raise self.error(element, "<until> needs one <before> and one <reach>")
            return [self.only_child(parts["before"]), self.only_child(parts["reach"])]
        if tag in ("is-fireable", "tokens-count", "integer-constant", "deadlock", "true", "false"):
            return []
        if tag == "place-bound":
            raise self.error(element, "<place-bound> must be the whole formula")
        raise self.error(element, f"unknown element <{tag}>")

    def build(self, element: _Element, done: dict[int, Formula | IntExpr]) -> Formula | IntExpr:
        tag = element.tag
        if tag == "integer-constant":
            return self.integer(element)
        if tag == "tokens-count":
            return Tokens(tuple((p, 1) for p in self.names(element, "place")))
        if tag == "is-fireable":
            return Fireable(self.names(element, "transition"))
        if tag == "deadlock":
            return Deadlock()
        if tag in ("true", "false"):
            return Const(tag == "true")
        args = [done[id(c)] for c in self.operands(element)]
        if tag in _COMPARISONS:
            left, right = args
            for operand, child in zip(args, element.children, strict=True):
                if not isinstance(operand, Tokens | IntConst):
                    raise self.error(child, f"<{child.tag}> is a formula, not an integer")
            assert isinstance(left, Tokens | IntConst) and isinstance(right, Tokens | IntConst)
            return Compare(left, _COMPARISONS[tag], right)
        subs = list(self.formulas(element, args))
        if tag == "negation":
            return Not(subs[0])
        if tag == "conjunction":
            return And(tuple(subs))
        if tag == "disjunction":
            return Or(tuple(subs))
        if tag == "all-paths":
            return All(subs[0])
        if tag == "exists-path":
            return Exists(subs[0])
        if tag == "globally":
            return Globally(subs[0])
        if tag == "finally":
            return Finally(subs[0])
        if tag == "next":
            return Next(subs[0])
        assert tag == "until"
        return Until(subs[0], subs[1])

    def formulas(self, element: _Element, args: Sequence[Formula | IntExpr]) -> Iterator[Formula]:
        for arg, child in zip(args, self.operands(element), strict=True):
            if isinstance(arg, Tokens | IntConst):
                raise self.error(child, f"<{child.tag}> is an integer, not a formula")
            yield arg

    def integer(self, element: _Element) -> IntConst:
        text = element.text
        try:
            value = int(text, 10)
        except ValueError:
            raise self.error(element, f"<integer-constant> '{text}' is not an integer") from None
        return IntConst(value)
