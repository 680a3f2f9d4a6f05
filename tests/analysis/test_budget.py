"""The one budget object: reasons in one shape, slices that never outlive their parent,
z3's milliseconds from one place, and every budget-limited search driven to its
deadline by a fake clock (no sleeps)."""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.budget import (
    Z3_NO_TIMEOUT_MS,
    Budget,
    BudgetExceeded,
    stage,
    time_limit_reason,
    work_limit_reason,
)
from analysis.coverability import coverability
from analysis.ctl import CtlChecker
from analysis.invariants import p_invariants
from analysis.report import Verdict
from analysis.siphons import minimal_siphons
from analysis.stategraph import GraphError, build_graph
from analysis.statespace import explore
from analysis.verify import VerifyOptions, verify
from coral_lang.formula import Exists, Finally, Fireable
from coral_lang.net import Net
from tests.analysis.nets import make_net, mutex

TIME_REASON = re.compile(r"time limit of (\S+) s reached( after [\d,]+ [a-z ]+)?$")
"""The one shape of a time limit's reason, wherever it ends a search."""


class FakeClock:
    """A clock that only moves when told to, or by ``step`` on every reading."""

    def __init__(self, step: float = 0.0) -> None:
        self.now = 0.0
        self.step = step

    def __call__(self) -> float:
        now = self.now
        self.now += self.step
        return now


def _ticking() -> Callable[[], float]:
    ticks = itertools.count()
    return lambda: float(next(ticks))


def _pump() -> Net:
    return make_net("pump", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})


# -- reason texts ------------------------------------------------------------------------


def test_reason_texts_have_one_shape() -> None:
    assert time_limit_reason(120) == "time limit of 120 s reached"
    assert time_limit_reason(0.5, 1_234_567) == "time limit of 0.5 s reached after 1,234,567 states"
    assert time_limit_reason(2, 1, "edge") == "time limit of 2 s reached after 1 edge"
    assert work_limit_reason(2_000_000) == "state budget of 2,000,000 reached"
    assert work_limit_reason(100, "edge") == "edge budget of 100 reached"


@given(
    st.floats(min_value=0.001, max_value=1e6, allow_nan=False),
    st.none() | st.integers(min_value=0, max_value=10**12),
    st.sampled_from(["state", "edge", "node", "row", "partial set"]),
)
def test_every_time_reason_matches_the_shape(seconds: float, done: int | None, unit: str) -> None:
    text = time_limit_reason(seconds, done, unit)
    shape = TIME_REASON.match(text)
    assert shape, text
    assert float(shape.group(1)) == pytest.approx(seconds, rel=1e-5)
    assert (shape.group(2) is None) == (done is None)


# -- the budget --------------------------------------------------------------------------


def test_check_raises_at_the_deadline_and_at_the_work_cap() -> None:
    clock = FakeClock()
    budget = Budget(10.0, 5, unit="row", clock=clock)
    budget.check(4)
    clock.now = 10.0
    budget.check(4)  # at the deadline, not past it
    with pytest.raises(BudgetExceeded, match=r"^row budget of 5 reached$"):
        budget.check(5)
    clock.now = 10.5
    with pytest.raises(BudgetExceeded) as caught:
        budget.check(3)
    assert caught.value.reason == "time limit of 10 s reached after 3 rows"
    assert str(caught.value) == caught.value.reason


def test_no_limit_never_expires() -> None:
    clock = FakeClock()
    budget = Budget(clock=clock)
    clock.now = 1e12
    assert not budget.expired() and budget.remaining() is None
    budget.check(10**15)
    assert budget.elapsed() == 1e12


def test_remaining_is_never_negative() -> None:
    clock = FakeClock()
    budget = Budget(2.0, clock=clock)
    clock.now = 1.5
    assert budget.remaining() == pytest.approx(0.5)
    clock.now = 9.0
    assert budget.remaining() == 0.0 and budget.expired()


@pytest.mark.parametrize("seconds", [-1.0, float("nan")])
def test_a_bad_limit_is_refused(seconds: float) -> None:
    with pytest.raises(ValueError, match="seconds"):
        Budget(seconds)
    with pytest.raises(ValueError, match="work cap"):
        Budget(work=-1)


@given(
    st.none() | st.floats(min_value=0, max_value=1e4),
    st.none() | st.floats(min_value=0, max_value=1e4),
    st.floats(min_value=0, max_value=1e4),
)
def test_a_child_never_outlives_its_parent(
    parent_s: float | None, child_s: float | None, later: float
) -> None:
    clock = FakeClock()
    parent = Budget(parent_s, clock=clock)
    clock.now = later
    child = parent.child(seconds=child_s)
    assert child.clock is parent.clock
    if parent.deadline is not None:
        assert child.deadline is not None and child.deadline <= parent.deadline
    if child_s is not None:
        assert child.deadline is not None and child.deadline <= later + child_s
    if parent.deadline is None and child_s is None:
        assert child.deadline is None
    # Whenever the parent has expired, so has the child.
    clock.now = max(later, parent.deadline or later) + 1
    if parent.expired():
        assert child.expired()


def test_a_child_cut_short_by_its_parent_quotes_the_parents_limit() -> None:
    clock = FakeClock()
    parent = Budget(120.0, clock=clock)
    clock.now = 100.0
    child = parent.child(seconds=60.0)
    assert child.deadline == 120.0 and child.time_reason() == "time limit of 120 s reached"
    own = parent.child(seconds=5.0)
    assert own.deadline == 105.0 and own.time_reason() == "time limit of 5 s reached"


