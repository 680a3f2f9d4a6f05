"""The vectorised explorer against the plain reference explorer, plus its budgets,
overflow handling, predicates, traces and graph export."""

from __future__ import annotations

import contextlib
import io
import itertools
from collections.abc import Iterator
from unittest import mock

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis.encoding as encoding
import analysis.encoding.keystore as keystore
import analysis.statespace as statespace
from analysis.budget import Budget, memory_limit_reason, resident_bytes, time_limit_reason
from analysis.encoding import CompactNet, KeyStore, Layout
from analysis.graph import to_networkx
from analysis.progress import ProgressInfo, ProgressPrinter
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.explored import counting_fired
from tests.analysis.nets import replay
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
        assert replay(net, trace) == space.marking(index)
        assert len(trace) == len(ref.trace_to(space.marking(index)))
    columns = np.array(ref.states, dtype=np.int64).reshape(len(ref.states), -1)
    assert space.place_bounds.tolist() == columns.max(axis=0).tolist()
    assert space.max_tokens_marking == int(columns.sum(axis=1).max())
    enabled_somewhere = [any(net.enabled(m, tr) for m in ref.states) for tr in net.transitions]
    assert space.fired_transitions.tolist() == enabled_somewhere


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
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
    assert replay(net, trace) == space.marking(hit)
    assert len(trace) == min(len(ref.trace_to(m)) for m in witnesses)


def test_unbounded_net_stops_at_the_state_budget() -> None:
    space = explore(_pump(), max_states=50)
    assert not space.complete and space.states == 50
    assert space.stopped_reason == "state budget of 50 reached"
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
    # (a second a reading: the set-up reads the clock about 16 times before the search)
    budget = Budget(30.0, clock=lambda: float(next(ticks)))
    space = explore(_pump(), max_states=None, budget=budget, chunk=1)
    assert not space.complete
    assert space.stopped_reason == time_limit_reason(30.0, space.states)
    assert 1 < space.states < 20  # stopped in the search, not in its set-up


def test_narrow_rounds_check_the_deadline_between_levels() -> None:
    """A deep chain is explored many layers per store insertion (narrow rounds): the
    deadline is checked between those layers, not only after a round of hundreds."""
    ticks = itertools.count()
    budget = Budget(0.05, clock=lambda: next(ticks) / 1000)  # a millisecond a reading
    chain = Net("countdown", (Place("c", 100_000),), (Transition("t", (("c", 1),), ()),))
    space = explore(chain, max_states=None, budget=budget)
    assert not space.complete
    assert space.stopped_reason == time_limit_reason(0.05, space.states)
    assert 0 < space.states <= 64  # a round would store 2,049 before its first check
    assert space.trace_to(space.states - 1) == [0] * (space.states - 1)


def _toggles(n: int) -> Net:
    """``n`` independent on/off switches: ``2**n`` markings."""
    places = tuple(p for i in range(n) for p in (Place(f"a{i}", 1), Place(f"b{i}")))
    transitions = tuple(
        t
        for i in range(n)
        for t in (
            Transition(f"on{i}", ((f"a{i}", 1),), ((f"b{i}", 1),)),
            Transition(f"off{i}", ((f"b{i}", 1),), ((f"a{i}", 1),)),
        )
    )
    return Net("toggles", places, transitions)


def test_a_memory_budget_stops_the_search_before_it_is_passed() -> None:
    """Every large allocation of the search (store growth, a step's temporaries) asks
    the memory budget first: the search stops under the limit, says which limit, and
    keeps a consistent partial space (traces replay). 2^22 markings need about 45 MiB
    of store, more than the 24 MiB allowed (2^21 took 21 MiB once table slots took
    3 bytes, and could finish under the limit)."""
    net = _toggles(22)
    explore(net, max_states=1000)  # the first run's imports and caches are not counted
    limit = resident_bytes() + (24 << 20)
    space = explore(net, max_states=None, budget=Budget(memory=limit))
    assert not space.complete and 1000 < space.states < 1 << 22
    assert space.stopped_reason == memory_limit_reason(limit, space.states)
    # within one step of the limit (glibc keeps what the steps freed: this is the peak)
    assert resident_bytes() <= limit + (8 << 20)
    last = space.states - 1
    assert replay(net, space.trace_to(last)) == space.marking(last)


def test_time_limit_is_respected_on_the_real_clock() -> None:
    space = explore(_pump(), max_states=None, budget=Budget(0.2))
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
    assert layout.n_words == 3  # widest first: [63], [40, 5, 1], [40]
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


