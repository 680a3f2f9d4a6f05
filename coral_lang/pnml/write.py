"""Writing PNML: any `Net` as a standard single-page ptnet document.

The document is built as an ``xml.etree`` element tree and serialised by it, so the
escaping of text and attributes is the library's, not ours; `ET.indent` lays it out.
Two things the library does not do are done here: refusing characters XML 1.0 cannot
carry at all (a ``\\x00`` in a name is a `PnmlError`, not a file no tool can read), and
keeping a carriage return in a label as one (serialised text keeps it raw, which every
parser would read back as a line feed).
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable

from coral_lang.diagnostics import PnmlError, Span
from coral_lang.net import (
    Command,
    Net,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
    Value,
)
from coral_lang.pnml.common import CORAL_TOOL, CORAL_TOOL_VERSION, PNML_NAMESPACE, PTNET_TYPE

__all__ = ["to_pnml", "write_pnml"]

# Ids written verbatim: a conservative, ASCII-only subset of XML's NCName that every PNML
# tool accepts. Other names get a sanitised id; their real name rides in a coral block.
_SAFE_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*", re.ASCII)
_UNSAFE_ID_CHAR = re.compile(r"[^A-Za-z0-9_.\-]", re.ASCII)
# Characters XML 1.0 cannot carry at all, not even as character references.
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")

_DECLARATION = '<?xml version="1.0" encoding="UTF-8"?>\n'

Attrs = dict[str, str | int | float | None]
"""Attributes of one element; None leaves the attribute out."""


def write_pnml(net: Net, path: str | os.PathLike[str]) -> None:
    """Write ``net`` as a PNML file (UTF-8); see `to_pnml`.

    Raises:
        PnmlError: A name or label holds a character XML cannot carry.
        OSError: The file cannot be written.
    """
    text = to_pnml(net)
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)


def to_pnml(net: Net) -> str:
    """The net as a standard single-page ptnet PNML document.

    Names that are plain ASCII identifiers (dots and dashes allowed) are used as ids
    unchanged; any other name, or one clashing with another element's id, gets a
    sanitised unique id, and the real name is kept in a coral ``<toolspecific>`` block
    so `parse_pnml` restores it. Weights of 1 and markings of 0 are left implicit, as
    the standard allows.

    Args:
        net: Any net.

    Returns:
        The document, starting with an XML declaration.

    Raises:
        PnmlError: A name or label holds a character XML cannot carry (e.g. ``\\x00``).
    """
    ids = _IdAllocator()
    place_ids = ids.assign([p.name for p in net.places])
    transition_ids = ids.assign([t.name for t in net.transitions])
    net_id = ids.fresh(net.name)
    page_id = ids.fresh("page0")

    # The namespace as a plain attribute: every tag is then written unprefixed.
    root = _element("pnml", {"xmlns": PNML_NAMESPACE})
    net_element = _sub(root, "net", {"id": net_id, "type": PTNET_TYPE})
    _text_child(_sub(net_element, "name"), net.name)
    page = _sub(net_element, "page", {"id": page_id})
    for place, ident in zip(net.places, place_ids, strict=True):
        node = _sub(page, "place", {"id": ident})
        _labelled(node, place.label)
        if place.initial:
            _text_child(_sub(node, "initialMarking"), str(place.initial))
        _attach(node, _place_block(place, ident))
    for tr, ident in zip(net.transitions, transition_ids, strict=True):
        node = _sub(page, "transition", {"id": ident})
        _labelled(node, tr.label)
        _attach(node, _transition_block(tr, ident))
    place_id = dict(zip((p.name for p in net.places), place_ids, strict=True))
    for tr, ident in zip(net.transitions, transition_ids, strict=True):
        arcs = [(place_id[p], ident, w) for p, w in tr.inputs]
        arcs += [(ident, place_id[p], w) for p, w in tr.outputs]
        for source, target, weight in arcs:
            arc_id = ids.fresh(f"{source}-{target}")
            arc = _sub(page, "arc", {"id": arc_id, "source": source, "target": target})
            if weight != 1:
                _text_child(_sub(arc, "inscription"), str(weight))
    _attach(net_element, _net_block(net, net_id))
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    # Attributes already carry "\r" as "&#13;" (ElementTree does it); any raw one left is
    # in text, where a reader would turn it into "\n".
    return _DECLARATION + body.replace("\r", "&#13;") + "\n"


class _IdAllocator:
    """Hands out document-unique XML ids, keeping names as ids whenever it can."""

    def __init__(self) -> None:
        self.used: set[str] = set()

    def assign(self, names: list[str]) -> list[str]:
        # First pass: safe names claim themselves, so a sanitised id never steals one.
        result: list[str | None] = []
        for name in names:
            if _SAFE_ID.fullmatch(name) and name not in self.used:
                self.used.add(name)
                result.append(name)
            else:
                result.append(None)
        return [
            ident if ident is not None else self.fresh(name)
            for ident, name in zip(result, names, strict=True)
        ]

    def fresh(self, wanted: str) -> str:
        base = _UNSAFE_ID_CHAR.sub("_", wanted)
        if not base or not _SAFE_ID.fullmatch(base):
            base = "_" + base
        candidate, n = base, 1
        while candidate in self.used:
            n += 1
            candidate = f"{base}_{n}"
        self.used.add(candidate)
        return candidate


# -- building elements -------------------------------------------------------------------


def _check_xml(value: str) -> str:
    bad = _NOT_XML.search(value)
    if bad is not None:
        raise PnmlError(
            f"cannot write {value!r} to PNML: character {bad.group()!r} is not allowed in XML"
        )
    return value


def _attributes(attrs: Attrs) -> dict[str, str]:
    return {key: _check_xml(str(value)) for key, value in attrs.items() if value is not None}


def _element(tag: str, attrs: Attrs | None = None) -> ET.Element:
    return ET.Element(tag, _attributes(attrs or {}))


def _sub(parent: ET.Element, tag: str, attrs: Attrs | None = None) -> ET.Element:
    return ET.SubElement(parent, tag, _attributes(attrs or {}))


def _text_child(parent: ET.Element, text: str) -> None:
    """``<text>TEXT</text>`` inside ``parent``: how PNML carries every label and count."""
    _sub(parent, "text").text = _check_xml(text)


def _labelled(node: ET.Element, label: str) -> None:
    """``<name><text>LABEL</text></name>``, left out for an empty label."""
    if label:
        _text_child(_sub(node, "name"), label)


def _attach(parent: ET.Element, block: ET.Element | None) -> None:
    if block is not None:
        parent.append(block)


def _block(children: Iterable[ET.Element]) -> ET.Element | None:
    """coral's ``<toolspecific>`` block holding ``children``; None when there are none."""
    block = _element("toolspecific", {"tool": CORAL_TOOL, "version": CORAL_TOOL_VERSION})
    block.extend(children)
    return block if len(block) else None


