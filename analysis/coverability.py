"""Boundedness by the Karp-Miller coverability tree, with replayable pumping traces.

The tree starts at M0 and fires every enabled transition. When a new marking M'
strictly covers a marking M_a on its own path from the root (M_a <= M', M_a != M'),
the firing sequence from M_a to M' can be repeated forever, so every place where M'
exceeds M_a is unbounded: it becomes omega (ω). Only *ancestors* are compared, never
markings on other branches: a marking on a sibling branch proves nothing about what this
path can repeat. A marking already in the tree is not expanded again.

What a result proves:

* A place that becomes ω is unbounded: proven even if the tree was cut off by a limit.
* If the tree is complete and no place is ω, the net is bounded, and the largest value
  each place takes in the tree is its exact bound (the tree covers every reachable
  marking, and every finite value in it is attained).

For each unbounded place a *pumping trace* is sought: a firing sequence ``prefix`` to
M1 and a ``loop`` from M1 to M2 >= M1 with M2(p) > M1(p). It is checked by replaying it
on the net (`Net.enabled`/`Net.fire`), so it is evidence a person can run. The tree's
own path is used when no ω was introduced before it; otherwise the earlier pumps are
repeated along the path and the concrete run is searched for such a pair, and as a last
resort a small concrete search runs. A place whose trace was not found within budget is
still reported unbounded (the tree proves it), listed in ``missing_pumps``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget, stage, work_limit_reason
from analysis.inputs import legal_trace
from analysis.lastnet import last_net
from coral_lang.net import Net

Marking = tuple[int, ...]

OMEGA = -1
"""ω in an internal tree marking: more tokens than any bound. Never in a public result."""

_BIG = np.iinfo(np.int64).max // 4
"""ω in the numpy view of markings: larger than any token count the tree holds (a
count reaching it stops the tree, see `MAX_EXACT_TOKENS`)."""

MAX_EXACT_TOKENS = int(_BIG) - 1
"""Largest token count the tree represents exactly (2**61 - 2). A larger count would
be mistaken for ω (a bounded place reported unbounded) or overflow int64 (a traceback):
the tree stops there and leaves boundedness undecided, saying why."""

DEFAULT_MAX_NODES = 100_000
CHILDREN_PER_CHECK = 64
"""Children made between two readings of the budget inside one node (the root of a net
of 2,000 independent rings has 2,000, at a fraction of a millisecond each)."""
DEFAULT_TIME_LIMIT = 30.0
_MAX_CONCRETE_STEPS = 4_000
_PUMP_SEARCH_NODES = 20_000


@dataclass(frozen=True)
class PumpingTrace:
    """Evidence that ``place`` is unbounded: replay ``prefix``, then ``loop`` again and
    again; each round leaves every place at least as full and ``place`` fuller.

    Attributes:
        place: The unbounded place.
        place_index: Its position in `Net.places`.
        prefix: Transition indices from M0 to ``start``.
        loop: Transition indices from ``start`` to ``after``.
        prefix_names: The same, as transition names.
        loop_names: The same, as transition names.
        start: M1, the marking after the prefix.
        after: M2, the marking after one loop; M2 >= M1 and M2(place) > M1(place).
    """

    place: str
    place_index: int
    prefix: tuple[int, ...]
    loop: tuple[int, ...]
    prefix_names: tuple[str, ...]
    loop_names: tuple[str, ...]
    start: Marking
    after: Marking

    def explain(self) -> str:
        """One line a person can replay by hand."""
        gain = self.after[self.place_index] - self.start[self.place_index]
        return (
            f"'{self.place}' is unbounded: fire [{', '.join(self.prefix_names)}], then "
            f"repeat [{', '.join(self.loop_names)}]; each repetition adds {gain} token(s) "
            f"to '{self.place}' and removes none anywhere"
        )


@dataclass(frozen=True)
class CoverabilityResult:
    """What the Karp-Miller tree proves about boundedness.

    Attributes:
        bounded: True if the tree is complete and no place became ω (proof of
            boundedness); False if some place became ω (proof of unboundedness, even if
            incomplete); None if the tree was cut off before either was shown.
        complete: The tree was fully built.
        reason: Why it was cut off (node budget or time), empty when complete.
        unbounded: Places proven unbounded, in net order.
        pumps: A replay-checked `PumpingTrace` for each unbounded place where one was
            found.
        missing_pumps: Unbounded places without a trace (proven unbounded anyway).
        bounds: Place -> largest finite value in the tree, for places never ω. The exact
            bound when ``complete``; only a lower bound otherwise.
        nodes: Tree nodes built.
    """

    bounded: bool | None
    complete: bool
    reason: str
    unbounded: tuple[str, ...]
    pumps: dict[str, PumpingTrace]
    missing_pumps: tuple[str, ...]
    bounds: dict[str, int]
    nodes: int
    method: str = "Karp-Miller coverability tree"

    def explain(self) -> str:
        """One line for a report."""
        if self.bounded:
            top = max(self.bounds.values(), default=0)
            return (
                f"bounded: complete coverability tree ({self.nodes} nodes), "
                f"at most {top} token(s) in any place"
            )
        if self.bounded is False:
            return (
                f"unbounded: {', '.join(self.unbounded)} "
                f"({len(self.pumps)} with a replayable pumping trace)"
            )
        return f"boundedness undecided: coverability tree cut off ({self.reason})"


@dataclass
class _Node:
    marking: Marking
    parent: int  # -1 for the root
    transition: int  # -1 for the root
    # Accelerations made when this node was created: (ancestor node, places set to ω).
    pumps: list[tuple[int, tuple[int, ...]]] = field(default_factory=list)


_Arcs = list[list[tuple[int, int]]]


@last_net
def _arcs_of(net: Net) -> tuple[_Arcs, _Arcs, list[list[int]], list[int]]:
    """Per transition its input and output arcs as (place number, weight), per place the
    transitions that take from it, and the transitions without inputs. Only a
    transition whose input places are all marked can fire: a node looks at the
    consumers of its marked places (and the transitions without inputs), so a node
    costs what it marks, not the width of the net.

    The last net's are kept, read-only (the quick tree and the full one are grown on
    the same net, and on 20,000 transitions these lists took 0.07-0.2 s, the full
    tree's start often past the command's limit)."""
    inputs = [[(net.place_index(p), w) for p, w in t.inputs] for t in net.transitions]
    outputs = [[(net.place_index(p), w) for p, w in t.outputs] for t in net.transitions]
    consumers: list[set[int]] = [set() for _ in net.places]
    for t, arcs in enumerate(inputs):
        for p, _ in arcs:
            consumers[p].add(t)
    sources = [t for t, arcs in enumerate(inputs) if not arcs]
    return inputs, outputs, [sorted(c) for c in consumers], sources


class _Tree:
    """The Karp-Miller tree over ω-markings, built breadth first."""

    def __init__(self, net: Net) -> None:
        self.net = net
        self.inputs, self.outputs, self.consumers, self.sources = _arcs_of(net)
        start = net.initial_marking()
        self.nodes = [_Node(start, -1, -1)]
        # node markings, ω as _BIG; none when M0 itself is too large (build stops at once)
        self.rows = [_numeric([start])[0]] if max(start, default=0) <= MAX_EXACT_TOKENS else []

    def build(self, max_nodes: int, budget: Budget) -> tuple[bool, str]:
        too_many = self._too_many(self.nodes[0].marking, range(len(self.nodes[0].marking)))
        if too_many:
            return False, too_many
        seen = {self.nodes[0].marking}
        queue = deque([0])
        while queue:
            if len(self.nodes) >= max_nodes:
                return False, work_limit_reason(max_nodes, "node")
            if budget.expired():
                return False, budget.time_reason(len(self.nodes), "node")
            index = queue.popleft()
            marking = self.nodes[index].marking
            chain: list[int] | None = None
            ancestors = np.zeros((0, len(marking)), dtype=np.int64)
            for tried, t in enumerate(self._candidates(index), start=1):
                if not all(marking[p] == OMEGA or marking[p] >= w for p, w in self.inputs[t]):
                    continue
                # One node of a wide net has thousands of children, each costing the
                # width of the net: the budget is read inside the node too.
                if tried % CHILDREN_PER_CHECK == 0 and budget.expired():
                    return False, budget.time_reason(len(self.nodes), "node")
                if chain is None:  # shared by all children of this node
                    chain = self.path(index)
                    ancestors = np.stack([self.rows[i] for i in chain])
                fired = self._fire(marking, t)
                too_many = self._too_many(fired, (p for p, _ in self.outputs[t]))
                if too_many:  # only outputs grow a count: the other places were checked
                    return False, too_many
                child, row = self._accelerate(index, t, fired, chain, ancestors)
                if child.marking in seen:
                    continue
                seen.add(child.marking)
                self.nodes.append(child)
                self.rows.append(row)
                queue.append(len(self.nodes) - 1)
                if len(self.nodes) >= max_nodes:
                    return False, work_limit_reason(max_nodes, "node")
        return True, ""

    def _candidates(self, index: int) -> list[int]:
        """Transitions that may be enabled at node ``index``, in index order (so the
        tree is the one a scan of every transition builds)."""
        found = set(self.sources)
        for p in np.flatnonzero(self.rows[index]).tolist():
            found.update(self.consumers[p])
        return sorted(found)

    def _too_many(self, values: Sequence[int], places: Iterable[int]) -> str:
        """Why the tree must stop if a finite count among ``places`` of ``values`` is
        past `MAX_EXACT_TOKENS` (the numpy view cannot hold it apart from ω); else ""."""
        for p in places:
            if values[p] > MAX_EXACT_TOKENS:
                return (
                    f"'{self.net.places[p].name}' reaches {values[p]} tokens, more than the "
                    f"{MAX_EXACT_TOKENS} the tree represents exactly"
                )
        return ""

    def _fire(self, marking: Marking, t: int) -> list[int]:
        values = list(marking)
        for p, w in self.inputs[t]:
            if values[p] != OMEGA:
                values[p] -= w
        for p, w in self.outputs[t]:
            if values[p] != OMEGA:
                values[p] += w
        return values

    def _accelerate(
        self,
        parent: int,
        t: int,
        values: list[int],
        chain: list[int],
        ancestors: npt.NDArray[np.int64],
    ) -> tuple[_Node, npt.NDArray[np.int64]]:
        """Set to ω every place in which ``values`` strictly exceeds a covered ancestor;
        the node and its numeric row (ω as `_BIG`).

        ``chain`` lists the ancestors (root first) and ``ancestors`` holds their markings
        with ω as `_BIG`, so "covers" is a plain ``>=`` on every column. Repeats until no
        covered ancestor is strictly exceeded (new ω can make more ancestors covered);
        each pumped place is credited to the nearest ancestor that pumps it.
        """
        node = _Node((), parent, t)
        # The parent's row with the transition's arcs applied (ω stays ω): a copy in
        # numpy, where converting ``values`` would cost a Python int per place.
        current = self.rows[parent].copy()
        for p, _ in (*self.inputs[t], *self.outputs[t]):
            if current[p] < _BIG:
                current[p] = values[p]
        while True:
            covered = np.flatnonzero(np.all(ancestors <= current, axis=1))[::-1]
            if covered.size == 0:
                break
            # Covering means an ω in the ancestor is ω here too, so the places that grew
            # are the finite ones with more tokens.
            grown = (current > ancestors[covered]) & (current < _BIG)
            if not grown.any():
                break
            assigned = np.zeros(current.shape, dtype=bool)
            for row, places in zip(covered, grown, strict=True):
                new = places & ~assigned
                if new.any():
                    node.pumps.append((chain[int(row)], tuple(np.flatnonzero(new).tolist())))
                    assigned |= new
            current[assigned] = _BIG
        if node.pumps:
            node.marking = tuple(OMEGA if v >= _BIG else int(v) for v in current)
        else:  # the common case: nothing pumped, the fired marking stands as it is
            node.marking = tuple(values)
        return node, current

    def path(self, index: int) -> list[int]:
        """Node indices from the root to ``index``."""
        chain = []
        while index >= 0:
            chain.append(index)
            index = self.nodes[index].parent
        return chain[::-1]


def _numeric(markings: Sequence[Marking | list[int]]) -> npt.NDArray[np.int64]:
    """Markings as int64 rows with ω as `_BIG`, for vectorised covering checks."""
    rows = np.array(markings, dtype=np.int64).reshape(len(markings), -1)
    rows[rows == OMEGA] = _BIG
    return rows


def coverability(
    net: Net,
    max_nodes: int = DEFAULT_MAX_NODES,
    budget: Budget | None = None,
    find_pumps: bool = True,
) -> CoverabilityResult:
    """Build the Karp-Miller tree of ``net`` and report boundedness with evidence.

    Args:
        net: The net.
        max_nodes: Node budget for the tree.
        budget: Bounds the time to build the tree (default: `DEFAULT_TIME_LIMIT`
            seconds from now).
        find_pumps: Also construct a replay-checked pumping trace per unbounded place.

    Returns:
        A `CoverabilityResult`; never loops forever.
    """
    budget = stage(budget, DEFAULT_TIME_LIMIT)
    tree = _Tree(net)
    complete, reason = tree.build(max_nodes, budget)
    n_places = len(net.places)
    first_omega, top = _summarise(tree.nodes, n_places, tree.rows)
    unbounded = tuple(net.places[p].name for p in sorted(first_omega))
    pumps: dict[str, PumpingTrace] = {}
    if find_pumps:
        for p in sorted(first_omega):
            trace = _pump_for(net, tree, p, first_omega[p])
            if trace is not None:
                pumps[net.places[p].name] = trace
    bounds = {net.places[p].name: top[p] for p in range(n_places) if p not in first_omega}
    bounded: bool | None = False if unbounded else (True if complete else None)
    return CoverabilityResult(
        bounded=bounded,
        complete=complete,
        reason=reason,
        unbounded=unbounded,
        pumps=pumps,
        missing_pumps=tuple(n for n in unbounded if n not in pumps),
        bounds=bounds,
        nodes=len(tree.nodes),
    )


def node_cap(max_nodes: int, net: Net, cells: int) -> int:
    """``max_nodes``, lowered so that the tree holds at most ``cells`` place values:
    each node keeps its marking twice (a tuple and a numeric row, 16 bytes a place), so
    on a net of 20,000 places 2,000 nodes are 640 MB and seconds of work. Always at
    least one node (the root)."""
    return max(1, min(max_nodes, cells // max(1, len(net.places))))


SUMMARY_BLOCK = 512
"""Most tree nodes read into one array by `_summarise`."""

SUMMARY_CELLS = 1 << 20
"""Most place values of one `_summarise` block (8 MB): blocks of 512 nodes of 20,000
places were 80 MB arrays, freshly mapped each time, and summarising 1,000 nodes took
0.4 s after the tree's time was up; in blocks of this size, 0.03 s."""


