"""A net as an inline SVG picture, for the HTML report.

Two layouts, one markup:

* ``graphviz``: `coral_lang.dot.to_dot` laid out by Graphviz (``dot -Tsvg``), when the
  ``dot`` program is installed; bounded in time (`GRAPHVIZ_TIMEOUT_S`), and not tried
  by ``auto`` on nets where it is known to be slow (`too_large_for_graphviz`);
* ``builtin``: coral's own layered drawing, for machines without Graphviz: columns by
  breadth-first distance from the initially marked places (places and transitions
  alternate), rows ordered by a few barycentre sweeps to untangle arcs, forward arcs
  straight and backward arcs curved below.

Either way the SVG follows the conventions the report's script animates, and has no
ids (a page holds several copies), no external references and no XML prolog::

    <g class="place" data-node="p3">...<text class="tokens">••</text></g>
    <g class="transition" data-node="t5">...</g>
    <g class="arc" data-t="t5" data-p="p3">...</g>

``p<i>`` and ``t<i>`` are positions in `Net.places` and `Net.transitions`.
"""

from __future__ import annotations

import html
import math
import shutil
import subprocess
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from coral_lang.dot import to_dot
from coral_lang.net import Net, PlaceKind, TransitionKind

if TYPE_CHECKING:
    from xml.etree.ElementTree import Element

Layout = Literal["auto", "graphviz", "builtin"]
LAYOUTS: tuple[Layout, ...] = ("auto", "graphviz", "builtin")

MAX_DRAWN_NODES = 400
"""Nets with more places and transitions than this are not drawn: the picture would be
unreadable and, copied once per counterexample, would make the page heavy."""
GRAPHVIZ_TIMEOUT_S = 5.0
"""Seconds ``auto`` gives Graphviz before falling back to the built-in layout: a report
must not hang on a drawing (``dot`` took 11 s on Dekker-PT-010, 120 transitions and
820 arcs, and over 40 s on PhilosophersDyn-PT-03)."""
FORCED_GRAPHVIZ_TIMEOUT_S = 60.0
"""Seconds ``graphviz`` (asked for by name) gives it: the user chose to wait."""
AUTO_GRAPHVIZ_MAX_TRANSITIONS = 80
AUTO_GRAPHVIZ_MAX_ARCS = 400
"""Above either size ``auto`` uses the built-in layout without trying Graphviz. Measured
with Graphviz 2.43 on the conformance nets (``dot -Tsvg`` on `coral_lang.dot.to_dot`):
up to 80 transitions and 400 arcs every net took under 2 s (the pool mission, 79
transitions and 58 places, 0.08 s); DrinkVendingMachine-PT-02 (72 transitions, 440 arcs)
took 18.7 s, TokenRing-PT-005 (156, 624) 6.7 s, Dekker-PT-010 (120, 820) 10.9 s.
Arcs (crossings to minimise) drive the time more than nodes do."""
TOKEN = "\u2022"
MAX_DRAWN_TOKENS = 3  # above this a number reads better than a row of dots

_XLINK_TITLE = "{http://www.w3.org/1999/xlink}title"


@dataclass(frozen=True)
class NetDrawing:
    """A drawing of a net.

    Attributes:
        svg: An ``<svg>`` element to inline in HTML; empty when the net was not drawn.
        layout: ``graphviz``, ``builtin``, or ``none`` (not drawn).
        note: Why the layout asked for was not used, or why nothing was drawn.
    """

    svg: str
    layout: str
    note: str = ""


def token_text(count: int) -> str:
    """Tokens as drawn in a place: up to three dots, then a number; empty for none."""
    if count <= 0:
        return ""
    return TOKEN * count if count <= MAX_DRAWN_TOKENS else str(count)


def graphviz_available(program: str = "dot") -> bool:
    """Whether Graphviz's ``program`` is on the PATH."""
    return shutil.which(program) is not None