def _walker(length: int, leak: bool) -> Net:
    """A token walking a ``length``-place chain while another toggles between two
    places: ``2 * length`` states. With ``leak``, a never-enabled transition adds a token
    to the chain, so the chain is no longer a one-hot component."""
    chain = [Place(f"c{i}", initial=1 if i == 0 else 0) for i in range(length)]
    places = (*chain, Place("a", initial=1), Place("b"), Place("z"))
    transitions = [
        Transition(f"step{i}", inputs=((f"c{i}", 1),), outputs=((f"c{i + 1}", 1),))
        for i in range(length - 1)
    ]
    transitions += [
        Transition("ab", inputs=(("a", 1),), outputs=(("b", 1),)),
        Transition("ba", inputs=(("b", 1),), outputs=(("a", 1),)),
    ]
    if leak:
        leak_arcs = (("c5", 1), ("z", 1))
        transitions.append(Transition("leak", inputs=(("z", 1),), outputs=leak_arcs))
    return Net("wide", places, tuple(transitions))


def _agrees_on_walker(net: Net, space: StateSpace) -> None:
    reference = explore_reference(net, max_states=5_000)
    assert space.complete and reference.complete
    assert (
        (space.states, space.edges)
        == (len(reference.states), reference.edges)
        == (1200, 1200 + 599 * 2)
    )
    assert {space.marking(i) for i in range(space.states)} == set(reference.states)


@pytest.mark.slow
def test_wide_markings_hash_with_whole_arrays_and_stay_exact() -> None:
    from analysis.encoding import WIDE_KEYS

    # 603 places, one count field each: at least WIDE_KEYS 64-bit words per marking.
    net = _walker(600, leak=True)
    space = explore(net)
    assert space.layout.n_words >= WIDE_KEYS
    _agrees_on_walker(net, space)


@pytest.mark.slow
def test_one_hot_components_pack_a_walking_token_into_a_few_bits() -> None:
    net = _walker(600, leak=False)
    space = explore(net)
    # The chain (600 places, one token) and {a, b} are one-hot components; z is a count.
    assert space.layout.n_words == 1
    assert sorted(space.layout.bits) == [1, 1, 10]
    _agrees_on_walker(net, space)


# -- every strategy of the explorer against the reference ---------------------------------

MODES: dict[str, dict[str, float]] = {
    # layer by layer, sleep sets on from the first layer (no narrow rounds)
    "wide": {"NARROW_WIDTH": 0, "SLEEP_MIN_DEGREE": 0.0},
    # layer by layer, every edge fired
    "wide, no sleep sets": {"NARROW_WIDTH": 0, "SLEEP_MIN_DEGREE": float("inf")},
    # several layers per insertion, whatever the width
    "narrow": {"NARROW_WIDTH": 1 << 30},
    # successor columns from the sparse effects
    "sparse effects": {"NARROW_WIDTH": 0, "SLEEP_MIN_DEGREE": 0.0, "DENSE_DELTA_CELLS": 0},
    # transitions testing a component looked up by its value, on any net
    "indexed": {"NARROW_WIDTH": 0, "SLEEP_MIN_DEGREE": 0.0, "KEYED_MIN": 0, "KEYED_SHARE": 0.0},
    # narrow rounds whose levels enable by lookup (`_Explorer.narrow_edges`)
    "indexed, narrow": {"NARROW_WIDTH": 1 << 30, "KEYED_MIN": 0, "KEYED_SHARE": 0.0},
    # every step's repeated successor keys filtered before the store
    "wide, repeats filtered": {
        "NARROW_WIDTH": 0,
        "SLEEP_MIN_DEGREE": 0.0,
        "REPEAT_FILTER_MIN": 0,
        "REPEAT_FILTER_DEGREE": 0.0,
    },
    # narrow rounds dropping the repeats of every growing level
    "narrow, repeats dropped": {"NARROW_WIDTH": 1 << 30, "REPEATS_MIN": 0},
    # the whole (T, n) enabled matrix instead of bit sets (`_EnablingBits`)
    "wide, dense enabling": {
        "NARROW_WIDTH": 0,
        "SLEEP_MIN_DEGREE": 0.0,
        "BIT_TABLES_MIN": 0,
        "BIT_TABLE_TRANSITIONS": 1 << 30,
    },
    # bit sets from tables of a few rows: a table per field or two, counts clipped
    "wide, small bit tables": {
        "NARROW_WIDTH": 0,
        "SLEEP_MIN_DEGREE": 0.0,
        "BIT_TABLE_ROWS": 6,
        "BIT_TABLES_MIN": 1 << 30,
    },
}


