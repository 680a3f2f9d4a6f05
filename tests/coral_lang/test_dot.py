"""DOT export: what a picture of a net shows, escaping, determinism, and Graphviz itself."""

from __future__ import annotations

import shutil
import subprocess

import pytest
from hypothesis import given

from coral_lang.dot import HIGHLIGHT_COLOR, to_dot
from coral_lang.net import Command, Net, Place, PlaceKind, Transition, TransitionKind
from coral_lang.pnml import read_pnml
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE

DOT = shutil.which("dot")


def mission() -> Net:
    command = Command("ROMEO", "DEPTH", (("z", 2.0),), replies=("ok", "timeout"))
    return Net(
        'say "hi"',
        (
            Place("start", 1),
            Place("many", 7),
            Place("go.pending", kind=PlaceKind.PENDING, pending_of="go"),
            Place("done"),
            Place("odd\\name", 2, label='a "quoted" label'),
        ),
        (
            Transition(
                "go",
                (("start", 1), ("many", 3)),
                (("go.pending", 1),),
                TransitionKind.COMMAND,
                priority=1,
                command=command,
                pending="go.pending",
            ),
            Transition(
                "go.timeout",
                (("go.pending", 1),),
                (("done", 2),),
                TransitionKind.REPLY,
                label="DEPTH",
                reply_to="go",
                reply="timeout",
            ),
            Transition('say "bye"', (("odd\\name", 1),), ()),
        ),
    )


def node_line(dot: str, node: str) -> str:
    (line,) = [x for x in dot.splitlines() if x.strip().startswith(f"{node} [")]
    return line


def test_places_show_name_and_tokens() -> None:
    dot = to_dot(mission())
    assert 'shape="circle"' in node_line(dot, "p0")
    assert 'label="•", xlabel="start"' in node_line(dot, "p0")
    assert 'label="7", xlabel="many"' in node_line(dot, "p1")  # a number above three
    assert 'label="", xlabel="done"' in node_line(dot, "p3")


def test_pending_places_are_dashed() -> None:
    dot = to_dot(mission())
    assert 'style="dashed"' in node_line(dot, "p2")
    assert "style" not in node_line(dot, "p0")


def test_transitions_say_what_they_do() -> None:
    dot = to_dot(mission())
    assert 'shape="box"' in node_line(dot, "t0")
    assert 'label="go: sends ROMEO(DEPTH, z = 2.0)\\n[priority 1]"' in node_line(dot, "t0")
    assert 'label="go: DEPTH replied timeout"' in node_line(dot, "t1")
    assert 'style="rounded"' in node_line(dot, "t1")


def test_arcs_carry_weights_above_one() -> None:
    dot = to_dot(mission())
    assert "  p0 -> t0;" in dot.splitlines()
    assert '  p1 -> t0 [label="3"];' in dot.splitlines()
    assert "  t0 -> p2;" in dot.splitlines()
    assert '  t1 -> p3 [label="2"];' in dot.splitlines()


def test_quotes_and_backslashes_are_escaped() -> None:
    dot = to_dot(mission())
    assert dot.startswith('digraph "say \\"hi\\"" {')
    assert 'label="say \\"bye\\""' in node_line(dot, "t2")
    # A doubled backslash shows one backslash; a single one would read as an escape (\n).
    assert 'xlabel="odd\\\\name"' in node_line(dot, "p4")
    assert 'tooltip="odd\\\\name (a \\"quoted\\" label) [mission]"' in node_line(dot, "p4")


def test_marking_can_be_given_as_tuple_or_mapping() -> None:
    net = mission()
    by_tuple = to_dot(net, marking=(0, 0, 1, 0, 0))
    by_mapping = to_dot(net, marking={"go.pending": 1})
    assert by_tuple == by_mapping
    assert 'label="•"' in node_line(by_tuple, "p2")
    assert 'label=""' in node_line(by_tuple, "p0")
    assert 'label="••"' in node_line(to_dot(net, marking={"done": 2}), "p3")


def test_highlight_marks_steps_of_a_counterexample() -> None:
    dot = to_dot(mission(), highlight={"go", "start"})
    assert f'color="{HIGHLIGHT_COLOR}"' in node_line(dot, "t0")
    assert 'style="filled"' in node_line(dot, "t0")
    assert f'color="{HIGHLIGHT_COLOR}"' in node_line(dot, "p0")
    assert f'  p1 -> t0 [color="{HIGHLIGHT_COLOR}", penwidth="2", label="3"];' in dot
    assert "color" not in node_line(dot, "t1")
    # The reply transition keeps its own style when highlighted too.
    assert 'style="rounded,filled"' in node_line(to_dot(mission(), highlight=["go.timeout"]), "t1")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"highlight": {"nope"}}, "cannot highlight \\['nope'\\]"),
        ({"marking": (1, 2)}, "marking has 2 entries, the net 5 places"),
        ({"marking": {"nope": 1}}, "marking names unknown places \\['nope'\\]"),
    ],
)
def test_arguments_that_do_not_fit_the_net_are_refused(
    kwargs: dict[str, object], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        to_dot(mission(), **kwargs)  # type: ignore[arg-type]


@given(small_nets())
def test_output_is_deterministic_and_lists_every_node_and_arc(net: Net) -> None:
    dot = to_dot(net)
    assert dot == to_dot(net)
    lines = dot.splitlines()
    nodes = [
        x
        for x in lines
        if " [" in x and "->" not in x and not x.lstrip().startswith(("node", "edge"))
    ]
    edges = [x for x in lines if "->" in x]
    assert len(nodes) == len(net.places) + len(net.transitions)
    assert len(edges) == sum(len(t.inputs) + len(t.outputs) for t in net.transitions)


@pytest.mark.skipif(DOT is None, reason="Graphviz 'dot' is not on PATH (optional external binary)")
@pytest.mark.parametrize("which", ["mission", "conformance"])
def test_graphviz_accepts_the_output(which: str) -> None:
    assert DOT is not None
    if which == "mission":
        text = to_dot(mission(), highlight={"go"})
    else:
        text = to_dot(read_pnml(CONFORMANCE / "pnml" / "Sudoku-PT-AN01.pnml"))
    result = subprocess.run(
        [DOT, "-Tsvg"], input=text.encode(), capture_output=True, timeout=20, check=False
    )
    assert result.returncode == 0, result.stderr.decode()
    assert b"<svg" in result.stdout