def _name(name: str, ident: str) -> list[ET.Element]:
    """The real name, when the id had to differ from it."""
    return [] if name == ident else [_element("name", {"value": name})]


def _span(span: Span | None) -> list[ET.Element]:
    if span is None:
        return []
    attrs: Attrs = {
        "file": span.file,
        "line": span.line,
        "col": span.col,
        "end-line": span.end_line,
        "end-col": span.end_col,
    }
    return [_element("span", attrs)]


def _resources(resources: tuple[str, ...]) -> list[ET.Element]:
    return [_element("resource", {"name": r}) for r in resources]


def _tokens(tokens: tuple[tuple[str, int], ...]) -> list[ET.Element]:
    return [_element("tokens", {"place": p, "count": n}) for p, n in tokens]


def _place_block(place: Place, ident: str) -> ET.Element | None:
    children = _name(place.name, ident)
    mission = (
        place.kind is not PlaceKind.MISSION
        or place.capacity is not None
        or place.span is not None
        or place.resources
        or place.pending_of is not None
        or place.complement_of is not None
        or place.armed_of is not None
    )
    if mission:
        attrs: Attrs = {
            "kind": place.kind.value,
            "capacity": place.capacity,
            "pending-of": place.pending_of,
            "complement-of": place.complement_of,
            "armed-of": place.armed_of,
        }
        children.append(_element("place", attrs))
        children += _span(place.span) + _resources(place.resources)
    return _block(children)


def _transition_block(tr: Transition, ident: str) -> ET.Element | None:
    children = _name(tr.name, ident)
    mission = (
        tr.kind is not TransitionKind.PLAIN
        or tr.priority
        or tr.span is not None
        or tr.command is not None
        or tr.pending is not None
        or tr.reply_to is not None
        or tr.reply is not None
        or tr.operator_input is not None
    )
    if mission:
        attrs: Attrs = {
            "kind": tr.kind.value,
            "priority": tr.priority or None,
            "pending": tr.pending,
            "reply-to": tr.reply_to,
            "reply": tr.reply,
            "operator-input": tr.operator_input,
        }
        children.append(_element("transition", attrs))
        children += _span(tr.span)
        if tr.command is not None:
            children.append(_command(tr.command))
    return _block(children)


def _command(command: Command) -> ET.Element:
    element = _element("command", {"system": command.system, "name": command.name})
    for name, value in command.params:
        _sub(element, "param", {"name": name, "type": _value_type(value), "value": _value(value)})
    element.extend(_resources(command.resources))
    for kind in command.replies:
        _sub(element, "reply", {"kind": kind})
    return element


def _value_type(value: Value) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "float"
    return "str"


def _value(value: Value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # repr round-trips every float exactly
    return str(value)


def _net_block(net: Net, ident: str) -> ET.Element | None:
    children = _name(net.name, ident)
    if net.vehicle is not None:
        children.append(_element("vehicle", {"name": net.vehicle}))
    children += [_element("source", {"path": s}) for s in net.sources]
    for final in net.finals:
        element = _element("final")
        element.extend(_span(final.span) + _tokens(final.tokens))
        children.append(element)
    for assertion in net.assertions:
        if assertion.temporal:
            continue  # PNML has no formula syntax: temporal assertions are not exported
        deadline = assertion.deadline_s
        attrs: Attrs = {
            "kind": assertion.kind.value,
            "bound": assertion.bound,
            # seconds, for 'within' only; repr so that the float reads back exactly
            "deadline-s": None if deadline is None else repr(float(deadline)),
        }
        element = _element("assertion", attrs)
        element.extend(_span(assertion.span) + _tokens(assertion.places))
        children.append(element)
    children += [_element("require", {"name": r}) for r in net.requirements]
    return _block(children)