@contextlib.contextmanager
def _mode(name: str, components: bool = True) -> Iterator[None]:
    with contextlib.ExitStack() as stack:
        for attribute, value in MODES[name].items():
            stack.enter_context(mock.patch.object(statespace, attribute, value))
        if not components:
            stack.enter_context(mock.patch.object(statespace, "one_hot_components", _none))
        yield


def _none(cn: CompactNet, budget: Budget | None = None) -> list[encoding.Component]:
    return []


@pytest.mark.slow
@settings(max_examples=400)
@given(
    small_nets(max_places=7, max_transitions=9),
    st.sampled_from(sorted(MODES)),
    st.sampled_from([1, 3, 17, 1 << 15]),
    st.booleans(),
)
def test_every_mode_agrees_with_the_reference(
    net: Net, mode: str, chunk: int, components: bool
) -> None:
    ref = explore_reference(net, max_states=BUDGET)
    with _mode(mode, components):
        space = explore(net, max_states=BUDGET, chunk=chunk)
    if not ref.complete:
        assert not space.complete and space.states == BUDGET
        return
    assert space.complete, space.stopped_reason
    _agree(space, ref, net)


@given(
    st.lists(st.integers(0, 40), max_size=1000),
    st.sampled_from([0, 1, 1 << 40, (1 << 64) - 41]),
)
def test_the_repeat_filter_keeps_every_first_occurrence_in_order(
    values: list[int], offset: int
) -> None:
    keys = (np.array(values, dtype=np.uint64) + np.uint64(offset)).reshape(-1, 1)
    explorer = mock.Mock(edges=1, store=mock.Mock(size=0))
    explorer.repeat_table = np.empty(0, dtype=np.int32)
    with mock.patch.object(statespace, "REPEAT_FILTER_MIN", 0):
        kept = statespace._Explorer.unrepeated(explorer, keys)
    assert kept is not None
    earliest: dict[int, int] = {}
    for i, v in enumerate(values):
        earliest.setdefault(v, i)
    assert all(np.diff(kept) > 0)
    assert set(earliest.values()) <= set(kept.tolist())
    # what it drops repeats a key it keeps (the earliest copy is always kept)
    for i in set(range(len(values))) - set(kept.tolist()):
        assert earliest[values[i]] < i


def _count_fired(net: Net, mode: str) -> tuple[StateSpace, int]:
    with _mode(mode), counting_fired() as fired:
        space = explore(net)
    return space, fired[0]


def test_sleep_sets_fire_about_one_edge_per_state_on_independent_transitions() -> None:
    # Ten independent toggles: 1,024 states, 5,120 edges. Sleep sets fire each state's
    # transitions above its highest set bit only: one edge per state but the first.
    places = tuple(Place(f"p{i}", 1) for i in range(10))
    transitions = tuple(Transition(f"t{i}", ((f"p{i}", 1),), ()) for i in range(10))
    net = Net("independent", places, transitions)
    full, every = _count_fired(net, "wide, no sleep sets")
    reduced, fired = _count_fired(net, "wide")
    assert (full.states, full.edges, every) == (1024, 5120, 5120)
    assert (reduced.states, reduced.edges, fired) == (1024, 5120, 1023)
    assert full.deadlocks.tolist() == reduced.deadlocks.tolist() == [1023]
    assert len(reduced.trace_to(1023)) == 10


def test_key_store_resolves_hash_collisions_exactly(monkeypatch: pytest.MonkeyPatch) -> None:
    # A hash with 16 values: two-word keys collide all the time, in tags and in slots.
    weak = lambda keys: (keys[:, 0] & np.uint64(15)) * np.uint64(0x9E3779B97F4A7C15)  # noqa: E731
    monkeypatch.setattr(keystore, "_hash", weak)
    rng = np.random.default_rng(7)
    store, seen = KeyStore(2), dict[tuple[int, ...], int]()
    for size in (5, 300, 2000, 40, 2000):
        batch = rng.integers(0, 60, size=(size, 2)).astype(np.uint64)
        added = store.add(batch, want_ids=True)
        assert added.ids is not None
        expected = []
        for row in map(tuple, batch.tolist()):
            seen.setdefault(row, len(seen))
            expected.append(seen[row])
        assert added.ids.tolist() == expected
    assert [tuple(k) for k in store.keys.tolist()] == list(seen)
    assert store.find(np.array([[61, 0], *seen][:3], dtype=np.uint64)).tolist()[0] == -1


