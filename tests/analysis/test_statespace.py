"""The vectorised explorer against the plain reference explorer, plus its budgets,
overflow handling, predicates, traces and graph export."""

from __future__ import annotations

import io
import itertools

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis.statespace as statespace
from analysis.encoding import CompactNet, KeyStore, Layout
from analysis.graph import to_networkx
from analysis.progress import ProgressInfo, ProgressPrinter
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.reference import ReferenceResult, explore_reference
from tests.analysis.strategies import small_nets

BUDGET = 400


def _pump(weight: int = 1, counter: int | None = None) -> Net:
    """``t`` adds ``weight`` tokens to ``b``; with ``counter`` it may fire that often."""
    inputs: tuple[tuple[str, int], ...] = (("a", 1),)
    places = [Place("a", 1), Place("b")]
    if counter is not None:
        places.append(Place("c", counter))
        inputs = (*inputs, ("c", 1))
    return Net("pump", tuple(places), (Transition("t", inputs, (("a", 1), ("b", weight))),))


def _replay(net: Net, trace: list[int]) -> tuple[int, ...]:
    marking = net.initial_marking()
    for t in trace:
        assert net.enabled(marking, net.transitions[t])
        marking = net.fire(marking, net.transitions[t])
    return marking


def _agree(space: StateSpace, ref: ReferenceResult, net: Net) -> None:
    markings = [tuple(row) for row in space.markings.tolist()]
    assert len(set(markings)) == len(markings) == space.states
    assert set(markings) == set(ref.states)
    assert markings[0] == net.initial_marking()
    assert space.edges == ref.edges
    dead = {space.marking(i) for i in space.deadlocks.tolist()}
    assert dead == set(ref.dead)
    for index in space.deadlocks.tolist():
        trace = space.trace_to(index)
        assert _replay(net, trace) == space.marking(index)
        assert len(trace) == len(ref.trace_to(space.marking(index)))
    columns = np.array(ref.states, dtype=np.int64).reshape(len(ref.states), -1)
    assert space.place_bounds.tolist() == columns.max(axis=0).tolist()
    assert space.max_tokens_marking == int(columns.sum(axis=1).max())
    enabled_somewhere = [any(net.enabled(m, tr) for m in ref.states) for tr in net.transitions]
    assert space.fired_transitions.tolist() == enabled_somewhere


@settings(max_examples=300)
@given(small_nets())
def test_explorer_agrees_with_the_reference(net: Net) -> None:
    ref = explore_reference(net, max_states=BUDGET)
    space = explore(net, max_states=BUDGET)
    if not ref.complete:
        assert not space.complete and space.states == BUDGET
        assert space.stopped_reason is not None and "budget" in space.stopped_reason
        return
    assert space.complete and space.stopped_reason is None
    _agree(space, ref, net)


@settings(max_examples=100)
@given(small_nets(max_weight=3, max_initial=3), st.integers(1, 64))
def test_small_chunks_give_the_same_answer(net: Net, chunk: int) -> None:
    whole = explore(net, max_states=BUDGET)
    pieces = explore(net, max_states=BUDGET, chunk=chunk)
    assert (whole.states, whole.complete) == (pieces.states, pieces.complete)
    if whole.complete:  # an incomplete run stops mid-layer, where chunks differ
        assert whole.edges == pieces.edges
        assert whole.deadlocks.size == pieces.deadlocks.size
        assert {tuple(r) for r in whole.markings.tolist()} == {
            tuple(r) for r in pieces.markings.tolist()
        }


@settings(max_examples=100)
@given(small_nets(), st.data())
def test_find_returns_a_shallowest_witness(net: Net, data: st.DataObject) -> None:
    ref = explore_reference(net, max_states=BUDGET)
    if not ref.complete:
        return
    space = explore(net, max_states=BUDGET)
    place = data.draw(st.integers(0, len(net.places) - 1))
    level = data.draw(st.integers(1, 3))
    hit = space.find(lambda m: m[:, place] >= level)
    witnesses = [m for m in ref.states if m[place] >= level]
    if not witnesses:
        assert hit is None
        return
    assert hit is not None
    assert space.marking(hit)[place] >= level
    trace = space.trace_to(hit)
    assert _replay(net, trace) == space.marking(hit)
    assert len(trace) == min(len(ref.trace_to(m)) for m in witnesses)


