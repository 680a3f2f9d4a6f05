"""Net drawings: every place, transition and arc, in either layout, with tokens."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from analysis.netdraw import (
    AUTO_GRAPHVIZ_MAX_ARCS,
    AUTO_GRAPHVIZ_MAX_TRANSITIONS,
    FORCED_GRAPHVIZ_TIMEOUT_S,
    GRAPHVIZ_TIMEOUT_S,
    MAX_DRAWN_NODES,
    draw_net,
    graphviz_available,
    token_text,
    too_large_for_graphviz,
)
from coral_lang import compile_file
from coral_lang.net import Net
from tests.analysis.nets import make_net, mutex
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
needs_graphviz = pytest.mark.skipif(not graphviz_available(), reason="Graphviz not installed")


def _pool() -> Net:
    net = compile_file(POOL).net
    assert net is not None
    return net


def _nodes(svg: str, kind: str) -> list[str]:
    return re.findall(rf'<g class="{kind}" data-node="([pt]\d+)"', svg)


def _arcs(svg: str) -> list[tuple[str, str]]:
    return re.findall(r'<g class="arc" data-t="(t\d+)" data-p="(p\d+)"', svg)


def _expected_arcs(net: Net) -> list[tuple[str, str]]:
    return sorted(
        (f"t{i}", f"p{net.place_index(p)}")
        for i, tr in enumerate(net.transitions)
        for p, _ in (*tr.inputs, *tr.outputs)
    )


@pytest.mark.parametrize("layout", ["builtin", pytest.param("graphviz", marks=needs_graphviz)])
def test_every_element_is_drawn_once_with_its_tokens(layout: str) -> None:
    net = _pool()
    drawing = draw_net(net, layout)  # type: ignore[arg-type]
    assert drawing.layout == layout and drawing.note == ""
    svg = drawing.svg
    assert svg.startswith("<svg ") and svg.endswith("</svg>")
    assert 'class="net"' in svg.split(">", 1)[0]
    assert sorted(_nodes(svg, "place")) == sorted(f"p{i}" for i in range(len(net.places)))
    assert sorted(_nodes(svg, "transition")) == sorted(f"t{i}" for i in range(len(net.transitions)))
    assert sorted(_arcs(svg)) == _expected_arcs(net)
    tokens = re.findall(r'<text class="tokens"[^>]*>([^<]*)</text>', svg)
    assert len(tokens) == len(net.places)
    assert tokens.count("\u2022") == sum(1 for p in net.places if p.initial == 1)
    assert " id=" not in svg and "xmlns" not in svg and "<?xml" not in svg


def test_token_text_switches_to_numbers_above_three() -> None:
    assert [token_text(n) for n in (0, 1, 3, 4, 12)] == ["", "\u2022", "\u2022" * 3, "4", "12"]


def test_builtin_layout_puts_the_initial_marking_first_and_follows_arcs() -> None:
    net = mutex()
    svg = draw_net(net, "builtin").svg
    centres = {
        node: float(x)
        for node, x in re.findall(
            r'data-node="(p\d+)"><title>[^<]*</title><circle cx="([\d.]+)"', svg
        )
    }
    marked = [f"p{i}" for i, p in enumerate(net.places) if p.initial]
    unmarked = [f"p{i}" for i, p in enumerate(net.places) if not p.initial]
    assert max(centres[p] for p in marked) < min(centres[p] for p in unmarked)


def test_names_are_escaped_in_both_layouts() -> None:
    net = make_net("a<b", {"x&y": 1, "z": 0}, {"go<": ({"x&y": 2}, {"z": 1})})
    for layout in ("builtin", "graphviz") if graphviz_available() else ("builtin",):
        svg = draw_net(net, layout).svg
        assert "x&amp;y" in svg and "go&lt;" in svg and "x&y" not in svg and "go<" not in svg
        assert re.search(r">2</text>", svg)  # the arc weight


def test_missing_graphviz_falls_back_with_a_note() -> None:
    drawing = draw_net(mutex(), "graphviz", dot_program="no-such-graphviz-program")
    assert drawing.layout == "builtin" and "not installed" in drawing.note
    assert len(_nodes(drawing.svg, "place")) == 5
    assert draw_net(mutex(), "auto", dot_program="no-such-graphviz-program").note == ""


@needs_graphviz
def test_a_failing_graphviz_falls_back(tmp_path: pytest.TempPathFactory) -> None:
    drawing = draw_net(mutex(), "graphviz", dot_program="false")
    assert drawing.layout == "builtin" and "Graphviz failed (exit code 1" in drawing.note


def test_huge_nets_are_not_drawn() -> None:
    n = MAX_DRAWN_NODES // 2 + 1
    net = make_net(
        "big",
        {f"p{i}": int(i == 0) for i in range(n)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % n}": 1}) for i in range(n)},
    )
    drawing = draw_net(net)
    assert drawing.svg == "" and drawing.layout == "none" and str(2 * n) in drawing.note


def _ring(transitions: int) -> Net:
    return make_net(
        "ring",
        {f"p{i}": int(i == 0) for i in range(transitions)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % transitions}": 1}) for i in range(transitions)},
    )


def _program(tmp_path: Path, name: str, body: str) -> str:
    """A stand-in for ``dot``: a shell script that records it ran, then ``body``."""
    script = tmp_path / name
    script.write_text(f"#!/bin/sh\necho ran >> {tmp_path / 'calls'}\n{body}\n")
    script.chmod(0o755)
    return str(script)


def test_auto_does_not_try_graphviz_on_large_nets(tmp_path: Path) -> None:
    program = _program(tmp_path, "dot-spy", "exit 1")
    large = _ring(AUTO_GRAPHVIZ_MAX_TRANSITIONS + 1)
    assert too_large_for_graphviz(large).startswith(f"{AUTO_GRAPHVIZ_MAX_TRANSITIONS + 1} ")
    drawing = draw_net(large, "auto", dot_program=program)
    assert drawing.layout == "builtin" and "Graphviz was not tried" in drawing.note
    assert "--net-layout graphviz" in drawing.note
    assert not (tmp_path / "calls").exists()
    # --net-layout graphviz forces it (here it fails, so the fallback says why).
    forced = draw_net(large, "graphviz", dot_program=program)
    assert (tmp_path / "calls").read_text() == "ran\n"
    assert forced.layout == "builtin" and "Graphviz failed" in forced.note
    # A net at the limits is tried.
    assert too_large_for_graphviz(_ring(AUTO_GRAPHVIZ_MAX_TRANSITIONS)) == ""
    dense = make_net(
        "dense",
        {f"p{i}": 1 for i in range(AUTO_GRAPHVIZ_MAX_ARCS // 10 + 1)},
        {f"t{j}": ({f"p{i}": 1 for i in range(6 + j % 2)}, {"p0": 1}) for j in range(70)},
    )
    assert dense.arc_count > AUTO_GRAPHVIZ_MAX_ARCS and len(dense.transitions) <= 80
    assert "arcs, over" in too_large_for_graphviz(dense)


def test_a_slow_graphviz_is_cut_off_and_the_builtin_layout_used(tmp_path: Path) -> None:
    program = _program(tmp_path, "dot-slow", "exec sleep 30")
    drawing = draw_net(mutex(), "auto", dot_program=program, timeout_s=0.3)
    assert drawing.layout == "builtin" and "no layout within 0.3 s" in drawing.note
    assert len(_nodes(drawing.svg, "place")) == 5
    assert GRAPHVIZ_TIMEOUT_S <= 5 < FORCED_GRAPHVIZ_TIMEOUT_S
