"""`analysis.timed.zones.Zone` against brute force over small integer valuations.

A zone is a set of integer points, so every operation has an obvious meaning on the
points: the tests enumerate them. Each zone is built inside the box where every
variable lies in ``0..D`` (``START`` is 0), so the point sets are finite and every
canonical bound must equal the largest difference the points attain: that is what
"canonical" promises and what the explorer reads off. Constants of the constraints
added lie in ``-D..D``, so the constraints cut the box in every way that matters.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from hypothesis import assume, given, settings
from hypothesis import strategies as st

from analysis.timed.zones import INF, NOW, START, Zone, ZoneLike

D = 6
"""Every variable of a test zone lies in ``0..D``."""

_PROFILE = settings.default
HEAVY = settings(max_examples=max(1, (100 if _PROFILE is None else _PROFILE.max_examples) // 2))
"""For the properties checking every point of a 5-variable box: half the examples of
the hypothesis profile in force (keeps the file fast, and ``explore`` still explores)."""

Point = tuple[int, ...]
Step = tuple[str, int, int, int, int]
"""``("le", i, j, c, _)``: ``x_i - x_j <= c``; ``("between", i, j, low, high)``."""


def box_zone(n: int) -> Zone:
    """``n`` variables (``START``, ``NOW`` and ``n - 2`` fresh ones), each in ``0..D``."""
    zone = Zone.initial().elapse()
    for _ in range(n - 2):
        zone, _var = zone.fresh()
    for var in range(1, n):
        constrained = zone.constrain(var, START, D)
        assert constrained is not None
        zone = constrained
    return zone


def box_points(n: int) -> list[Point]:
    """Every integer valuation of the box, ``START`` first and 0."""
    return [(0, *rest) for rest in itertools.product(range(D + 1), repeat=n - 1)]


def holds(point: Point, step: Step) -> bool:
    """Whether ``point`` satisfies ``step``."""
    kind, i, j, a, b = step
    diff = point[i] - point[j]
    return diff <= a if kind == "le" else a <= diff <= b


def apply(zone: Zone, step: Step) -> Zone | None:
    """``step`` added to ``zone`` by the operation under test."""
    kind, i, j, a, b = step
    return zone.constrain(i, j, a) if kind == "le" else zone.between(i, j, a, b)


def members(zone: Zone, candidates: Iterable[Point]) -> set[Point]:
    """The candidates the zone says it contains."""
    return {p for p in candidates if zone.contains(p)}


def assert_exact(zone: Zone, points: Sequence[Point]) -> None:
    """Every bound of ``zone`` is the largest difference its (non-empty) points attain."""
    assert points
    for i in range(zone.n):
        for j in range(zone.n):
            assert zone.bound(i, j) == max(p[i] - p[j] for p in points), (i, j)


@st.composite
def steps(draw: st.DrawFn, n: int, max_size: int = 5) -> list[Step]:
    """A few constraints over ``n`` variables, constants in ``-D..D``."""
    out: list[Step] = []
    for _ in range(draw(st.integers(0, max_size))):
        i, j = draw(st.permutations(range(n)).map(lambda p: (p[0], p[1])))
        if draw(st.booleans()):
            out.append(("le", i, j, draw(st.integers(-D, D)), 0))
        else:
            out.append(("between", i, j, draw(st.integers(-D, D)), draw(st.integers(-D, D))))
    return out


@dataclass(frozen=True)
class Case:
    """A zone built by the operations under test and its points by brute force."""

    zone: Zone
    points: list[Point]


def build(n: int, constraints: Sequence[Step]) -> Case | None:
    """The box with ``constraints`` added; None when the brute force finds it empty
    (after checking the zone agrees)."""
    zone: Zone | None = box_zone(n)
    points = box_points(n)
    for step in constraints:
        assert zone is not None
        zone = apply(zone, step)
        points = [p for p in points if holds(p, step)]
        assert (zone is None) == (not points), step
        if zone is None:
            return None
    assert zone is not None
    return Case(zone, points)


def build_nonempty(n: int, constraints: Sequence[Step]) -> Case:
    """The box with those of ``constraints`` added that leave it non-empty (each one
    that would empty it is checked to, by brute force, and skipped)."""
    zone = box_zone(n)
    points = box_points(n)
    for step in constraints:
        narrowed = apply(zone, step)
        kept = [p for p in points if holds(p, step)]
        assert (narrowed is None) == (not kept), step
        if narrowed is not None:
            zone, points = narrowed, kept
    return Case(zone, points)


@st.composite
def cases(draw: st.DrawFn, n: int | None = None) -> Case:
    """A non-empty zone of 3 or 4 variables (``n`` if given)."""
    size = draw(st.sampled_from([3, 4])) if n is None else n
    return build_nonempty(size, draw(steps(size)))


# -- constraints -----------------------------------------------------------------------


def test_the_box_and_the_initial_zone() -> None:
    initial = Zone.initial()
    assert initial.n == 2
    assert initial.contains((0, 0)) and not initial.contains((0, 1))
    assert initial.bound(NOW, START) == 0 and initial.bound(START, NOW) == 0
    for n in (3, 4):
        zone = box_zone(n)
        points = box_points(n)
        assert members(zone, points) == set(points)
        assert_exact(zone, points)


@given(st.sampled_from([3, 4]).flatmap(lambda n: st.tuples(st.just(n), steps(n, 7))))
def test_constrain_and_between_keep_exactly_the_points_satisfying_every_constraint(
    drawn: tuple[int, list[Step]],
) -> None:
    n, constraints = drawn
    zone: Zone | None = box_zone(n)
    everything = box_points(n)
    points = everything
    for step in constraints:
        assert zone is not None
        zone = apply(zone, step)
        points = [p for p in points if holds(p, step)]
        if zone is None:  # empty exactly when no point is left
            assert points == []
            return
        assert points
        assert members(zone, everything) == set(points)
        assert_exact(zone, points)


@given(st.sampled_from([3, 4]).flatmap(lambda n: st.tuples(st.just(n), steps(n, 7))))
def test_constrain_all_is_constrain_one_by_one(drawn: tuple[int, list[Step]]) -> None:
    n, constraints = drawn
    plain = [(i, j, c) for kind, i, j, c, _ in constraints if kind == "le"]
    together = box_zone(n).constrain_all(plain)
    one_by_one = build(n, [("le", i, j, c, 0) for i, j, c in plain])
    if one_by_one is None:
        assert together is None
    else:
        assert together is not None and together.key() == one_by_one.zone.key()


def test_contradictions_are_none() -> None:
    zone = box_zone(3)
    assert zone.between(2, NOW, 3, 2) is None
    assert zone.constrain(2, START, -1) is None  # a stamp before the start
    narrowed = zone.between(2, NOW, 1, 1)
    assert narrowed is not None and narrowed.constrain(NOW, 2, -2) is None
    assert narrowed.constrain(NOW, 2, -1) is narrowed  # already implied: unchanged


@given(cases(), steps(4, 3))
def test_operations_leave_their_operand_unchanged(case: Case, extra: list[Step]) -> None:
    zone = case.zone
    before = zone.key()
    for step in extra:
        if max(step[1], step[2]) < zone.n:
            apply(zone, step)
    zone.elapse()
    zone.stamp_now()
    zone.fresh()
    zone.keep([START, NOW])
    zone.merge(zone)
    zone.point([NOW], [True])
    assert zone.key() == before


# -- time and variables ----------------------------------------------------------------


@HEAVY
@given(cases())
def test_elapse_lets_now_grow_and_fixes_every_other_stamp(case: Case) -> None:
    zone = case.zone
    n = zone.n
    later = zone.elapse()
    assert all(later.bound(NOW, j) == INF for j in range(n) if j != NOW)
    image = {(*p[:NOW], t, *p[NOW + 1 :]) for p in case.points for t in range(p[NOW], D + 1)}
    assert members(later, box_points(n)) == image
    boxed = later.constrain(NOW, START, D)
    assert boxed is not None
    assert_exact(boxed, sorted(image))


@HEAVY
@given(cases())
def test_stamp_now_adds_a_variable_equal_to_now(case: Case) -> None:
    stamped, var = case.zone.stamp_now()
    n = case.zone.n
    assert var == n and stamped.n == n + 1
    expected = {(*p, p[NOW]) for p in case.points}
    assert members(stamped, box_points(n + 1)) == expected
    assert_exact(stamped, sorted(expected))


@HEAVY
@given(cases())
def test_fresh_adds_a_variable_only_known_to_follow_the_start(case: Case) -> None:
    widened, var = case.zone.fresh()
    n = case.zone.n
    assert var == n and widened.n == n + 1
    assert widened.bound(var, START) == INF and widened.bound(START, var) == 0
    boxed = widened.constrain(var, START, D)
    assert boxed is not None
    expected = {(*p, t) for p in case.points for t in range(D + 1)}
    assert members(boxed, box_points(n + 1)) == expected
    assert_exact(boxed, sorted(expected))


def _normal(point: Sequence[int]) -> Point:
    """A zone constrains differences only: points equal up to a shift are alike."""
    return tuple(x - point[0] for x in point)


@HEAVY
@given(cases(4), st.data())
def test_keep_projects_onto_the_variables_in_the_order_given(
    case: Case, data: st.DataObject
) -> None:
    chosen = data.draw(st.lists(st.integers(0, 3), min_size=1, max_size=4, unique=True))
    kept = case.zone.keep(chosen)
    assert kept.n == len(chosen)
    projected = [tuple(p[v] for v in chosen) for p in case.points]
    assert_exact(kept, projected)
    shapes = {_normal(p) for p in projected}
    for candidate in itertools.product(range(D + 1), repeat=len(chosen)):
        assert kept.contains(candidate) == (_normal(candidate) in shapes), candidate


@HEAVY
@given(st.sampled_from([3, 4]).flatmap(lambda n: st.tuples(cases(n), cases(n))))
def test_includes_is_inclusion_of_the_point_sets(pair: tuple[Case, Case]) -> None:
    first, second = pair
    assert first.zone.includes(second.zone) == (set(second.points) <= set(first.points))
    assert second.zone.includes(first.zone) == (set(first.points) <= set(second.points))
    assert first.zone.includes(first.zone)


def test_includes_reads_the_lower_bounds_too() -> None:
    # Both zones keep NOW <= x_2; they differ only in x_2's lower bound, which no
    # other entry of the matrix reflects.
    wide = box_zone(3).constrain(NOW, 2, 0)
    assert wide is not None
    narrow = wide.between(2, START, 3, D)
    assert narrow is not None
    assert wide.includes(narrow)
    assert not narrow.includes(wide)


def _hull(points: Iterable[Point], n: int) -> set[Point]:
    """The box points of the smallest zone holding ``points``."""
    pts = list(points)
    top = [[max(p[i] - p[j] for p in pts) for j in range(n)] for i in range(n)]
    return {
        q
        for q in box_points(n)
        if all(q[i] - q[j] <= top[i][j] for i in range(n) for j in range(n))
    }


@HEAVY
@given(st.sampled_from([3, 4]).flatmap(lambda n: st.tuples(cases(n), cases(n))))
def test_merge_is_a_zone_exactly_when_the_union_is_one(pair: tuple[Case, Case]) -> None:
    first, second = pair
    n = first.zone.n
    union = set(first.points) | set(second.points)
    convex = union == _hull(union, n)
    for a, b in ((first, second), (second, first)):
        merged = a.zone.merge(b.zone)
        assert (merged is not None) == convex
        if merged is not None:
            assert members(merged, box_points(n)) == union
            assert_exact(merged, sorted(union))


@HEAVY
@given(cases(), st.data())
def test_a_zone_split_in_two_merges_back(case: Case, data: st.DataObject) -> None:
    n = case.zone.n
    i, j = data.draw(st.permutations(range(n)).map(lambda p: (p[0], p[1])))
    c = data.draw(st.integers(-D, D))
    low = case.zone.constrain(i, j, c)
    high = case.zone.constrain(j, i, -c - 1)  # x_i - x_j >= c + 1
    assume(low is not None and high is not None)
    assert low is not None and high is not None
    merged = low.merge(high)
    assert merged is not None and merged.key() == case.zone.key()
    # A zone merged with a part of itself is itself.
    inner = low.merge(case.zone)
    assert inner is not None and inner.key() == case.zone.key()


@HEAVY
@given(cases(), st.data())
def test_two_slices_of_a_zone_merge_exactly_when_their_union_is_a_zone(
    case: Case, data: st.DataObject
) -> None:
    n = case.zone.n
    i, j = data.draw(st.permutations(range(n)).map(lambda p: (p[0], p[1])))
    cut = st.tuples(st.integers(-D, D), st.integers(-D, D)).map(sorted)
    (a, b), (c, d) = data.draw(cut), data.draw(cut)
    first = build_on(case, ("between", i, j, a, b))
    second = build_on(case, ("between", i, j, c, d))
    assume(first is not None and second is not None)
    assert first is not None and second is not None
    union = set(first.points) | set(second.points)
    merged = first.zone.merge(second.zone)
    assert (merged is not None) == (union == _hull(union, n))
    if merged is not None:
        assert members(merged, box_points(n)) == union


def build_on(case: Case, step: Step) -> Case | None:
    """``case`` with ``step`` added (None: empty, checked against the brute force)."""
    zone = apply(case.zone, step)
    points = [p for p in case.points if holds(p, step)]
    assert (zone is None) == (not points)
    return None if zone is None else Case(zone, points)


def test_two_corners_do_not_merge() -> None:
    zone = box_zone(3)
    a = zone.between(NOW, START, 0, 1)
    b = zone.between(NOW, START, 3, 4)
    assert a is not None and b is not None
    assert a.merge(b) is None  # the hull holds NOW = 2, in neither


# -- concrete points ---------------------------------------------------------------------


def _greedy(points: Sequence[Point], order: Sequence[int], high: Sequence[bool]) -> Point:
    """What `Zone.point` promises, by brute force."""
    n = len(points[0])
    left = list(points)
    sequence = [*order, *(v for v in range(n) if v not in order)]
    for index, var in enumerate(sequence):
        pick = max if index < len(high) and high[index] else min
        value = pick(p[var] for p in left)
        left = [p for p in left if p[var] == value]
    (point,) = left
    return point


@given(cases(), st.data())
def test_point_fixes_the_variables_in_order_at_their_extremes(
    case: Case, data: st.DataObject
) -> None:
    n = case.zone.n
    order = data.draw(st.lists(st.integers(0, n - 1), max_size=n, unique=True))
    high = data.draw(st.lists(st.booleans(), min_size=len(order), max_size=len(order)))
    point = case.zone.point(order, high)
    assert point[START] == 0
    assert case.zone.contains(point)
    assert tuple(point) == _greedy(case.points, order, high)
    if order and order[0] != START and high[0]:
        assert point[order[0]] == case.zone.bound(order[0], START)


def test_point_of_an_unbounded_variable_takes_its_lowest_value() -> None:
    zone, var = Zone.initial().elapse().fresh()
    narrowed = zone.constrain(START, var, -2)  # var >= 2, no upper bound
    assert narrowed is not None
    assert narrowed.point([var, NOW], [True, True]) == [0, 0, 2]


def test_a_zone_is_zone_like() -> None:
    zone: ZoneLike = Zone.initial()
    stamped, var = zone.elapse().stamp_now()
    assert stamped.bound(var, NOW) == 0 and stamped.bound(NOW, var) == 0