def test_a_share_of_the_time_left_quotes_the_parents_limit() -> None:
    clock = FakeClock()
    parent = Budget(10.0, clock=clock)
    clock.now = 6.0
    share = parent.child(seconds=0.8 * 4.0, share=True)  # (4 s left)
    assert share.deadline == 6.0 + 0.8 * 4.0
    assert share.time_reason() == "time limit of 10 s reached"


def test_a_child_has_its_own_work_cap_and_unit() -> None:
    parent = Budget(work=10, clock=FakeClock())
    child = parent.child(work=3, unit="edge")
    assert (child.work, child.unit) == (3, "edge")
    assert parent.child().work is None  # states and edges are not the same work


def test_stage_gives_the_default_limit_only_without_a_caller_budget() -> None:
    assert stage(None, 20.0).limit == 20.0
    caller = Budget(clock=FakeClock())
    assert stage(caller, 20.0).deadline is None
    assert stage(caller, 20.0, work=7).work == 7


def test_z3_time_out_comes_from_one_place() -> None:
    clock = FakeClock()
    budget = Budget(30.0, clock=clock)
    assert budget.z3_timeout_ms(10.0) == 10_000  # the query's own cap
    clock.now = 29.75
    assert budget.z3_timeout_ms(10.0) == 250  # what is left of the budget
    clock.now = 31.0
    assert budget.z3_timeout_ms(10.0) == 1  # never 0: z3 would read "no time-out"
    assert Budget(clock=clock).z3_timeout_ms() == Z3_NO_TIMEOUT_MS
    assert Budget(clock=clock).z3_timeout_ms(0.0001) == 1


# -- every budget-limited search, driven to its deadline by a fake clock -----------------


def test_the_explicit_search_stops_at_the_deadline() -> None:
    space = explore(_pump(), max_states=None, budget=Budget(5.0, clock=_ticking()), chunk=1)
    assert not space.complete and space.stopped_reason is not None
    assert TIME_REASON.match(space.stopped_reason)
    assert re.search(r" states?$", space.stopped_reason)


def test_the_explicit_search_takes_a_work_cap_from_the_budget() -> None:
    space = explore(_pump(), max_states=None, budget=Budget(work=7))
    assert space.states == 7 and space.stopped_reason == "state budget of 7 reached"


def test_the_graph_build_stops_at_the_deadline() -> None:
    space = explore(mutex())
    with pytest.raises(GraphError) as caught:
        build_graph(space, budget=Budget(0.5, clock=_ticking()))
    reason = str(caught.value).removeprefix("building the edges: ")
    assert TIME_REASON.match(reason), reason


def test_the_karp_miller_tree_stops_at_the_deadline() -> None:
    result = coverability(_pump(), budget=Budget(2.5, clock=_ticking()))
    assert not result.complete and TIME_REASON.match(result.reason), result.reason


def test_the_invariants_stop_at_the_deadline() -> None:
    result = p_invariants(mutex(), budget=Budget(0.5, clock=_ticking()))
    assert not result.complete and TIME_REASON.match(result.reason), result.reason


def test_the_siphon_search_stops_at_the_deadline() -> None:
    # x0 is fed by u0 and y0 by v0, both taking x1 and y1, fed alike from level 2, ...:
    # a siphon grown from x0 branches two ways per level (thousands of partial sets).
    depth = 12
    places = {f"{p}{i}": 1 for i in range(depth + 1) for p in "xy"}
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(depth):
        inputs = {f"x{i + 1}": 1, f"y{i + 1}": 1}
        transitions[f"u{i}"] = (inputs, {f"x{i}": 1})
        transitions[f"v{i}"] = (inputs, {f"y{i}": 1})
    net = make_net("binary", places, transitions)
    result = minimal_siphons(net, budget=Budget(0.5, clock=_ticking()))
    assert not result.complete and TIME_REASON.match(result.reason), result.reason


def test_ctl_labelling_stops_at_the_deadline() -> None:
    graph = build_graph(explore(mutex()))
    checker = CtlChecker(graph, budget=Budget(0.5, clock=_ticking()))
    with pytest.raises(BudgetExceeded) as caught:
        checker.sat(Exists(Finally(Fireable(("enter1",)))))
    assert TIME_REASON.match(caught.value.reason.removeprefix("labelling stopped: "))


def test_a_whole_verification_runs_on_the_budgets_clock() -> None:
    """`verify` times every stage on the budget's clock and gives the explicit search a
    slice of ``time_limit`` of it: on a clock that ticks a second per reading, a net of
    16,384 markings stops at 5 s, and the report says so in the one shape (that the
    proofs after a stopped search still run is in test_command_budget.py)."""
    n = 14
    places = {f"a{i}": 1 for i in range(n)} | {f"b{i}": 0 for i in range(n)}
    transitions = {f"on{i}": ({f"a{i}": 1}, {f"b{i}": 1}) for i in range(n)} | {
        f"off{i}": ({f"b{i}": 1}, {f"a{i}": 1}) for i in range(n)
    }
    net = make_net("toggles", places, transitions)
    options = VerifyOptions(structural=False, time_limit=5)
    first = verify(net, options, budget=Budget(clock=_ticking()))
    reason = first.statespace.stopped_reason
    assert not first.statespace.complete and reason is not None
    assert TIME_REASON.match(reason) and reason.startswith("time limit of 5 s reached after ")
    assert first.seconds == int(first.seconds) > 5  # whole ticks: the fake clock's seconds
    again = verify(net, options, budget=Budget(clock=_ticking()))
    assert again.statespace.stopped_reason == reason and again.seconds == first.seconds
    # The limit bounds the whole command: the state equation after the search is not
    # started once it has passed, and the verdict says which limit stopped it.
    deadlock = first.property("deadlock")
    assert deadlock.verdict is Verdict.INCONCLUSIVE
    assert "before the state equation" in deadlock.detail and "time limit of 5 s" in deadlock.detail
