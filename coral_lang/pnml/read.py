"""Reading PNML: a P/T net out of a document another tool wrote.

Defensive because the files come from other people's tools: the XML goes through the
hardened parser (`coral_lang.safexml`: no DTD, no entity expansion, no external
references), and every fault is a `PnmlError` naming the file, line, column, element and
id. Positions come from expat events, since ElementTree keeps none; that is why this
side builds its own small element tree instead of using ``xml.etree``.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar
from xml.sax import SAXParseException

from defusedxml import DefusedXmlException, DTDForbidden, EntitiesForbidden

from coral_lang.diagnostics import PnmlError, Span, did_you_mean
from coral_lang.gcpause import cyclic_gc_paused
from coral_lang.net import (
    MAX_INPUTS,
    Assertion,
    AssertKind,
    Command,
    FinalMarking,
    Net,
    NetError,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
    Value,
)
from coral_lang.pnml.common import CORAL_TOOL, CORAL_TOOL_VERSION, PTNET_TYPE
from coral_lang.safefile import PNML_LIMIT, UnreadableFile, read_file_bytes
from coral_lang.safexml import SafeExpatParser

__all__ = ["parse_pnml", "read_pnml"]

# Other net types people try to feed us, so the refusal can say what the file is.
_KNOWN_TYPES = {
    "http://www.pnml.org/version-2009/grammar/symmetricnet": "a symmetric (coloured) net",
    "http://www.pnml.org/version-2009/grammar/highlevelnet": "a high-level (coloured) net",
    "http://www.pnml.org/version-2009/grammar/pt-hlpng": "a P/T net in high-level notation",
}
# Elements that only high-level (coloured) nets have; a ptnet holding one is mislabelled.
_HIGH_LEVEL = frozenset(
    {"declaration", "declarations", "hlinitialMarking", "hlinscription", "condition"}
)
_INTEGER = re.compile(r"[+-]?[0-9]{1,19}", re.ASCII)
"""At most 19 digits: every count and weight fits in 64 bits (a 5,000-digit one would
make ``int()`` raise, far past the analyses' own 2**63 limit)."""
_Kind = TypeVar("_Kind", PlaceKind, TransitionKind, AssertKind)


@dataclass(slots=True)
class _Element:
    """One XML element with its source position; namespaces are dropped (see docs)."""

    tag: str
    attrs: dict[str, str]
    line: int
    col: int
    children: list[_Element] = field(default_factory=list)
    chunks: list[str] = field(default_factory=list)

    @property
    def text(self) -> str:
        return "".join(self.chunks)

    def child(self, tag: str) -> _Element | None:
        for c in self.children:
            if c.tag == tag:
                return c
        return None

    def describe(self) -> str:
        ident = self.attrs.get("id")
        return f"<{self.tag}> '{ident}'" if ident is not None else f"<{self.tag}>"


class _TreeBuilder:
    """Builds `_Element`s with line numbers from expat events (ElementTree keeps none).

    Foreign ``<toolspecific>`` blocks are skipped whole: they can hold anything, and
    large ones (NUPN unit trees) are not worth keeping in memory.
    """

    def __init__(self) -> None:
        self.root = _Element("#document", {}, 0, 0)
        self.expat: Any = None  # the pyexpat parser, for positions
        self._stack = [self.root]
        self._skip = 0

    def start(self, name: str, attrs: dict[str, str]) -> None:
        if self._skip:
            self._skip += 1
            return
        # Namespaced names arrive as "uri local"; PNML is read by local names only.
        element = _Element(
            name.rpartition(" ")[2],
            {key.rpartition(" ")[2]: value for key, value in attrs.items()},
            self.expat.CurrentLineNumber,
            self.expat.CurrentColumnNumber + 1,
        )
        self._stack[-1].children.append(element)
        self._stack.append(element)
        if element.tag == "toolspecific" and not _is_coral_block(element):
            self._skip = 1

    def end(self, name: str) -> None:
        if self._skip:
            self._skip -= 1
            if self._skip:
                return
        self._stack.pop()

    def data(self, content: str) -> None:
        if not self._skip:
            self._stack[-1].chunks.append(content)


def _is_coral_block(element: _Element) -> bool:
    return (
        element.attrs.get("tool") == CORAL_TOOL
        and element.attrs.get("version") == CORAL_TOOL_VERSION
    )


def read_pnml(path: str | os.PathLike[str], *, net_id: str | None = None) -> Net:
    """Read a PNML file holding a P/T net.

    Args:
        path: The ``.pnml`` file.
        net_id: Which ``<net>`` to read when the file holds several; a file with more
            than one net and no ``net_id`` is refused rather than silently cut short.

    Returns:
        The net; see `parse_pnml` for how PNML maps to `Net`.

    Raises:
        PnmlError: The file cannot be read, is not well-formed or safe XML, is not a P/T
            net, or is inconsistent. The message names the file, line and element.
    """
    try:  # regular files only, at most PNML_LIMIT bytes: never a FIFO or /dev/zero
        data = read_file_bytes(path, PNML_LIMIT)
    except UnreadableFile as e:
        raise PnmlError(f"{e.path}: cannot read: {e.reason}") from None
    return parse_pnml(data, os.fspath(path), net_id=net_id)


def parse_pnml(data: bytes | str, file: str = "<pnml>", *, net_id: str | None = None) -> Net:
    """Parse PNML text into a `Net`.

    Place and transition ids become `Place.name` / `Transition.name`, ``<name>`` texts
    become their ``label``. Nested pages are flattened in document order; reference
    nodes resolve to the node they refer to; parallel arcs add their weights. Foreign
    ``<toolspecific>`` blocks are ignored, coral's own restore what `to_pnml` stored.

    Args:
        data: The document; bytes are decoded as the XML declaration says, a str is
            taken as already decoded.
        file: Name used in error messages.
        net_id: Which ``<net>`` to read when the document holds several.

    Returns:
        The net, named after the ``<net>`` id.

    Raises:
        PnmlError: On any fault, with ``file:line:col`` and the element at fault.
    """
    # The element tree of a large net is hundreds of thousands of objects without a
    # cycle (children never point back): each collection the allocations trigger would
    # walk all of them, a third of the reading time of a 20,000-place net.
    with cyclic_gc_paused():
        root = _parse_xml(data, file)
        return _Reader(file).read(root, net_id)


def _parse_xml(data: bytes | str, file: str) -> _Element:
    builder = _TreeBuilder()
    parser = SafeExpatParser(builder)
    try:
        parser.feed(data)
        parser.close()
    except SAXParseException as e:
        where = f"{file}:{e.getLineNumber()}:{(e.getColumnNumber() or 0) + 1}"
        raise PnmlError(f"{where}: not well-formed XML: {e.getMessage()}") from None
    except DTDForbidden as e:
        where = f"{file}:{parser.getLineNumber()}"
        system = f" (system id '{e.sysid}')" if e.sysid else ""
        raise PnmlError(
            f"{where}: refused a <!DOCTYPE {e.name}> declaration{system}: PNML needs no DTD,"
            " and DTDs can carry entity bombs and external references"
        ) from None
    except EntitiesForbidden as e:
        raise PnmlError(
            f"{file}:{parser.getLineNumber()}: refused entity declaration '{e.name}'"
        ) from None
    except DefusedXmlException as e:
        raise PnmlError(
            f"{file}:{parser.getLineNumber()}: refused unsafe XML construct: {e}"
        ) from None
    if not builder.root.children:  # expat reports this itself; kept as a safety net
        raise PnmlError(f"{file}: empty document")
    return builder.root.children[0]


class _Reader:
    """Turns the element tree of one PNML document into a `Net`."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.ids: dict[str, _Element] = {}

    def error(self, element: _Element, message: str) -> PnmlError:
        return PnmlError(f"{self.file}:{element.line}:{element.col}: {message}")

    def read(self, root: _Element, net_id: str | None) -> Net:
        if root.tag != "pnml":
            raise self.error(root, f"root element is <{root.tag}>, expected <pnml>")
        nets = [c for c in root.children if c.tag == "net"]
        if not nets:
            raise self.error(root, "no <net> element in <pnml>")
        net = self.select(root, nets, net_id)
        self.check_type(net)
        return self.read_net(net)

    def select(self, root: _Element, nets: list[_Element], net_id: str | None) -> _Element:
        ids = [n.attrs.get("id", "") for n in nets]
        if net_id is None:
            if len(nets) > 1:
                listed = ", ".join(f"'{i}'" for i in ids)
                raise self.error(
                    root,
                    f"the file holds {len(nets)} nets ({listed});"
                    " pass net_id to choose which one to read",
                )
            return nets[0]
        for net, ident in zip(nets, ids, strict=True):
            if ident == net_id:
                return net
        raise self.error(root, f"no <net> with id '{net_id}'{did_you_mean(net_id, ids)}")

    def check_type(self, net: _Element) -> None:
        ident = net.attrs.get("id", "?")
        net_type = net.attrs.get("type")
        if net_type is None:
            raise self.error(net, f"<net> '{ident}' has no type; coral reads '{PTNET_TYPE}'")
        net_type = net_type.strip()
        if net_type != PTNET_TYPE:
            what = _KNOWN_TYPES.get(net_type, "not a P/T net")
            raise self.error(
                net,
                f"<net> '{ident}' has type '{net_type}' ({what});"
                f" coral reads only P/T nets of type '{PTNET_TYPE}'",
            )

    # -- the net ------------------------------------------------------------------------

    def read_net(self, net: _Element) -> Net:
        net_ident = self.require_id(net)
        self.refuse_high_level(net, net)
        nodes = list(self.walk(net))
        for element in nodes:
            if element.tag in _ID_ELEMENTS:
                self.require_id(element)
                self.refuse_high_level(element, net)

        places: dict[str, Place] = {}  # by PNML id
        place_names: set[str] = set()
        transition_elements: list[_Element] = []
        transition_names: dict[str, str] = {}  # PNML id -> Net name
        arcs: list[_Element] = []
        for element in nodes:
            if element.tag == "place":
                place = self.read_place(element)
                if place.name in place_names:
                    raise self.error(element, f"two places are named '{place.name}'")
                place_names.add(place.name)
                places[element.attrs["id"]] = place
            elif element.tag == "transition":
                transition_elements.append(element)
                transition_names[element.attrs["id"]] = self.coral_name(element)
            elif element.tag == "arc":
                arcs.append(element)

        resolved = self.resolve_references(nodes)
        inputs: dict[str, dict[str, int]] = {i: {} for i in transition_names}
        outputs: dict[str, dict[str, int]] = {i: {} for i in transition_names}
        for arc in arcs:
            source, target = self.arc_ends(arc, resolved)
            weight = self.read_weight(arc)
            if source.tag == "place" and target.tag == "transition":
                bucket = inputs[target.attrs["id"]]
                place_name = places[source.attrs["id"]].name
            elif source.tag == "transition" and target.tag == "place":
                bucket = outputs[source.attrs["id"]]
                place_name = places[target.attrs["id"]].name
            else:
                raise self.error(
                    arc,
                    f"<arc> '{arc.attrs['id']}' joins {source.tag} '{source.attrs['id']}'"
                    f" to {target.tag} '{target.attrs['id']}'; an arc must join a place"
                    " and a transition",
                )
            bucket[place_name] = bucket.get(place_name, 0) + weight

        transitions = []
        for element in transition_elements:
            ident = element.attrs["id"]
            transitions.append(
                self.read_transition(
                    element,
                    transition_names[ident],
                    tuple(inputs[ident].items()),
                    tuple(outputs[ident].items()),
                )
            )
        extras = self.read_net_block(net)
        armed = sum(p.kind is PlaceKind.ARMED for p in places.values())
        if armed > MAX_INPUTS:
            raise self.error(
                net,
                f"net '{net_ident}' has {armed} armed places (operator inputs); "
                f"at most {MAX_INPUTS} are supported",
            )
        try:
            return Net(
                name=self.coral_name(net),
                places=tuple(places.values()),
                transitions=tuple(transitions),
                finals=extras.finals,
                assertions=extras.assertions,
                vehicle=extras.vehicle,
                sources=extras.sources,
                requirements=extras.requirements,
            )
        except NetError as e:
            raise self.error(net, f"inconsistent net '{net_ident}': {e}") from None

    def walk(self, net: _Element) -> Iterator[_Element]:
        """Every element under ``net`` that matters, pages flattened in document order.

        Also registers ids, so duplicates are caught wherever they are.
        """
        stack = list(reversed(net.children))
        while stack:
            element = stack.pop()
            if element.tag == "toolspecific":
                continue
            ident = element.attrs.get("id")
            if ident is not None and element.tag in _ID_ELEMENTS:
                first = self.ids.get(ident)
                if first is not None:
                    raise self.error(
                        element,
                        f"duplicate id '{ident}' on <{element.tag}>; first used by"
                        f" <{first.tag}> on line {first.line}",
                    )
                self.ids[ident] = element
            yield element
            if element.tag == "page":
                stack.extend(reversed(element.children))

    def refuse_high_level(self, element: _Element, net: _Element) -> None:
        """Refuse coloured-net content in a net whose type says P/T."""
        for child in element.children:
            if child.tag in _HIGH_LEVEL or (child.tag == "type" and element.tag == "place"):
                raise self.error(
                    child,
                    f"<{child.tag}> in {element.describe()} belongs to high-level (coloured)"
                    f" nets, but <net> '{net.attrs.get('id')}' is typed ptnet;"
                    " coral reads only P/T nets",
                )

    def require_id(self, element: _Element) -> str:
        ident = element.attrs.get("id")
        if ident is None or not ident.strip():
            raise self.error(element, f"<{element.tag}> has no id")
        return ident

    def label(self, element: _Element) -> str:
        name = element.child("name")
        if name is None:
            return ""
        text = name.child("text")
        return "" if text is None else text.text.strip()

    def read_place(self, element: _Element) -> Place:
        ident = element.attrs["id"]
        initial = 0
        marking = element.child("initialMarking")
        if marking is not None:
            initial = self.read_count(marking, f"initial marking of <place> '{ident}'", 0)
        name = self.coral_name(element)
        block = _coral_block(element)
        info = block.child("place") if block is not None else None
        if block is None or info is None:
            return Place(name=name, initial=initial, label=self.label(element))
        return Place(
            name=name,
            initial=initial,
            label=self.label(element),
            kind=self.enum(info, "kind", PlaceKind, PlaceKind.MISSION),
            capacity=self.optional_int(info, "capacity"),
            span=self.span(block),
            resources=self.resources(block),
            pending_of=info.attrs.get("pending-of"),
            complement_of=info.attrs.get("complement-of"),
            armed_of=info.attrs.get("armed-of"),
        )

    def read_transition(
        self,
        element: _Element,
        name: str,
        inputs: tuple[tuple[str, int], ...],
        outputs: tuple[tuple[str, int], ...],
    ) -> Transition:
        label = self.label(element)
        block = _coral_block(element)
        info = block.child("transition") if block is not None else None
        if block is None or info is None:
            return Transition(name=name, inputs=inputs, outputs=outputs, label=label)
        return Transition(
            name=name,
            inputs=inputs,
            outputs=outputs,
            label=label,
            kind=self.enum(info, "kind", TransitionKind, TransitionKind.PLAIN),
            priority=self.optional_int(info, "priority") or 0,
            span=self.span(block),
            command=self.command(block),
            pending=info.attrs.get("pending"),
            reply_to=info.attrs.get("reply-to"),
            reply=info.attrs.get("reply"),
            operator_input=info.attrs.get("operator-input"),
        )

    def read_count(self, element: _Element, what: str, minimum: int) -> int:
        text = element.child("text")
        if text is None:
            raise self.error(element, f"{what} has no <text>")
        raw = text.text.strip()
        if not _INTEGER.fullmatch(raw):
            raise self.error(text, f"{what} is '{_short(raw)}', not an integer below 2**63")
        value = int(raw)
        if value >= 2**63:
            raise self.error(text, f"{what} is {value}: it must be below 2**63")
        if value < minimum:
            if minimum == 0:
                raise self.error(text, f"{what} is {value}: it must not be negative")
            raise self.error(text, f"{what} is {value}: it must be at least {minimum}")
        return value

    def read_weight(self, arc: _Element) -> int:
        ident = arc.attrs["id"]
        arc_type = arc.attrs.get("type")
        type_element = arc.child("type")
        if type_element is not None:
            text = type_element.child("text")
            arc_type = type_element.attrs.get("value") or (text.text if text is not None else "")
        if arc_type is not None and arc_type.strip().lower() not in ("normal", ""):
            raise self.error(
                arc if type_element is None else type_element,
                f"<arc> '{ident}' is of type '{arc_type.strip()}'; coral reads only normal"
                " arcs (no inhibitor, reset, read or other arc extensions)",
            )
        inscription = arc.child("inscription")
        if inscription is None:
            return 1
        return self.read_count(inscription, f"weight of <arc> '{ident}'", 1)

    def resolve_references(self, nodes: list[_Element]) -> dict[str, _Element]:
        """Map every node id, reference nodes included, to the place or transition.

        One pass: each reference chain is walked once and every reference on it remembers
        where it ends, so a later reference stops at the first one already resolved (a
        chain of n references costs n steps, not n^2). Errors are reported in document
        order, at the same node as a walk of each chain from its start would find them.
        """
        resolved: dict[str, _Element] = {}
        for element in nodes:
            if element.tag in ("place", "transition"):
                resolved[element.attrs["id"]] = element
        ends: dict[str, _Element] = {}  # reference id -> the place or transition it reaches
        for element in nodes:
            if element.tag not in ("referencePlace", "referenceTransition"):
                continue
            current = self.reference_end(element, ends)
            wanted = "place" if element.tag == "referencePlace" else "transition"
            if current.tag != wanted:
                raise self.error(
                    element,
                    f"{element.describe()} refers to {current.tag} '{current.attrs['id']}';"
                    f" it must refer to a {wanted}",
                )
            resolved[element.attrs["id"]] = current
        return resolved

    def reference_end(self, element: _Element, ends: dict[str, _Element]) -> _Element:
        """The place or transition the chain of references from ``element`` reaches;
        every reference walked is added to ``ends``."""
        path = [element.attrs["id"]]
        on_path = {path[0]: 0}
        current = element
        while current.tag in ("referencePlace", "referenceTransition"):
            known = ends.get(current.attrs["id"])
            if known is not None:
                current = known
                break
            ref = current.attrs.get("ref")
            if ref is None:
                raise self.error(current, f"{current.describe()} has no ref")
            target = self.ids.get(ref)
            if target is None or target.tag not in _NODE_TAGS:
                nodes_ids = [i for i, e in self.ids.items() if e.tag in _NODE_TAGS]
                raise self.error(
                    current,
                    f"{current.describe()} refers to unknown node '{ref}'"
                    f"{did_you_mean(ref, nodes_ids)}",
                )
            if ref in on_path:
                raise self.error(
                    element,
                    f"{element.describe()} is part of a reference cycle "
                    f"{_cycle_text([*path, ref])}",
                )
            on_path[ref] = len(path)
            path.append(ref)
            current = target
        for ident in path:
            if ident != current.attrs["id"]:  # every other id on the path is a reference
                ends[ident] = current
        return current

    def arc_ends(self, arc: _Element, resolved: dict[str, _Element]) -> tuple[_Element, _Element]:
        ends = []
        for end in ("source", "target"):
            ref = arc.attrs.get(end)
            if ref is None:
                raise self.error(arc, f"<arc> '{arc.attrs['id']}' has no {end}")
            node = resolved.get(ref)
            if node is None:
                raise self.error(
                    arc,
                    f"<arc> '{arc.attrs['id']}' has {end} '{ref}', an unknown id"
                    f"{did_you_mean(ref, resolved)}",
                )
            ends.append(node)
        return ends[0], ends[1]

    # -- coral's own blocks -----------------------------------------------------------------

    def coral_name(self, element: _Element) -> str:
        """The Net name: the one `to_pnml` stored when it had to sanitise the id."""
        block = _coral_block(element)
        if block is not None:
            named = block.child("name")
            if named is not None and "value" in named.attrs:
                return named.attrs["value"]
        return element.attrs["id"]

    def optional_int(self, element: _Element, attribute: str) -> int | None:
        raw = element.attrs.get(attribute)
        if raw is None:
            return None
        if not _INTEGER.fullmatch(raw.strip()):
            raise self.error(
                element,
                f"coral <{element.tag}> {attribute} '{_short(raw)}' is not an integer below 2**63",
            )
        value = int(raw)
        if value >= 2**63:
            raise self.error(element, f"coral <{element.tag}> {attribute} must be below 2**63")
        return value

    def required(self, element: _Element, attribute: str) -> str:
        raw = element.attrs.get(attribute)
        if raw is None:
            raise self.error(element, f"coral <{element.tag}> has no {attribute}")
        return raw

    def enum(self, element: _Element, attribute: str, kind: type[_Kind], default: _Kind) -> _Kind:
        raw = element.attrs.get(attribute)
        if raw is None:
            return default
        try:
            return kind(raw)
        except ValueError:
            choices = ", ".join(k.value for k in kind)
            raise self.error(
                element, f"coral <{element.tag}> {attribute} '{raw}' is not one of {choices}"
            ) from None

    def span(self, block: _Element) -> Span | None:
        element = block.child("span")
        if element is None:
            return None
        numbers = []
        for attribute in ("line", "col", "end-line", "end-col"):
            value = self.optional_int(element, attribute)
            if value is None:
                raise self.error(element, f"coral <span> has no {attribute}")
            numbers.append(value)
        return Span(self.required(element, "file"), *numbers)

    def resources(self, block: _Element) -> tuple[str, ...]:
        return tuple(self.required(c, "name") for c in block.children if c.tag == "resource")

    def tokens(self, element: _Element) -> tuple[tuple[str, int], ...]:
        result = []
        for child in element.children:
            if child.tag == "tokens":
                count = self.optional_int(child, "count")
                result.append((self.required(child, "place"), 1 if count is None else count))
        return tuple(result)

    def command(self, block: _Element) -> Command | None:
        element = block.child("command")
        if element is None:
            return None
        params: list[tuple[str, Value]] = []
        for child in element.children:
            if child.tag == "param":
                params.append((self.required(child, "name"), self.value(child)))
        return Command(
            system=self.required(element, "system"),
            name=self.required(element, "name"),
            params=tuple(params),
            resources=self.resources(element),
            replies=tuple(self.required(c, "kind") for c in element.children if c.tag == "reply"),
        )

    def value(self, element: _Element) -> Value:
        raw = self.required(element, "value")
        kind = element.attrs.get("type", "str")
        try:
            if kind == "int":
                return int(raw)
            if kind == "float":
                return float(raw)
            if kind == "bool":
                return raw == "true"
        except ValueError:
            raise self.error(element, f"coral <param> value '{raw}' is not a {kind}") from None
        if kind != "str":
            raise self.error(element, f"coral <param> has unknown type '{kind}'")
        return raw

    def read_net_block(self, net: _Element) -> _NetExtras:
        block = _coral_block(net)
        if block is None:
            return _NetExtras()
        vehicle = block.child("vehicle")
        finals = []
        assertions = []
        requirements: dict[str, None] = {}
        for child in block.children:
            if child.tag == "require":
                requirements[self.requirement(child)] = None
            elif child.tag == "final":
                finals.append(FinalMarking(self.tokens(child), self.span(child)))
            elif child.tag == "assertion":
                kind = self.enum(child, "kind", AssertKind, AssertKind.NEVER)
                if kind in (AssertKind.LTL, AssertKind.CTL):
                    raise self.error(
                        child,
                        f"coral <assertion> of kind '{kind.value}' has no formula: "
                        "temporal assertions are not carried in PNML",
                    )
                assertions.append(
                    Assertion(
                        kind=kind,
                        places=self.tokens(child),
                        bound=self.optional_int(child, "bound"),
                        span=self.span(child),
                        deadline_s=self.deadline(child, kind),
                    )
                )
        return _NetExtras(
            vehicle=None if vehicle is None else self.required(vehicle, "name"),
            sources=tuple(self.required(c, "path") for c in block.children if c.tag == "source"),
            finals=tuple(finals),
            assertions=tuple(assertions),
            requirements=tuple(requirements),
        )

    def deadline(self, element: _Element, kind: AssertKind) -> float | None:
        """The ``deadline-s`` of a ``within`` assertion (seconds, finite, above 0), which
        it must have and no other kind may: a deadline read as absent would make the
        assertion mean something else, so a fault is refused, never dropped."""
        raw = element.attrs.get("deadline-s")
        if kind is not AssertKind.WITHIN:
            if raw is not None:
                raise self.error(
                    element,
                    f"coral <assertion> of kind '{kind.value}' has a deadline-s: "
                    "only 'within' takes one",
                )
            return None
        if raw is None:
            raise self.error(element, "coral <assertion> of kind 'within' has no deadline-s")
        try:
            seconds = float(raw)
        except ValueError:
            seconds = math.nan
        if not (math.isfinite(seconds) and seconds > 0):
            raise self.error(
                element,
                f"coral <assertion> deadline-s '{_short(raw)}' is not a number of seconds above 0",
            )
        return seconds

    def requirement(self, element: _Element) -> str:
        """A ``require`` line's name, refused unless the compiler knows it: a certificate
        must prove each one, so a name nothing can prove is an error, not a no-op."""
        from coral_lang.compiler import REQUIREMENTS  # only for the rare net that has one

        name = self.required(element, "name")
        if name not in REQUIREMENTS:
            raise self.error(
                element,
                f"coral <require> names unknown requirement '{_short(name)}'"
                f"{did_you_mean(name, REQUIREMENTS)}; known: {', '.join(REQUIREMENTS)}",
            )
        return name


_NODE_TAGS = frozenset({"place", "transition", "referencePlace", "referenceTransition"})


def _cycle_text(chain: list[str]) -> str:
    """``a -> b -> a``; a long cycle shows its start and end and how many nodes it has."""
    if len(chain) <= 10:
        return " -> ".join(chain)
    return f"{' -> '.join([*chain[:4], '...', *chain[-3:]])} ({len(chain) - 1} references)"


_ID_ELEMENTS = _NODE_TAGS | {"arc", "page"}


@dataclass(frozen=True)
class _NetExtras:
    vehicle: str | None = None
    sources: tuple[str, ...] = ()
    finals: tuple[FinalMarking, ...] = ()
    assertions: tuple[Assertion, ...] = ()
    requirements: tuple[str, ...] = ()


def _coral_block(element: _Element) -> _Element | None:
    for child in element.children:
        if child.tag == "toolspecific" and _is_coral_block(child):
            return child
    return None


def _short(raw: str) -> str:
    """``raw`` cut to a readable length for a message."""
    return raw if len(raw) <= 40 else raw[:37] + "..."
