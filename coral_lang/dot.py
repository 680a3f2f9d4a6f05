"""Graphviz DOT export of a `Net`, for pictures of missions and counterexamples.

Places are circles holding their tokens, transitions are boxes saying what they do
(command transitions the command they send, reply transitions the reply they stand
for), arcs carry their weight when it is above 1. A marking other than the initial one
can be drawn, and a set of places and transitions highlighted, so one picture per step
of a counterexample shows where the tokens are and what fired.

The output is deterministic (nets are drawn in declaration order, node ids are
positions), so it can be compared in tests and diffed between runs. Render it with
``dot -Tsvg net.dot -o net.svg``.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

from coral_lang.net import Net, Place, PlaceKind, Transition, TransitionKind

__all__ = ["HIGHLIGHT_COLOR", "to_dot"]

HIGHLIGHT_COLOR = "red"
OPERATOR_COLOR = "lightgoldenrod1"
"""Fill of operator inputs (INPUT transitions) and their armed places: the operator,
not the engine or the vehicle, moves these tokens."""
_TOKEN = "\u2022"  # a bullet: one drawn token
_MAX_DRAWN_TOKENS = 3  # above this a number reads better than a row of dots


def to_dot(
    net: Net,
    marking: Sequence[int] | Mapping[str, int] | None = None,
    highlight: Collection[str] | None = None,
) -> str:
    """The net as a Graphviz ``digraph``.

    Node ids are ``p<i>`` / ``t<i>`` (positions in `Net.places` / `Net.transitions`),
    so no name ever needs escaping in an id; names appear in labels, escaped.

    Args:
        net: The net to draw.
        marking: Tokens to draw: a full marking aligned with ``net.places``, or a
            ``{place: tokens}`` mapping (unnamed places empty). Default: the initial
            marking.
        highlight: Names of places and transitions to draw in `HIGHLIGHT_COLOR`, e.g.
            the transition a counterexample step fires; arcs of a highlighted
            transition are highlighted too. A name that is both a place and a
            transition highlights both.

    Returns:
        The DOT text, ending with a newline.

    Raises:
        ValueError: ``marking`` does not fit the net, or ``highlight`` names an element
            the net does not have (a stale counterexample, usually).
    """
    tokens = _tokens(net, marking)
    marked = frozenset(highlight or ())
    known = {p.name for p in net.places} | {t.name for t in net.transitions}
    unknown = sorted(marked - known)
    if unknown:
        raise ValueError(f"cannot highlight {unknown}: no such place or transition")

    lines = [
        f"digraph {_quote(net.name)} {{",
        "  rankdir=LR;",
        "  forcelabels=true;",
        '  node [fontname="Helvetica", fontsize=11];',
        '  edge [fontname="Helvetica", fontsize=10];',
    ]
    for i, (place, count) in enumerate(zip(net.places, tokens, strict=True)):
        lines.append(f"  p{i} [{_attrs(_place_attrs(place, count, place.name in marked))}];")
    for i, tr in enumerate(net.transitions):
        lines.append(f"  t{i} [{_attrs(_transition_attrs(tr, tr.name in marked))}];")
    for i, tr in enumerate(net.transitions):
        edge: dict[str, str] = {}
        if tr.name in marked:
            edge = {"color": HIGHLIGHT_COLOR, "penwidth": "2"}
        for name, weight in tr.inputs:
            lines.append(f"  p{net.place_index(name)} -> t{i}{_edge(weight, edge)};")
        for name, weight in tr.outputs:
            lines.append(f"  t{i} -> p{net.place_index(name)}{_edge(weight, edge)};")
    lines.append("}")
    return "\n".join(lines) + "\n"


def _tokens(net: Net, marking: Sequence[int] | Mapping[str, int] | None) -> tuple[int, ...]:
    if marking is None:
        return net.initial_marking()
    if isinstance(marking, Mapping):
        unknown = sorted(set(marking) - set(net.place_names))
        if unknown:
            raise ValueError(f"marking names unknown places {unknown}")
        return net.marking_from(marking)
    values = tuple(marking)
    if len(values) != len(net.places):
        raise ValueError(f"marking has {len(values)} entries, the net {len(net.places)} places")
    return values


def _token_text(count: int) -> str:
    if count <= 0:
        return ""
    if count <= _MAX_DRAWN_TOKENS:
        return _TOKEN * count
    return str(count)


def _place_attrs(place: Place, count: int, highlighted: bool) -> dict[str, str]:
    # The name sits outside the circle (xlabel) so long names do not inflate it.
    attrs = {
        "shape": "circle",
        "fixedsize": "true",
        "width": "0.5",
        "label": _token_text(count),
        "xlabel": place.name,
        "tooltip": _tooltip(place.name, place.label, place.kind.value),
    }
    if place.kind is PlaceKind.PENDING:
        attrs["style"] = "dashed"  # a command in flight: the vehicle, not the net, moves it
    elif place.kind is PlaceKind.COMPLEMENT:
        attrs["style"] = "dotted"
    elif place.kind is PlaceKind.ARMED:
        # the operator may still give its input: drawn in the operator's colour
        attrs.update(style="filled", fillcolor=OPERATOR_COLOR)
    if highlighted:
        attrs.update(color=HIGHLIGHT_COLOR, penwidth="2", fontcolor=HIGHLIGHT_COLOR)
    return attrs


def _transition_attrs(tr: Transition, highlighted: bool) -> dict[str, str]:
    label = tr.describe()
    if tr.priority:
        label += f"\n[priority {tr.priority}]"
    styles = []
    if tr.kind is TransitionKind.REPLY:
        styles.append("rounded")  # fired by the vehicle's answer, not by the engine
    attrs = {
        "shape": "box",
        "label": label,
        "tooltip": _tooltip(tr.name, tr.label, tr.kind.value),
    }
    if tr.kind is TransitionKind.INPUT:
        styles.append("filled")  # fired by the operator, not by the engine
        attrs["fillcolor"] = OPERATOR_COLOR
    if highlighted:
        styles.append("filled")
        attrs.update(color=HIGHLIGHT_COLOR, penwidth="2", fillcolor="mistyrose")
    if styles:
        attrs["style"] = ",".join(styles)
    return attrs


def _tooltip(name: str, label: str, kind: str) -> str:
    shown = name if not label or label == name else f"{name} ({label})"
    return f"{shown} [{kind}]"


def _edge(weight: int, extra: dict[str, str]) -> str:
    attrs = dict(extra)
    if weight > 1:
        attrs["label"] = str(weight)
    return f" [{_attrs(attrs)}]" if attrs else ""


def _attrs(attrs: dict[str, str]) -> str:
    return ", ".join(f"{key}={_quote(value)}" for key, value in attrs.items())


def _quote(text: str) -> str:
    """A DOT double-quoted string whose label shows ``text`` literally.

    Backslashes are doubled so Graphviz does not read ``\\n``, ``\\N`` or ``\\G`` in a
    name as an escape; line breaks become ``\\n``, the one escape we mean.
    """
    escaped = text.replace("\\", "\\\\").replace('"', '\\"')
    escaped = escaped.replace("\r\n", "\n").replace("\r", "\n").replace("\n", "\\n")
    return f'"{escaped}"'
