"""The general agglomeration and redundant-transition rules keep every answer: checked
by exploring both nets on random small nets that contain the shapes they look for."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.reduce import Goal, decide_deadlock, reduce_net
from analysis.reduce.agglomerate import post_agglomerate
from analysis.reduce.deadlock import is_dead, replay
from analysis.reduce.redundant import (
    collapse_live,
    remove_dominated_self_loops,
    remove_duplicate_transitions,
)
from analysis.reduce.work import WorkNet
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.reduce.test_preservation import (
    assert_deadlock_preserved,
    assert_same_observations,
)
from tests.analysis.strategies import small_nets


@st.composite
def shaped_nets(draw: st.DrawFn) -> Net:
    """A random net plus the shapes of the rules: a fresh place ``q`` that some
    transitions produce into (multiples of ``w``) and one to three transitions consume
    alone (``pre = {q: w}``), copies of transitions, a place ``r`` with initial tokens
    that only ``mv`` consumes (places in series), a transition ``h`` with a private input
    feeding a place ``pp`` alone (pre-agglomeration), and self-loops."""
    net = draw(small_nets(max_places=4, max_transitions=4))
    names = [p.name for p in net.places]
    weight = draw(st.integers(1, 2))
    n_consumers = draw(st.integers(1, 3))
    producers = set(draw(st.lists(st.sampled_from(net.transitions), max_size=3)))
    transitions: list[Transition] = []
    for t in net.transitions:
        k = draw(st.integers(1, 2 if n_consumers == 1 else 1))
        outputs = (*t.outputs, ("q", k * weight)) if t in producers else t.outputs
        # Mostly no source transitions: one makes every net deadlock-free at once.
        inputs = t.inputs or (
            ((draw(st.sampled_from(names)), 1),) if draw(st.integers(0, 4)) else ()
        )
        transitions.append(Transition(t.name, inputs=inputs, outputs=outputs))
        if draw(st.booleans()):
            transitions.append(Transition(f"{t.name}_copy", inputs=inputs, outputs=outputs))
    for i in range(n_consumers):
        out = draw(st.dictionaries(st.sampled_from(names), st.integers(1, 2), max_size=2))
        transitions.append(
            Transition(f"f{i}", inputs=(("q", weight),), outputs=tuple(sorted(out.items())))
        )
    # Places in series with initial tokens: r -> mv -> an existing place.
    feeders = set(draw(st.lists(st.sampled_from(transitions), max_size=2)))
    transitions = [
        Transition(t.name, t.inputs, (*t.outputs, ("r", 1))) if t in feeders else t
        for t in transitions
    ]
    transitions.append(Transition("mv", (("r", 1),), ((draw(st.sampled_from(names)), 1),)))
    # Pre-agglomeration: h takes from its own place s and feeds pp alone; pp's
    # consumers take a from it and may need another place too.
    a = draw(st.integers(1, 2))
    feeders = set(draw(st.lists(st.sampled_from(transitions), max_size=2)))
    transitions = [
        Transition(t.name, t.inputs, (*t.outputs, ("s", 1))) if t in feeders else t
        for t in transitions
    ]
    transitions.append(Transition("h", (("s", 1),), (("pp", a),)))
    for i in range(draw(st.integers(1, 2))):
        extra = draw(st.dictionaries(st.sampled_from(names), st.integers(1, 2), max_size=1))
        out = draw(st.dictionaries(st.sampled_from(names), st.integers(1, 2), max_size=2))
        transitions.append(
            Transition(f"g{i}", (("pp", a), *sorted(extra.items())), tuple(sorted(out.items())))
        )
    for i in range(draw(st.integers(0, 2))):
        loop = draw(st.dictionaries(st.sampled_from(names), st.integers(1, 2), max_size=2))
        arcs = tuple(sorted(loop.items()))
        transitions.append(Transition(f"loop{i}", inputs=arcs, outputs=arcs))
    places = (
        *net.places,
        Place("q"),
        Place("r", draw(st.integers(0, 2))),
        Place("s", draw(st.integers(0, 2))),
        Place("pp"),
    )
    return Net(name="shaped", places=places, transitions=tuple(transitions))


@given(shaped_nets())
@settings(max_examples=60)
def test_deadlock_verdict_and_witness_survive_the_rules(net: Net) -> None:
    assert_deadlock_preserved(net)


@st.composite
def shaped_and_observed(draw: st.DrawFn) -> tuple[Net, list[str], list[str]]:
    net = draw(shaped_nets())
    places = draw(st.lists(st.sampled_from([p.name for p in net.places]), unique=True, max_size=3))
    names = [t.name for t in net.transitions]
    transitions = draw(st.lists(st.sampled_from(names), unique=True, max_size=2))
    return net, places, transitions


@given(shaped_and_observed())
@settings(max_examples=60)
def test_reachable_observations_and_bounds_are_the_same(
    case: tuple[Net, list[str], list[str]],
) -> None:
    """Equal sets of reachable (observed values, observed enabledness): every predicate
    and every bound over them answers alike; bounds are also checked with their own goal."""
    net, places, transitions = case
    original = assert_same_observations(net, places, transitions)
    if places:
        bounded = explore(reduce_net(net, Goal.bounds(places)).net, max_states=None)
        want = original.max_sum([net.place_index(p) for p in places])
        assert bounded.max_sum([bounded.net.place_index(p) for p in places]) == want


def _work(net: Net, goal: Goal | None = None) -> WorkNet:
    return WorkNet(net, goal or Goal.deadlock())


def _t(name: str, inputs: dict[str, int], outputs: dict[str, int]) -> Transition:
    return Transition(name, inputs=tuple(inputs.items()), outputs=tuple(outputs.items()))


def test_post_agglomeration_pairs_every_producer_with_every_consumer() -> None:
    net = Net(
        name="fan",
        places=(Place("a", 1), Place("b", 1), Place("q"), Place("x"), Place("y")),
        transitions=(
            _t("h1", {"a": 1}, {"q": 1, "b": 1}),
            _t("h2", {"b": 1}, {"q": 1}),
            _t("f1", {"q": 1}, {"x": 1}),
            _t("f2", {"q": 1}, {"y": 1}),
        ),
    )
    w = _work(net)
    assert post_agglomerate(w)
    assert "q" not in w.initial
    assert sorted(w.expand.values()) == [("h1", "f1"), ("h1", "f2"), ("h2", "f1"), ("h2", "f2")]
    assert w.post["h1.f2"] == {"b": 1, "y": 1}


def test_post_agglomeration_refuses_a_consumer_with_another_input() -> None:
    net = Net(
        name="guarded",
        places=(Place("a", 1), Place("g"), Place("q")),
        transitions=(_t("h", {"a": 1}, {"q": 1}), _t("f", {"q": 1, "g": 1}, {"a": 1})),
    )
    assert not post_agglomerate(_work(net))


def test_post_agglomeration_keeps_an_observed_consumer_output_for_reachability() -> None:
    net = Net(
        name="observed",
        places=(Place("a", 1), Place("q"), Place("x")),
        transitions=(_t("h", {"a": 1}, {"q": 1}), _t("f", {"q": 1}, {"x": 1})),
    )
    assert not post_agglomerate(_work(net, Goal.reachability(["x"])))
    assert post_agglomerate(_work(net, Goal.reachability(["a"])))


def test_duplicates_keep_the_observed_copy() -> None:
    net = Net(
        name="dup",
        places=(Place("a", 1),),
        transitions=(_t("t", {"a": 1}, {}), _t("u", {"a": 1}, {})),
    )
    w = _work(net, Goal.reachability((), ["u"]))
    assert remove_duplicate_transitions(w)
    assert list(w.pre) == ["u"]


def test_a_self_loop_goes_only_when_another_transition_covers_it() -> None:
    places = (Place("a", 1), Place("b", 1))
    loop = _t("loop", {"a": 1, "b": 1}, {"a": 1, "b": 1})
    covered = Net("c", places, (loop, _t("u", {"a": 1}, {"b": 1})))
    alone = Net("a", places, (loop, _t("u", {"a": 2}, {"b": 1})))
    assert remove_dominated_self_loops(_work(covered))
    assert not remove_dominated_self_loops(_work(alone))
    assert not remove_dominated_self_loops(_work(covered, Goal.reachability(["a"])))


def test_a_source_transition_collapses_the_net_for_deadlock_only() -> None:
    net = Net(
        name="source",
        places=(Place("a", 1), Place("b")),
        transitions=(_t("gen", {}, {"b": 1}), _t("t", {"a": 1, "b": 1}, {})),
    )
    w = _work(net)
    assert collapse_live(w)
    assert list(w.pre) == ["gen"] and w.post["gen"] == {} and not w.initial
    assert not collapse_live(_work(net, Goal.bounds(["b"])))
    answer = decide_deadlock(net)
    assert answer.deadlock is False
    assert len(answer.reduction.net.transitions) == 1 and not answer.reduction.net.places


def test_places_in_series_with_initial_tokens_start_the_witness_with_the_prefix() -> None:
    net = Net(
        name="prefix",
        places=(Place("r", 2), Place("s"), Place("lock", 1)),
        transitions=(
            _t("mv", {"r": 1}, {"s": 1}),
            _t("use", {"s": 1, "lock": 1}, {}),
            _t("give", {"lock": 1}, {"s": 1}),  # a second producer: no pre-agglomeration
        ),
    )
    red = reduce_net(net, Goal.deadlock())
    assert red.prefix == ("mv", "mv")
    answer = decide_deadlock(net)
    assert answer.deadlock is True and answer.trace is not None
    assert answer.trace[:2] == ["mv", "mv"]
    reached = replay(net, answer.trace)
    assert reached is not None and is_dead(net, reached)


def test_a_marked_two_cycle_with_a_reader_is_deadlock_free_without_a_search() -> None:
    """The SatelliteMemory shape: ``a`` and ``b`` pass one token around, ``read`` only
    tests ``b``. Fusing ``a`` into ``b`` (its token first) leaves a self-loop on a place
    that never loses its token: always enabled."""
    net = Net(
        name="cycle",
        places=(Place("a", 1), Place("b"), Place("c", 3)),
        transitions=(
            _t("ab", {"a": 1}, {"b": 1}),
            _t("ba", {"b": 1}, {"a": 1}),
            _t("read", {"b": 1, "c": 1}, {"b": 1}),
        ),
    )
    answer = decide_deadlock(net)
    assert answer.deadlock is False
    assert len(answer.reduction.net.transitions) == 1 and not answer.reduction.net.places


def test_pre_agglomeration_completes_the_witness_with_the_postponed_transition() -> None:
    """``mv`` only moves ``r``'s tokens to ``s``, which ``use`` consumes with the lock:
    ``mv`` is merged into ``use``. The reduced net is dead with a token left in ``r``,
    where the original can still fire ``mv``: the witness ends with it."""
    net = Net(
        name="pre",
        places=(Place("r", 2), Place("s"), Place("lock", 1)),
        transitions=(
            _t("mv", {"r": 1}, {"s": 1}),
            _t("use", {"s": 1, "lock": 1}, {}),
        ),
    )
    red = reduce_net(net, Goal.deadlock())
    assert red.applied.get("pre-agglomeration") == 1 and red.closers == (("mv",),)
    answer = decide_deadlock(net)
    assert answer.deadlock is True and answer.trace == ["mv", "use", "mv"]
    reached = replay(net, answer.trace)
    assert reached is not None and is_dead(net, reached)