def too_large_for_graphviz(net: Net) -> str:
    """Why ``auto`` does not try Graphviz on ``net`` (empty when it does)."""
    transitions, arcs = len(net.transitions), net.arc_count
    if transitions > AUTO_GRAPHVIZ_MAX_TRANSITIONS:
        return f"{transitions} transitions, over {AUTO_GRAPHVIZ_MAX_TRANSITIONS}"
    if arcs > AUTO_GRAPHVIZ_MAX_ARCS:
        return f"{arcs} arcs, over {AUTO_GRAPHVIZ_MAX_ARCS}"
    return ""


def draw_net(
    net: Net,
    layout: Layout = "auto",
    *,
    dot_program: str = "dot",
    timeout_s: float | None = None,
) -> NetDrawing:
    """Draw ``net`` with its initial marking.

    Args:
        net: The net.
        layout: ``graphviz`` (Graphviz whatever the size), ``builtin``, or ``auto``
            (Graphviz when installed and the net is small enough for it to be quick,
            `too_large_for_graphviz`).
        dot_program: The Graphviz program to run.
        timeout_s: Seconds Graphviz may take before the built-in layout is used
            (default `GRAPHVIZ_TIMEOUT_S`, or `FORCED_GRAPHVIZ_TIMEOUT_S` for
            ``graphviz``).

    Returns:
        The drawing; when Graphviz was asked for but is missing, fails or takes too
        long, the built-in layout, with a note saying why.
    """
    nodes = len(net.places) + len(net.transitions)
    if nodes > MAX_DRAWN_NODES:
        return NetDrawing(
            "", "none", f"not drawn: {nodes} places and transitions, over {MAX_DRAWN_NODES}"
        )
    if timeout_s is None:
        timeout_s = FORCED_GRAPHVIZ_TIMEOUT_S if layout == "graphviz" else GRAPHVIZ_TIMEOUT_S
    note = ""
    large = too_large_for_graphviz(net) if layout == "auto" else ""
    if large:
        note = (
            f"Graphviz was not tried ({large}: it can take tens of seconds); "
            "--net-layout graphviz forces it"
        )
    elif layout in ("auto", "graphviz"):
        if graphviz_available(dot_program):
            svg, problem = _graphviz_svg(net, dot_program, timeout_s)
            if svg is not None:
                return NetDrawing(svg, "graphviz")
            note = f"Graphviz failed ({problem}); coral's own layout is shown"
        elif layout == "graphviz":
            note = f"Graphviz ('{dot_program}') is not installed; coral's own layout is shown"
    return NetDrawing(_builtin_svg(net), "builtin", note)


# -- Graphviz ---------------------------------------------------------------------------