def test_unbounded_net_stops_at_the_state_budget() -> None:
    space = explore(_pump(), max_states=50)
    assert not space.complete and space.states == 50
    assert space.stopped_reason == "state budget reached (max_states=50)"
    assert space.marking(49) == (1, 49)


def test_default_budget_is_finite() -> None:
    assert statespace.DEFAULT_MAX_STATES == 5_000_000


def test_counts_beyond_every_small_dtype_are_exact() -> None:
    # b reaches 100 * 1000 = 100_000: past int8, int16, and many field widenings.
    net = _pump(weight=100, counter=1000)
    space = explore(net)
    assert space.complete and space.states == 1001 and space.edges == 1000
    assert space.max_tokens_place == 100_000
    assert space.marking(1000) == (1, 100_000, 0)
    assert space.deadlocks.tolist() == [1000]
    assert len(space.trace_to(1000)) == 1000


def test_weights_of_one_hundred_and_initial_one_hundred() -> None:
    net = Net(
        "heavy",
        (Place("a", 100), Place("b", 0)),
        (
            Transition("move", (("a", 100),), (("b", 100),)),
            Transition("back", (("b", 1),), (("a", 1),)),
        ),
    )
    space = explore(net)
    ref = explore_reference(net)
    _agree(space, ref, net)