def _summarise(
    nodes: Sequence[_Node],
    n_places: int,
    rows: Sequence[npt.NDArray[np.int64]] = (),
) -> tuple[dict[int, int], list[int]]:
    """Per place, the first node where it is omega and the largest finite count: block
    by block in numpy (a Python loop over nodes x places took 10 s of a 10 s budget on
    a 2,001-place net of 14,582 nodes). ``rows``, the tree's numeric rows (one per node,
    ω as `_BIG`), spare turning every marking tuple into numbers again: on wide nets that
    was a third of a second after the tree's time was up."""
    first_omega: dict[int, int] = {}
    top = np.zeros(n_places, dtype=np.int64)
    if n_places == 0:  # a mission with no places: nothing to summarise
        return first_omega, top.tolist()
    numeric = len(rows) == len(nodes)
    size = max(1, min(SUMMARY_BLOCK, SUMMARY_CELLS // n_places))
    for start in range(0, len(nodes), size):
        if numeric:
            block = np.stack(rows[start : start + size])
            omega = block >= _BIG
        else:
            block = np.array(
                [node.marking for node in nodes[start : start + size]], dtype=np.int64
            ).reshape(-1, n_places)
            omega = block == OMEGA
        top = np.maximum(top, np.where(omega, 0, block).max(axis=0, initial=0))
        seen = omega.any(axis=0)
        for p in np.flatnonzero(seen).tolist():
            if p not in first_omega:
                first_omega[p] = start + int(np.argmax(omega[:, p]))
    return first_omega, [int(v) for v in top]


# -- pumping traces ---------------------------------------------------------------------


def replay_pump(
    net: Net, prefix: Sequence[int], loop: Sequence[int], place: int
) -> tuple[Marking, Marking] | None:
    """Replay ``prefix`` then ``loop`` on the real net; return (M1, M2) if it pumps.

    It pumps when every transition is enabled in turn, M2 >= M1 and M2(place) >
    M1(place); then the loop can be fired forever (monotonicity).
    """
    marking = net.initial_marking()
    for t in prefix:
        tr = net.transitions[t]
        if not net.enabled(marking, tr):
            return None
        marking = net.fire(marking, tr)
    start = marking
    for t in loop:
        tr = net.transitions[t]
        if not net.enabled(marking, tr):
            return None
        marking = net.fire(marking, tr)
    if all(a >= s for a, s in zip(marking, start, strict=True)) and marking[place] > start[place]:
        return start, marking
    return None


def _trace(net: Net, place: int, prefix: Sequence[int], loop: Sequence[int]) -> PumpingTrace | None:
    # An operator input fires once and only while the run is on (analysis.inputs): the
    # loop never holds one, and the prefix is reordered so that each fires in time.
    legal = legal_trace(net, prefix)
    if legal is None:
        return None
    prefix = legal
    checked = replay_pump(net, prefix, loop, place)
    if checked is None:
        return None
    names = [t.name for t in net.transitions]
    return PumpingTrace(
        place=net.places[place].name,
        place_index=place,
        prefix=tuple(prefix),
        loop=tuple(loop),
        prefix_names=tuple(names[t] for t in prefix),
        loop_names=tuple(names[t] for t in loop),
        start=checked[0],
        after=checked[1],
    )


def _pump_for(net: Net, tree: _Tree, place: int, node: int) -> PumpingTrace | None:
    """A replay-checked pump for ``place``, first made ω at tree node ``node``."""
    path = tree.path(node)
    transitions = [tree.nodes[i].transition for i in path[1:]]
    position = {n: k for k, n in enumerate(path)}
    ancestor = next(a for a, places in tree.nodes[node].pumps if place in places)
    cut = position[ancestor]
    # 1. The tree's own loop, when it is concrete (often: no earlier ω on the path).
    trace = _trace(net, place, transitions[:cut], transitions[cut:])
    if trace is not None:
        return trace
    # 2. Repeat every earlier pump on the path, more for earlier ones, and look for a
    #    covering pair in the concrete run.
    for k in (1, 2, 3, 4, 6, 8, 12, 16):
        run = _unrolled(tree, path, transitions, k)
        if run is None:
            break
        trace = _pair_in_run(net, place, run)
        if trace is not None:
            return trace
    # 3. A small concrete search over firing sequences.
    return _search(net, place)


def _unrolled(tree: _Tree, path: list[int], transitions: list[int], k: int) -> list[int] | None:
    """The path's firing sequence with each acceleration loop repeated; earlier loops
    are repeated more (k ** later pumps), so they feed the later ones."""
    position = {n: i for i, n in enumerate(path)}
    pump_points = [i for i, n in enumerate(path) if tree.nodes[n].pumps]
    run: list[int] = []
    for i in range(1, len(path)):
        run.append(transitions[i - 1])
        node = tree.nodes[path[i]]
        if not node.pumps:
            continue
        later = sum(1 for j in pump_points if j > i)
        times = k ** (later + 1)
        start = min(position[a] for a, _ in node.pumps)
        loop = transitions[start:i]
        if len(run) + times * len(loop) > _MAX_CONCRETE_STEPS:
            return None
        run.extend(loop * times)
    return run


def _pair_in_run(net: Net, place: int, run: list[int]) -> PumpingTrace | None:
    """Fire ``run`` as far as it goes; find i < j with M_i <= M_j and M_i(p) < M_j(p)."""
    marking = net.initial_marking()
    seen = [marking]
    for t in run:
        tr = net.transitions[t]
        if not net.enabled(marking, tr):
            break
        marking = net.fire(marking, tr)
        if max(marking, default=0) > MAX_EXACT_TOKENS:
            break  # past int64's reach: compare only the markings before it
        seen.append(marking)
    rows = np.array(seen, dtype=np.int64)
    for j in range(1, len(rows)):
        below = np.all(rows[:j] <= rows[j], axis=1) & (rows[:j, place] < rows[j, place])
        hits = np.flatnonzero(below)
        if hits.size:
            i = int(hits[-1])
            return _trace(net, place, run[:i], run[i:j])
    return None


def _search(net: Net, place: int) -> PumpingTrace | None:
    """Breadth-first over firing sequences, comparing each marking with its ancestors."""
    start = net.initial_marking()
    # Each entry: (marking, transitions so far, markings on the path so far).
    queue: deque[tuple[Marking, tuple[int, ...], tuple[Marking, ...]]] = deque(
        [(start, (), (start,))]
    )
    explored = 0
    while queue and explored < _PUMP_SEARCH_NODES:
        marking, fired, history = queue.popleft()
        explored += 1
        for t, tr in enumerate(net.transitions):
            if not net.enabled(marking, tr):
                continue
            nxt = net.fire(marking, tr)
            if nxt in history:
                continue
            sequence = (*fired, t)
            for i, old in enumerate(history):
                if old[place] < nxt[place] and all(o <= n for o, n in zip(old, nxt, strict=True)):
                    return _trace(net, place, sequence[:i], sequence[i:])
            queue.append((nxt, sequence, (*history, nxt)))
    return None


__all__ = [
    "DEFAULT_MAX_NODES",
    "DEFAULT_TIME_LIMIT",
    "MAX_EXACT_TOKENS",
    "CoverabilityResult",
    "PumpingTrace",
    "coverability",
    "node_cap",
    "replay_pump",
]