def _graphviz_svg(net: Net, program: str, timeout_s: float) -> tuple[str | None, str]:
    """Graphviz's SVG of the net, rewritten to the report's conventions; or None and
    the reason."""
    # Places are drawn empty: the tokens are our own text elements, so the report's
    # script can change them step by step.
    dot = to_dot(net, marking=[0] * len(net.places))
    try:
        completed = subprocess.run(
            [program, "-Tsvg"],
            input=dot,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return None, f"no layout within {timeout_s:g} s"
    except OSError as exc:
        return None, exc.strerror or str(exc)
    if completed.returncode != 0:
        first = (completed.stderr.strip().splitlines() or ["no message"])[0]
        return None, f"exit code {completed.returncode}: {first}"
    start = completed.stdout.find("<svg")
    if start < 0:
        return None, "no <svg> in its output"
    from defusedxml.ElementTree import fromstring

    root = fromstring(completed.stdout[start:])
    out: list[str] = []
    _write_element(root, net, out)
    return "".join(out), ""


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _children(element: Element) -> list[Element]:
    """Children with Graphviz's tooltip links (``<a xlink:title>``) unwrapped."""
    kept: list[Element] = []
    for child in element:
        if _local(child.tag) == "a":
            kept.extend(_children(child))
        else:
            kept.append(child)
    return kept


def _tooltip(element: Element) -> str:
    for child in element.iter():
        if _local(child.tag) == "a" and _XLINK_TITLE in child.attrib:
            return child.attrib[_XLINK_TITLE]
    return ""


def _write_element(element: Element, net: Net, out: list[str]) -> None:
    tag = _local(element.tag)
    attrs = {
        name: value
        for name, value in element.attrib.items()
        if not name.startswith("{") and name not in ("id", "class")
    }
    children = _children(element)
    extra: list[str] = []
    css = element.attrib.get("class", "")
    title = next((c for c in children if _local(c.tag) == "title"), None)
    key = (title.text or "").strip() if title is not None else ""
    if tag == "svg":
        for size in ("width", "height"):  # points to pixels: three quarters of the size
            if attrs.get(size, "").endswith("pt"):
                attrs[size] = attrs[size][:-2]
        attrs["class"] = "net"
        attrs["role"] = "img"
        attrs["aria-label"] = f"net {net.name}"
    elif css == "node" and key[:1] in ("p", "t") and key[1:].isdigit():
        index = int(key[1:])
        attrs["class"] = "place" if key[0] == "p" else "transition"
        attrs["data-node"] = key
        children = [c for c in children if c is not title]
        tip = _tooltip(element)
        if tip:
            extra.append(f"<title>{html.escape(tip, quote=False)}</title>")
        if key[0] == "p":
            ellipse = next((c for c in element.iter() if _local(c.tag) == "ellipse"), None)
            if ellipse is not None:
                x, y = float(ellipse.attrib["cx"]), float(ellipse.attrib["cy"])
                tokens = token_text(net.places[index].initial)
                extra.append(
                    f'<text class="tokens" x="{x:g}" y="{y + 4:g}" text-anchor="middle" '
                    f'font-size="11">{tokens}</text>'
                )
    elif css == "edge" and "->" in key:
        source, target = key.split("->", 1)
        transition, place = (target, source) if target.startswith("t") else (source, target)
        attrs.update({"class": "arc", "data-t": transition, "data-p": place})
        children = [c for c in children if c is not title]
    elif tag == "title":
        return  # the net's name as a tooltip over the whole drawing: noise
    rendered = " ".join(f'{name}="{html.escape(value)}"' for name, value in attrs.items())
    out.append(f"<{tag}{' ' + rendered if rendered else ''}>")
    out.extend(extra)
    if element.text and element.text.strip():
        out.append(html.escape(element.text, quote=False))
    for child in children:
        _write_element(child, net, out)
    out.append(f"</{tag}>")


# -- built-in layout ------------------------------------------------------------------

OPERATOR_FILL = "#fff2b3"
"""Fill of operator inputs and their armed places (the operator moves those tokens)."""
_R = 16.0  # place radius
_ROW = 64.0  # vertical slot of a node
_GAP = 70.0  # between columns
_BOX_H = 28.0
_CHAR_W = 6.4  # average glyph width at 11 px
_MAX_LABEL = 40
_MAX_NAME = 22

Node = tuple[str, int]  # ("p", i) or ("t", i)


def _label(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "\u2026"


def _layers(net: Net) -> dict[Node, int]:
    """Breadth-first distance from the initially marked places (and the transitions
    that need no token); parts not reached that way start their own search."""
    succ: dict[Node, list[Node]] = {}
    for i, tr in enumerate(net.transitions):
        for place, _ in tr.inputs:
            succ.setdefault(("p", net.place_index(place)), []).append(("t", i))
        for place, _ in tr.outputs:
            succ.setdefault(("t", i), []).append(("p", net.place_index(place)))
    order: list[Node] = [("p", i) for i in range(len(net.places))]
    order += [("t", i) for i in range(len(net.transitions))]
    roots = [("p", i) for i, p in enumerate(net.places) if p.initial > 0]
    roots += [("t", i) for i, t in enumerate(net.transitions) if not t.inputs]
    layer: dict[Node, int] = {}

    def search(starts: Sequence[Node]) -> None:
        queue = deque(starts)
        for start in starts:
            layer[start] = 0
        while queue:
            node = queue.popleft()
            for nxt in succ.get(node, ()):
                if nxt not in layer:
                    layer[nxt] = layer[node] + 1
                    queue.append(nxt)

    search(roots)
    for node in order:
        if node not in layer:
            search([node])
    return layer


def _ordered_columns(net: Net, layer: dict[Node, int]) -> list[list[Node]]:
    """Nodes per column, reordered by barycentre sweeps to shorten and uncross arcs."""
    columns: list[list[Node]] = [[] for _ in range(max(layer.values(), default=-1) + 1)]
    for node in sorted(layer, key=lambda n: (n[0] == "t", n[1])):
        columns[layer[node]].append(node)
    neighbours: dict[Node, list[Node]] = {node: [] for node in layer}
    for i, tr in enumerate(net.transitions):
        for place, _ in (*tr.inputs, *tr.outputs):
            p = ("p", net.place_index(place))
            neighbours[("t", i)].append(p)
            neighbours[p].append(("t", i))
    for sweep in range(4):
        forward = sweep % 2 == 0
        indices = range(1, len(columns)) if forward else range(len(columns) - 2, -1, -1)
        for c in indices:
            ref = columns[c - 1] if forward else columns[c + 1]
            position = {node: k for k, node in enumerate(ref)}
            current = {node: k for k, node in enumerate(columns[c])}

            def weight(
                node: Node,
                position: dict[Node, int] = position,
                current: dict[Node, int] = current,
            ) -> float:
                seen = [position[n] for n in neighbours[node] if n in position]
                return sum(seen) / len(seen) if seen else float(current[node])

            columns[c].sort(key=weight)
    return columns


def _builtin_svg(net: Net) -> str:
    layer = _layers(net)
    columns = _ordered_columns(net, layer)
    width_of: dict[Node, float] = {}
    for node in layer:
        if node[0] == "p":
            width_of[node] = 2 * _R
        else:
            text = _label(net.transitions[node[1]].describe(), _MAX_LABEL)
            width_of[node] = max(40.0, _CHAR_W * len(text) + 16)
    rows = max((len(c) for c in columns), default=1)
    height = rows * _ROW + 30
    centre: dict[Node, tuple[float, float]] = {}
    x = 20.0
    for column in columns:
        span = max((width_of[n] for n in column), default=2 * _R)
        top = (rows - len(column)) * _ROW / 2 + 10
        for k, node in enumerate(column):
            centre[node] = (x + span / 2, top + k * _ROW + _ROW / 2 - 8)
        x += span + _GAP
    width = x - _GAP + 20 if columns else 100.0
    parts = [
        f'<svg class="net" role="img" aria-label="net {html.escape(net.name)}" '
        f'viewBox="0 0 {width:.0f} {height:.0f}" width="{width:.0f}" height="{height:.0f}" '
        'font-family="Helvetica,Arial,sans-serif">'
    ]
    for i, tr in enumerate(net.transitions):
        for name, weight in tr.inputs:
            parts.append(
                _arc(("p", net.place_index(name)), ("t", i), weight, centre, layer, width_of)
            )
        for name, weight in tr.outputs:
            parts.append(
                _arc(("t", i), ("p", net.place_index(name)), weight, centre, layer, width_of)
            )
    for i, place in enumerate(net.places):
        cx, cy = centre[("p", i)]
        dash = ""
        if place.kind is PlaceKind.PENDING:
            dash = ' stroke-dasharray="4 3"'
        elif place.kind is PlaceKind.COMPLEMENT:
            dash = ' stroke-dasharray="1 3"'
        fill = OPERATOR_FILL if place.kind is PlaceKind.ARMED else "white"
        shown = html.escape(_label(place.name, _MAX_NAME), quote=False)
        parts.append(
            f'<g class="place" data-node="p{i}"><title>{html.escape(place.name, quote=False)} '
            f"[{place.kind.value}]</title>"
            f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{_R:g}" fill="{fill}" stroke="black"{dash}/>'
            f'<text class="tokens" x="{cx:.1f}" y="{cy + 4:.1f}" text-anchor="middle" '
            f'font-size="11">{token_text(place.initial)}</text>'
            f'<text class="name" x="{cx:.1f}" y="{cy + _R + 12:.1f}" text-anchor="middle" '
            f'font-size="10">{shown}</text></g>'
        )
    for i, tr in enumerate(net.transitions):
        cx, cy = centre[("t", i)]
        w = width_of[("t", i)]
        rounded = ' rx="8"' if tr.kind is TransitionKind.REPLY else ""
        fill = OPERATOR_FILL if tr.kind is TransitionKind.INPUT else "white"
        label = html.escape(_label(tr.describe(), _MAX_LABEL), quote=False)
        priority = f" [priority {tr.priority}]" if tr.priority else ""
        parts.append(
            f'<g class="transition" data-node="t{i}"><title>'
            f"{html.escape(tr.describe() + priority, quote=False)} [{tr.kind.value}]</title>"
            f'<rect x="{cx - w / 2:.1f}" y="{cy - _BOX_H / 2:.1f}" width="{w:.1f}" '
            f'height="{_BOX_H:g}"{rounded} fill="{fill}" stroke="black"/>'
            f'<text x="{cx:.1f}" y="{cy + 4:.1f}" text-anchor="middle" font-size="11">'
            f"{label}</text></g>"
        )
    parts.append("</svg>")
    return "".join(parts)


def _border(
    node: Node, centre: tuple[float, float], toward: tuple[float, float], half_w: float
) -> tuple[float, float]:
    """Where the line from the node's centre toward ``toward`` leaves its shape."""
    cx, cy = centre
    dx, dy = toward[0] - cx, toward[1] - cy
    length = math.hypot(dx, dy) or 1.0
    if node[0] == "p":
        return cx + dx / length * _R, cy + dy / length * _R
    scale = min(
        half_w / abs(dx) if dx else math.inf,
        (_BOX_H / 2) / abs(dy) if dy else math.inf,
    )
    return cx + dx * scale, cy + dy * scale


def _arc(
    source: Node,
    target: Node,
    weight: int,
    centre: dict[Node, tuple[float, float]],
    layer: dict[Node, int],
    width_of: dict[Node, float],
) -> str:
    transition, place = (target, source) if target[0] == "t" else (source, target)
    (sx, sy), (tx, ty) = centre[source], centre[target]
    if layer[target] > layer[source]:
        start = _border(source, (sx, sy), (tx, ty), width_of[source] / 2)
        end = _border(target, (tx, ty), (sx, sy), width_of[target] / 2)
        path = f"M{start[0]:.1f},{start[1]:.1f} L{end[0]:.1f},{end[1]:.1f}"
        tail = start
        middle = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
    else:  # backward (or within a column): a curve below both nodes
        drop = 34.0 + 6.0 * abs(layer[source] - layer[target])
        start = (sx, sy + (_R if source[0] == "p" else _BOX_H / 2))
        end = (tx, ty + (_R if target[0] == "p" else _BOX_H / 2))
        c1 = (start[0], start[1] + drop)
        c2 = (end[0], end[1] + drop)
        path = (
            f"M{start[0]:.1f},{start[1]:.1f} C{c1[0]:.1f},{c1[1]:.1f} "
            f"{c2[0]:.1f},{c2[1]:.1f} {end[0]:.1f},{end[1]:.1f}"
        )
        tail = c2
        middle = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2 + drop * 0.75)
    head = _arrowhead(tail, end)
    label = (
        f'<text x="{middle[0]:.1f}" y="{middle[1] - 3:.1f}" text-anchor="middle" '
        f'font-size="10">{weight}</text>'
        if weight > 1
        else ""
    )
    return (
        f'<g class="arc" data-t="t{transition[1]}" data-p="p{place[1]}">'
        f'<path d="{path}" fill="none" stroke="black"/>'
        f'<polygon points="{head}" fill="black" stroke="black"/>{label}</g>'
    )


def _arrowhead(tail: tuple[float, float], tip: tuple[float, float]) -> str:
    dx, dy = tip[0] - tail[0], tip[1] - tail[1]
    length = math.hypot(dx, dy) or 1.0
    ux, uy = dx / length, dy / length
    bx, by = tip[0] - 8 * ux, tip[1] - 8 * uy
    left = (bx - 3.5 * uy, by + 3.5 * ux)
    right = (bx + 3.5 * uy, by - 3.5 * ux)
    return " ".join(f"{x:.1f},{y:.1f}" for x, y in (tip, left, right))