def test_token_counts_past_the_field_limit_stop_with_a_reason(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(statespace, "MAX_FIELD_BITS", 12)
    space = explore(_pump(weight=100), max_states=None)
    assert not space.complete
    assert space.stopped_reason is not None and "place 'b'" in space.stopped_reason
    assert "unbounded" in space.stopped_reason
    assert space.max_tokens_place < 1 << 12


def test_time_limit_is_respected_with_a_fake_clock() -> None:
    ticks = itertools.count()
    space = explore(_pump(), max_states=None, time_limit=5.0, chunk=1, clock=lambda: next(ticks))
    assert not space.complete
    assert space.stopped_reason == "time limit reached (5 s)"
    assert space.states < 20


def test_time_limit_is_respected_on_the_real_clock() -> None:
    space = explore(_pump(), max_states=None, time_limit=0.2)
    assert not space.complete and space.seconds < 5.0
    assert space.stopped_reason is not None and "time limit" in space.stopped_reason


def test_parallel_transitions_count_as_separate_edges() -> None:
    net = Net(
        "fork",
        (Place("a", 1), Place("b")),
        (Transition("t1", (("a", 1),), (("b", 1),)), Transition("t2", (("a", 1),), (("b", 1),))),
    )
    space = explore(net)
    assert (space.states, space.edges, space.deadlocks.tolist()) == (2, 2, [1])
    assert space.trace_names(1) == ["t1"]
    graph = to_networkx(space)
    assert graph.number_of_edges() == 2
    assert set(graph.edges(keys=True)) == {(0, 1, "t1"), (0, 1, "t2")}


@settings(max_examples=50)
@given(small_nets())
def test_networkx_export_is_the_reachability_graph(net: Net) -> None:
    ref = explore_reference(net, max_states=200)
    if not ref.complete:
        return
    graph = to_networkx(net)
    assert isinstance(graph, nx.MultiDiGraph)
    assert graph.number_of_nodes() == len(ref.states)
    assert graph.number_of_edges() == ref.edges
    for u, v, name in graph.edges(keys=True):
        before = graph.nodes[u]["marking"]
        assert net.fire(before, net.transition(name)) == graph.nodes[v]["marking"]
    assert graph.nodes[0]["marking"] == net.initial_marking()


def test_networkx_export_refuses_incomplete_spaces() -> None:
    with pytest.raises(ValueError, match="incomplete"):
        to_networkx(explore(_pump(), max_states=10))


def test_layout_packs_and_unpacks_markings() -> None:
    layout = Layout.for_bits([1, 63, 5, 40, 40])
    rows = np.array([[1, (1 << 63) - 1, 31, 0, (1 << 40) - 1], [0, 0, 0, 7, 9]], dtype=np.uint64)
    keys = layout.pack(rows)
    assert layout.n_words == 4
    assert (keys >> np.uint64(63) == 0).all()
    assert layout.unpack(keys, np.uint64).tolist() == rows.tolist()


def test_key_store_numbers_new_keys_by_first_occurrence() -> None:
    store = KeyStore(1)
    added = store.add(np.array([[5], [3], [5], [9]], dtype=np.uint64))
    assert added.first.tolist() == [0, 1, 3]
    assert store.keys[:, 0].tolist() == [5, 3, 9]
    again = store.add(np.array([[9], [4], [4]], dtype=np.uint64), limit=0)
    assert again.known.tolist() == [True, False, False] and again.cut and store.size == 3


def test_compact_net_adds_up_parallel_arcs() -> None:
    net = Net("twice", (Place("a", 2),), (Transition("t", (("a", 1), ("a", 1)), ()),))
    cn = CompactNet.from_net(net)
    assert cn.pre.tolist() == [[2]] and cn.delta.tolist() == [[-2]]
    assert explore(cn).states == 2


def test_progress_printer_is_rate_limited_and_quiet_off_a_terminal() -> None:
    now = [0.0]
    stream = io.StringIO()
    printer = ProgressPrinter(stream, interval=1.0, force=True, clock=lambda: now[0])
    info = ProgressInfo(states=10, edges=20, frontier=3, depth=2, seconds=0.5)
    printer(info)
    now[0] = 0.5
    printer(info)
    now[0] = 1.6
    printer(info)
    printer.close()
    assert stream.getvalue().count("\r") == 2 and stream.getvalue().endswith("\n")
    assert "20 states/s" in info.line()
    quiet = io.StringIO()
    ProgressPrinter(quiet)(info)
    assert quiet.getvalue() == ""


def test_progress_callback_sees_the_run() -> None:
    seen: list[ProgressInfo] = []
    space = explore(_pump(counter=100), progress=seen.append, chunk=1)
    assert seen and seen[-1].states == space.states == 101


def test_degenerate_nets() -> None:
    nothing = explore(Net("empty", (), ()))
    assert (nothing.states, nothing.edges, nothing.deadlocks.tolist()) == (1, 0, [0])
    loop = explore(Net("source", (), (Transition("t", (), ()),)))
    assert (loop.states, loop.edges, loop.deadlocks.tolist(), loop.complete) == (1, 1, [], True)
    assert loop.fired_transitions.tolist() == [True] and loop.dead_transitions.size == 0
    idle = explore(Net("idle", (Place("a", 3),), ()))
    assert idle.marking(0) == (3,) and idle.ever_marked.tolist() == [True]


def test_wide_markings_hash_with_whole_arrays_and_stay_exact() -> None:
    from analysis.encoding import WIDE_KEYS

    # A token walking a 600-place chain while another toggles between two places:
    # 1,200 states, each marking packed into at least WIDE_KEYS 64-bit words.
    chain = [Place(f"c{i}", initial=1 if i == 0 else 0) for i in range(600)]
    places = (*chain, Place("a", initial=1), Place("b"))
    transitions = [
        Transition(f"step{i}", inputs=((f"c{i}", 1),), outputs=((f"c{i + 1}", 1),))
        for i in range(599)
    ]
    transitions += [
        Transition("ab", inputs=(("a", 1),), outputs=(("b", 1),)),
        Transition("ba", inputs=(("b", 1),), outputs=(("a", 1),)),
    ]
    net = Net("wide", places, tuple(transitions))
    space = explore(net)
    assert space.layout.n_words >= WIDE_KEYS
    reference = explore_reference(net, max_states=5_000)
    assert space.complete and reference.complete
    assert (
        (space.states, space.edges)
        == (len(reference.states), reference.edges)
        == (1200, 1200 + 599 * 2)
    )
    assert {space.marking(i) for i in range(space.states)} == set(reference.states)