def test_one_hot_components_are_proven_invariants() -> None:
    # p + q holds one token; r + s holds two (not one-hot); u is produced from nothing.
    net = Net(
        "mixed",
        (Place("p", 1), Place("q"), Place("r", 2), Place("s"), Place("u")),
        (
            Transition("pq", (("p", 1),), (("q", 1),)),
            Transition("qp", (("q", 1), ("r", 1)), (("p", 1), ("s", 1))),
            Transition("sr", (("s", 1),), (("r", 1), ("u", 1))),
        ),
    )
    cn = CompactNet.from_net(net)
    found = encoding.one_hot_components(cn)
    assert [(c.places.tolist(), c.exact) for c in found] == [([0, 1], True)]
    ref = explore_reference(net, max_states=BUDGET)
    assert not ref.complete  # u grows forever
    space = explore(net, max_states=BUDGET)
    assert space.states == BUDGET and not space.complete


@pytest.mark.slow
@pytest.mark.parametrize(("words", "weak"), [(1, False), (2, False), (9, False), (3, True)])
def test_key_store_matches_a_dict(words: int, weak: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Batches with repeats, budgets and growth (table rebuilds, wrap-around) against a
    plain dict; ``weak`` makes the hash take 16 values (tags and slots collide)."""
    if weak:
        weak_hash = lambda keys: (keys[:, 0] & np.uint64(15)) * np.uint64(0x9E3779B97F4A7C15)  # noqa: E731
        monkeypatch.setattr(keystore, "_hash", weak_hash)
    rng = np.random.default_rng(words)
    store, seen = KeyStore(words), dict[tuple[int, ...], int]()
    for r in range(12):
        size = int(rng.integers(1, 40 if r % 3 == 0 else (1500 if weak else 20_000)))
        batch = rng.integers(0, 300 if weak else 5000, size=(size, words)).astype(np.uint64)
        limit = int(rng.integers(0, 100)) if r % 4 == 1 else None
        added = store.add(batch, limit=limit, want_ids=True)
        expected_ids, expected_first, fresh = [], [], 0
        for i, row in enumerate(map(tuple, batch.tolist())):
            if row not in seen and (limit is None or fresh < limit):
                seen[row] = len(seen)
                fresh += 1
                expected_first.append(i)
            expected_ids.append(seen.get(row, -1))
        assert added.ids is not None and added.ids.tolist() == expected_ids
        assert added.first.tolist() == expected_first
        assert store.find(batch).tolist() == expected_ids
    assert [tuple(k) for k in store.keys.tolist()] == list(seen)


def _forked(chains: int, length: int) -> Net:
    """A fork into ``chains`` chains of ``length`` steps, each step able to give up into
    one shared ``abort`` place (as missions compile replies that can time out)."""
    places = [Place("start", 1), Place("abort")]
    transitions = [
        Transition("fork", (("start", 1),), tuple((f"c{c}_0", 1) for c in range(chains)))
    ]
    for c in range(chains):
        places += [Place(f"c{c}_{i}") for i in range(length + 1)]
        for i in range(length):
            here, there = f"c{c}_{i}", f"c{c}_{i + 1}"
            transitions.append(Transition(f"go{c}_{i}", ((here, 1),), ((there, 1),)))
            transitions.append(Transition(f"quit{c}_{i}", ((here, 1),), (("abort", 1),)))
    return Net("forked", tuple(places), tuple(transitions))


def test_parts_of_a_flow_hold_at_most_one_token_and_are_packed_so() -> None:
    # start + chain c never gains a token (the fork moves one in, quitting moves it to
    # the shared abort): each chain is a component that may be empty (value 0).
    net = _forked(3, 5)
    cn = CompactNet.from_net(net)
    parts = encoding.one_hot_components(cn)
    assert len(parts) == 3 and not any(p.exact for p in parts)
    space = explore(net)
    assert sorted(space.layout.first) == [0, 1, 1, 1]  # abort is a count
    _agree(space, explore_reference(net, max_states=5_000), net)
    assert space.max_tokens_place == 3 and space.max_tokens_marking == 3


@pytest.mark.slow
@pytest.mark.parametrize("fields", [5, 300])
def test_repacking_with_wider_fields_keeps_every_count(fields: int) -> None:
    rng = np.random.default_rng(fields)
    bits = rng.integers(1, 9, fields).tolist()
    narrow = Layout.for_bits(bits)
    wide = Layout.for_bits([b + int(rng.integers(0, 3)) for b in bits])
    rows = np.array([[rng.integers(0, 1 << b) for b in bits] for _ in range(500)], np.uint64)
    repacked = narrow.repack(narrow.pack(rows), wide)
    assert (repacked == wide.pack(rows)).all()
    assert (wide.unpack(repacked, np.uint64) == rows).all()


def test_a_wide_net_explores_at_the_cost_of_what_it_enables() -> None:
    """4,200 transitions of which two are enabled per marking: the narrow rounds look
    the candidates up by component value instead of testing every transition in every
    marking, with exact counts and shortest traces."""
    from tests.analysis.wide_nets import rings

    net = rings(2, 100, idle=4_000)
    space = explore(net)
    assert space.complete and (space.states, space.edges) == (100**2, 2 * 100**2)
    assert not space.deadlocks.size and space.max_tokens_place == 1
    assert not space.fired_transitions[200:].any() and space.fired_transitions[:200].all()
    far = space.find(lambda m: (m[:, 50] == 1) & (m[:, 150] == 1))  # both rings halfway
    assert far is not None and len(space.trace_to(far)) == 100


@settings(max_examples=30, deadline=None)
@given(small_nets())
def test_field_columns_read_from_keys_are_the_markings_field_values(net: Net) -> None:
    """The frontier is unpacked from the stored keys (`Layout.fields`): the values must
    be those `FieldNet.values` computes from the markings themselves."""
    space = explore(net, max_states=2000)
    got = space.layout.fields(space.keys[:], np.int64).T
    assert np.array_equal(got, encoding.FieldNet.values(space.markings, space.layout))


@pytest.mark.slow
@settings(max_examples=150)
@given(small_nets(max_weight=3, max_initial=3))
def test_looking_transitions_up_by_a_key_agrees_with_the_reference(net: Net) -> None:
    """Every transition with at most two input fields looked up by a key (a component
    value or a count), as on wide nets, even on these small ones: the same answers."""
    ref = explore_reference(net, max_states=BUDGET)
    with (
        mock.patch.object(statespace, "KEYED_MIN", 0),
        mock.patch.object(statespace, "KEYED_SHARE", 0.0),
    ):
        space = explore(net, max_states=BUDGET)
    if not ref.complete:
        assert not space.complete and space.states == BUDGET
        return
    assert space.complete
    _agree(space, ref, net)


def test_a_wide_net_of_counts_explores_at_the_cost_of_what_it_marks() -> None:
    """4,160 transitions on count places (two tokens per ring, no components): the
    enabled ones are looked up from the marked places, with exact counts and traces."""
    from tests.analysis.wide_nets import count_rings

    net = count_rings(2, 40, 2, idle=4_080)
    ways = 40 * 41 // 2  # two tokens on 40 places
    space = explore(net)
    assert space.complete and space.states == ways**2
    assert not space.deadlocks.size and space.max_tokens_place == 2
    assert not space.fired_transitions[80:].any() and space.fired_transitions[:80].all()
    # each ring's marking enables one transition per marked place
    per_ring = 2 * (ways - 40) + 40  # two marked places, or one place with both tokens
    assert space.edges == 2 * per_ring * ways
    far = space.find(lambda m: (m[:, 39] == 2) & (m[:, 79] == 2))  # both rings' last place
    assert far is not None and len(space.trace_to(far)) == 4 * 39


@settings(max_examples=60, deadline=None)
@given(small_nets(max_places=7, max_transitions=9, max_weight=3, max_initial=3), st.booleans())
def test_enabling_as_bit_sets_is_the_dense_enabled_matrix(net: Net, small: bool) -> None:
    """`_EnablingBits` on every reachable marking (with tables of a few rows, or the
    default): the same transitions as the dense test, listed in (marking, transition)
    order."""
    space = explore(net, max_states=2000)
    with mock.patch.object(statespace, "BIT_TABLE_ROWS", 6 if small else 1 << 12):
        explorer = statespace._Explorer(
            CompactNet.from_net(net), None, Budget(), None, None, 1 << 15
        )
        bits = statespace._EnablingBits(explorer.fnet, len(net.transitions))
    if not bits.feasible:  # (a count tested at more values than a table holds)
        return
    bits.fit(explorer.dtype)
    rows = encoding.FieldNet.values(space.markings, explorer.layout)
    rows = rows[(rows <= np.iinfo(explorer.dtype).max).all(axis=1)]  # (before any widening)
    cols = np.ascontiguousarray(rows.T).astype(explorer.dtype)
    dense = explorer.enabled(cols)
    trans, src = bits.edges(bits.enabled(cols))
    expected_src, expected_trans = np.nonzero(dense.T)
    assert np.array_equal(src, expected_src) and np.array_equal(trans, expected_trans)
