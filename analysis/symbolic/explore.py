"""The reachable markings of a net and the StateSpace answers from them.

By default by saturation on the nodes of a multi-valued diagram (`analysis.symbolic.mdd`,
answered on it; `_by_nodes`); when that gives up, or with `strategy="sets"` or
`"chaining"`, as a BDD by a set-level fixpoint over per-transition relations
(`analysis.symbolic.saturate`; chaining kept to measure against).

For the BDD, each transition gets its own relation over only the places it touches (a partitioned
relation): places it reads without changing are a guard on the current bits, places it
changes map current bits to next bits. Images are `and_exists` then a rename. The
chained schedule applies the transitions in order of their top place in the variable
order, so one sweep carries tokens along a whole causal chain (Roig, Cortadella and
Pastor, "Verification of asynchronous circuits by BDD-based model checking of Petri
nets", 1995). Counters are sized by P-invariant bounds where one exists; a counter that
would outgrow its bits is detected before any image is taken, the encoding widened and
the fixpoint restarted: a value never wraps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import dd.cudd as cudd

from analysis.budget import Budget, memory_limit_reason, resident_bytes
from analysis.symbolic.encoding import (
    Encoding,
    arc_weights,
    initial_bits,
    invariant_facts,
    level_order,
    place_order,
)
from analysis.symbolic.mdd import MddSaturation, Stopped, Unbounded
from analysis.symbolic.saturate import Saturation
from analysis.symbolic.trace import TraceError, shortest_to_dead
from coral_lang.net import Net

Bdd = Any  # dd.cudd.Function: the stubs of dd are not typed


@dataclass(frozen=True)
class SymbolicLimits:
    """Budgets of a symbolic run. `max_bits` caps a place's counter: a place needing
    more is reported as possibly unbounded (inconclusive), never silently wrapped."""

    time_limit: float | None = None
    max_nodes: int | None = 50_000_000
    max_bits: int = 16
    max_memory: int | None = None  # bytes for CUDD's tables; None: CUDD's default
    budget: Budget | None = None
    """The command's budget: its deadline and memory limit bound the run too (checked
    after every transition's image, and inside counting and the trace search)."""
    trace: bool = True
    """Search a shortest firing sequence to a dead marking (forward layers of images,
    `analysis.symbolic.trace`)."""
    strategy: Literal["saturation", "sets", "chaining"] = "saturation"
    """The fixpoint's schedule: saturation on the nodes of a multi-valued diagram
    (`analysis.symbolic.mdd`, then converted to a BDD); "sets", the set-level schedule
    of `analysis.symbolic.saturate`, and "chaining", the oldest, kept to measure
    against."""


BYTES_PER_NODE = 48
"""What one CUDD node costs with its share of the unique table and computed cache: the
memory limit becomes a node budget, checked after every image (an allocation CUDD
cannot make is caught too, but the node budget stops the run well before)."""

NODE_CHECK_SECONDS = 0.1


@dataclass
class SymbolicResult:
    """What the fixpoint learned. `complete` False means `reason` says which budget
    stopped it; the counts then describe the markings found so far (a lower bound).
    `peak_nodes` and `iterations` are the MDD's nodes and node images after node
    saturation, the BDD's peak nodes and rounds (or sweeps) after a set-level one."""

    complete: bool
    reason: str | None
    states: int
    max_tokens_place: int
    max_tokens_marking: int
    place_bounds: dict[str, int]
    deadlock: bool | None
    deadlock_marking: dict[str, int] | None
    deadlock_trace: list[str] | None
    seconds: float
    peak_nodes: int
    iterations: int
    bits: list[int] = field(default_factory=list)


class _Overflow(Exception):
    def __init__(self, places: set[int]) -> None:
        super().__init__(f"counters overflow: {sorted(places)}")
        self.places = places


class _Budget(Exception):
    """A budget ran out in a pass after the fixpoint; the message says which."""


class _Deadline:
    """The limits of one run as one check: the time limit from `start`, the command
    budget's deadline and memory limit, and the node budget (from `max_nodes` and the
    memory left when the run started). `reason()` is None while every limit holds."""

    def __init__(self, limits: SymbolicLimits, start: float) -> None:
        self.limits = limits
        self.start = start
        self.max_nodes = limits.max_nodes
        self.memory_reason: str | None = None
        self.next_count = 0.0
        self.last_nodes = 0
        budget = limits.budget
        if budget is not None and budget.memory is not None:
            spare = max(0, budget.memory - resident_bytes()) // BYTES_PER_NODE
            if self.max_nodes is None or spare < self.max_nodes:
                self.max_nodes = spare
                self.memory_reason = memory_limit_reason(budget.memory)

    def reason(self, nodes: int = 0) -> str | None:
        limits = self.limits
        if limits.time_limit is not None and time.monotonic() - self.start > limits.time_limit:
            return f"time limit of {limits.time_limit:g} s"
        budget = limits.budget
        if budget is not None and budget.expired():
            return budget.time_reason()
        if self.max_nodes is not None and nodes > self.max_nodes:
            return self.memory_reason or f"node budget of {self.max_nodes} BDD nodes"
        return None

    def nodes(self, bdd: Any) -> int:
        """CUDD's live node count, read at most every `NODE_CHECK_SECONDS` and never
        more than 5% of the time: reading it walks the whole unique table
        (`Cudd_CheckZeroRef`, 40 ms on a grown table), which cost 75% of a fixpoint
        when read after every image; in between, the last count."""
        now = time.monotonic()
        if now >= self.next_count:
            self.last_nodes = len(bdd)
            spent = time.monotonic() - now
            self.next_count = now + max(NODE_CHECK_SECONDS, 20 * spent)
        return self.last_nodes

    def check(self) -> None:
        """Raise `_Budget` once a limit is passed (for the passes after the fixpoint)."""
        reason = self.reason()
        if reason is not None:
            raise _Budget(reason)


@dataclass
class _Transition:
    name: str
    relation: Bdd  # guard and updates, over x of read places and x, y of changed ones
    enabled: Bdd  # over x only
    overflow: dict[int, Bdd]  # per changed place: enabled and the result exceeds the counter
    changed: list[int]
    qvars: set[str]
    rename: dict[str, str]
    top: int
    support: set[int]


class SymbolicNet:
    """A net's encoding in one BDD manager: the initial marking, transitions, helpers."""

    def __init__(
        self,
        net: Net,
        bits: list[int],
        limits: SymbolicLimits,
        deadline: _Deadline | None = None,
        proven: frozenset[int] = frozenset(),
        order: list[int] | None = None,
    ) -> None:
        self.net = net
        self.proven = proven  # places whose bits hold a P-invariant bound
        self.limits = limits
        self.enc = Encoding(tuple(place_order(net) if order is None else order), tuple(bits))
        self.bdd = cudd.BDD()
        self.bdd.configure(reordering=False)
        max_memory = limits.max_memory
        budget = limits.budget
        if budget is not None and budget.memory is not None:
            spare = max(1 << 24, budget.memory - resident_bytes())
            max_memory = spare if max_memory is None else min(max_memory, spare)
        if max_memory is not None:
            self.bdd.configure(max_memory=max_memory)
        # (declaring 40,000 variables and the initial cube take a while on a wide net:
        # the budget is read before and after each)
        if deadline is not None:
            deadline.check()
        self.bdd.declare(*self.enc.declaration())
        if deadline is not None:
            deadline.check()
        self.level_of_place = {p: i for i, p in enumerate(self.enc.order)}
        self.xvars = [v for p in self.enc.order for v in self.enc.xs(p)]
        self.initial = self.marking_cube([p.initial for p in net.places], current=True)
        self.transitions: list[_Transition] = []
        for tr in net.transitions:
            pre, post = arc_weights(net, tr)
            self.transitions.append(self._transition(tr.name, pre, post))
            if deadline is not None:
                deadline.check()  # a wide net's relations take a while to build
        self.transitions.sort(key=lambda t: -t.top)

    def value(self, place: int, v: int, *, current: bool = True) -> Bdd:
        """The cube `place == v` over its x (or y) bits."""
        names = self.enc.xs(place) if current else self.enc.ys(place)
        k = len(names)
        return self.bdd.cube({name: bool((v >> (k - 1 - i)) & 1) for i, name in enumerate(names)})

    def at_least(self, place: int, w: int) -> Bdd:
        """`place >= w` over its x bits, by the usual MSB-first comparison."""
        names = self.enc.xs(place)
        k = len(names)
        if w <= 0:
            return self.bdd.true
        if w > (1 << k) - 1:
            return self.bdd.false
        result = self.bdd.true  # suffix >= suffix of w, built from the LSB up
        for i in reversed(range(k)):
            bit = (w >> (k - 1 - i)) & 1
            var = self.bdd.var(names[i])
            result = (var & result) if bit else (var | result)
        return result

    def shifted(self, place: int, delta: int) -> Bdd:
        """``y == x + delta`` for the place's counter, with neither overflow nor
        underflow: a ripple-carry adder (or borrow subtractor) of the constant over
        the bits, least significant first, so its cost is the counter's width, not
        the values it can hold (a 16-bit counter has 65,536)."""
        bdd = self.bdd
        xs, ys = self.enc.xs(place), self.enc.ys(place)
        k = len(xs)
        amount = abs(delta)
        if amount > (1 << k) - 1:
            return bdd.false
        result = bdd.true
        carry = bdd.false  # carry (adding) or borrow (subtracting) into this bit
        for i in reversed(range(k)):  # names are most significant first
            x, y = bdd.var(xs[i]), bdd.var(ys[i])
            c = bool((amount >> (k - 1 - i)) & 1)
            total = bdd.apply("<=>", x, carry) if c else bdd.apply("xor", x, carry)
            result &= bdd.apply("<=>", y, total)
            if delta > 0:
                carry = (x | carry) if c else (x & carry)
            else:
                carry = (~x | carry) if c else (~x & carry)
        return result & ~carry

    def marking_cube(self, marking: list[int], *, current: bool) -> Bdd:
        """The cube of one marking over every place's x (or y) bits, in one call: a
        cube costs the number of declared variables, so a cube per place, conjoined,
        cost their square (20,000 places: 196 s)."""
        literals: dict[str, bool] = {}
        for p, v in enumerate(marking):
            names = self.enc.xs(p) if current else self.enc.ys(p)
            k = len(names)
            literals.update({name: bool((v >> (k - 1 - i)) & 1) for i, name in enumerate(names)})
        return self.bdd.cube(literals)

    def _transition(self, name: str, pre: dict[int, int], post: dict[int, int]) -> _Transition:
        bdd = self.bdd
        relation = bdd.true
        enabled = bdd.true
        overflow: dict[int, Bdd] = {}
        changed: list[int] = []
        qvars: set[str] = set()
        rename: dict[str, str] = {}
        for p in sorted(set(pre) | set(post)):
            w_in, w_out = pre.get(p, 0), post.get(p, 0)
            guard = self.at_least(p, w_in)
            enabled &= guard
            delta = w_out - w_in
            if delta == 0:
                relation &= guard
                continue
            changed.append(p)
            cap = self.enc.capacity(p)
            # the guard too: a loop that takes 3 and gives back 2 shifts by -1 but needs 3
            relation &= guard & self.shifted(p, delta)
            if delta > 0 and p not in self.proven:
                # filled in below, once the guard is complete; a place whose bound a
                # P-invariant proves never outgrows the counter sized for it
                overflow[p] = self.at_least(p, max(w_in, cap - delta + 1))
            qvars.update(self.enc.xs(p))
            rename.update(zip(self.enc.ys(p), self.enc.xs(p), strict=True))
        overflow = {p: enabled & cond for p, cond in overflow.items()}
        support = set(pre) | set(post)
        top = min((self.level_of_place[p] for p in support), default=0)
        return _Transition(name, relation, enabled, overflow, changed, qvars, rename, top, support)

    def image(self, states: Bdd, t: _Transition) -> Bdd:
        if not t.changed:
            return states & t.relation
        return self.bdd.let(t.rename, cudd.and_exists(states, t.relation, t.qvars))

    def contains(self, states: Bdd, marking: list[int]) -> bool:
        return bool((states & self.marking_cube(marking, current=True)) != self.bdd.false)

    def overflowing(self, states: Bdd, t: _Transition) -> set[int]:
        """Places `t` would push past their counters from some marking of `states`."""
        false = self.bdd.false
        return {p for p, cond in t.overflow.items() if cond != false and (states & cond) != false}


def _fixpoint(sym: SymbolicNet, limits: _Deadline) -> tuple[Bdd, int, int, str | None]:
    """The reachable markings by the strategy `limits` names; returns (reached,
    iterations, peak nodes, reason it stopped early). Raises `_Overflow` after a
    fixpoint in which some counter would have outgrown its bits."""
    if limits.limits.strategy == "chaining":
        return _chained(sym, limits)
    overflow: set[int] = set()
    peak = len(sym.bdd)

    def step(t: _Transition, frontier: Bdd) -> str | None:
        nonlocal peak
        overflow.update(sym.overflowing(frontier, t))
        nodes = limits.nodes(sym.bdd)
        peak = max(peak, nodes)
        return limits.reason(nodes)

    run = Saturation(sym, step)
    reached, reason = run.run(sym.initial)
    if reason is None and overflow:
        raise _Overflow(overflow)
    return reached, run.rounds, peak, reason


def _chained(sym: SymbolicNet, limits: _Deadline) -> tuple[Bdd, int, int, str | None]:
    """Chained fixpoint over frontiers (`strategy="chaining"`, kept for comparison).

    Each transition's image is taken of the frontier only (the markings it has not yet
    been applied to), and what it adds joins the frontier at once, so the transitions
    after it in the chain see it in the same sweep. A marking added by a transition
    has met only the transitions after it: the next sweep's frontier is everything the
    sweep added. The fixpoint is reached when a sweep adds nothing."""
    reached = sym.initial
    frontier = sym.initial
    sweeps = 0
    peak = len(sym.bdd)
    overflow: set[int] = set()
    false = sym.bdd.false
    while frontier != false:
        sweeps += 1
        added = false
        for t in sym.transitions:
            overflow |= sym.overflowing(frontier, t)
            new = sym.image(frontier, t) & ~reached
            if new != false:
                reached |= new
                frontier |= new
                added |= new
            nodes = limits.nodes(sym.bdd)
            peak = max(peak, nodes)
            reason = limits.reason(nodes)
            if reason is not None:
                return reached, sweeps, peak, reason
        frontier = added
    if overflow:
        # every counter that overflows within the markings its bits can hold, found in
        # one fixpoint: widen them all at once, then start again
        raise _Overflow(overflow)
    return reached, sweeps, peak, None


def _max_value(sym: SymbolicNet, states: Bdd, place: int, limits: _Deadline) -> int:
    """Largest value of `place` in `states`, MSB first: keep a bit set when some
    marking allows it."""
    value = 0
    names = sym.enc.xs(place)
    for i, name in enumerate(names):
        limits.check()
        var = sym.bdd.var(name)
        if (states & var) != sym.bdd.false:
            states &= var
            value |= 1 << (len(names) - 1 - i)
        else:
            states &= ~var
    return value


def decode(sym: SymbolicNet, assignment: dict[str, bool]) -> list[int]:
    """A marking from a satisfying assignment of the x bits (absent bits are 0)."""
    marking = []
    for p in range(len(sym.net.places)):
        names = sym.enc.xs(p)
        v = 0
        for name in names:
            v = (v << 1) | int(bool(assignment.get(name, False)))
        marking.append(v)
    return marking


def explore_symbolic(net: Net, limits: SymbolicLimits | None = None) -> SymbolicResult:
    """Reachable markings of `net` as a BDD, then the StateSpace answers from it.

    Widening on overflow restarts the fixpoint with the overflowing counters one bit
    wider; past `limits.max_bits` the run ends inconclusive ("may be unbounded"). Every
    limit (time, the command's budget, nodes, memory) ends the run with `complete`
    False and the reason, never an exception; the passes after a stopped fixpoint get a
    short grace (`GRACE_SECONDS`) to count what was found, else report 0 states.
    """
    limits = limits or SymbolicLimits()
    start = time.monotonic()
    seconds = [INVARIANT_SECONDS]
    if limits.time_limit is not None:
        seconds.append(limits.time_limit)
    deadline = _Deadline(limits, start)
    # The set-up (invariants, the order of places, the levels, the transitions'
    # steps, the variables) reads the budget between its stages: on rings(2000, 10)
    # they took 0.1-1 s each, 1.3-2.2 s in all before the first reading.
    bounds, units = invariant_facts(net, min(seconds), limits.budget)
    bits = initial_bits(net, bounds=bounds)
    try:
        deadline.check()
        order = place_order(net)  # (once: the diagrams of both schedules use it)
    except _Budget as exc:
        return _stopped(net, bits, start, f"{exc} (setting up: ordering the places)")
    proven = frozenset(p for p, b in enumerate(bounds) if b is not None)
    conserved_bits = _conserved_bits(net)
    if limits.strategy == "saturation":
        result = _by_nodes(net, bounds, units, order, limits, deadline, start)
        if result is not None:
            return result
    while True:
        try:
            sym = SymbolicNet(net, bits, limits, deadline, proven, order)
            reached, sweeps, peak, reason = _fixpoint(sym, deadline)
            break
        except _Budget as exc:
            return _stopped(net, bits, start, f"{exc} (building the transition relations)")
        except _Overflow as over:
            wide = [p for p in over.places if bits[p] + 1 > limits.max_bits]
            if wide:
                names = ", ".join(net.places[p].name for p in sorted(wide)[:5])
                return _stopped(
                    net,
                    bits,
                    start,
                    f"place(s) {names} exceed {(1 << limits.max_bits) - 1} tokens: "
                    "the net may be unbounded",
                )
            # doubled, and with it every place no invariant bounds: tokens that pile up
            # in one place usually flow on into the next (DoubleExponent-PT-002 found its
            # 9 unbounded places one restart at a time, 29 restarts)
            unproven = [p for p, b in enumerate(bounds) if b is None and bits[p] < limits.max_bits]
            for p in {*over.places, *unproven}:
                bits[p] = min(limits.max_bits, max(2 * bits[p], conserved_bits))
        except _OUT_OF_MEMORY as exc:
            return _stopped(net, bits, start, _memory_reason(limits, exc))
    after = deadline
    if reason is not None:
        # counting what was found is worth a little more time, never much
        grace = replace(limits, time_limit=time.monotonic() - start + GRACE_SECONDS, budget=None)
        after = _Deadline(grace, start)
    try:
        return _answers(sym, reached, after, reason, start, sweeps, peak)
    except _Budget as exc:
        result = _stopped(net, list(sym.enc.bits), start, reason or str(exc))
        result.peak_nodes, result.iterations = peak, sweeps
        return result
    except _OUT_OF_MEMORY as exc:
        return _stopped(net, list(sym.enc.bits), start, _memory_reason(limits, exc))


GRACE_SECONDS = 1.0

INVARIANT_SECONDS = 1.0
"""At most this long for the P-invariants whose bounds size the counters."""


_OUT_OF_MEMORY = (MemoryError, RuntimeError, ValueError)
"""What dd.cudd raises when CUDD returns no node (its `max_memory` reached): a
RuntimeError naming memory from most operators, a ValueError about a NULL node from
`and_exists`. `_memory_reason` re-raises the ones that are not about memory."""


MDD_NODE_WEIGHT = 40
"""BDD nodes' worth of memory per MDD node: its dictionary of children, its key in the
unique table and its share of the union, image and saturation caches, 2.25 KB a node
measured on Peterson-PT-3 (resident growth over the fixpoint, 56,774 nodes), against
CUDD's 48 bytes. The node budget counts an MDD node this many times."""


MDD_MAX_CALLS = 600_000
"""Node images (cache misses of the recursive fire) after which node-level saturation
gives up for the set-level schedule: the conformance models that finish need at most
299,000 (DoubleExponent-PT-003; Peterson-PT-3 234,000, Dekker-PT-015 215,000);
Dekker-PT-020, where every process reads every other's flag, needs 3.8M (about 15 s)
where the set-level schedule takes 2-5 s."""

MDD_SHARE = 0.4
"""The share of the time left that node-level saturation may use before giving up."""


WIDE_TESTS = 8
"""A transition testing this many levels without changing them sends the net to the
set-level schedule at once. Node saturation rebuilds every level such a transition
tests, at every image, where a BDD relational product takes the guard as one cube:
Dekker-PT-015/020 (14 and 19 tested levels) take 0.3 and 1.7-3 s by sets against 0.5
and about 15 s by nodes. Every other conformance model tests at most 3 levels in one
transition. A rule from one family, so a cautious threshold; Dekker-PT-010 (9) is
equally fast either way."""


class _GiveUp(Exception):
    """Node-level saturation used its share; the set-level schedule takes over."""


def _by_nodes(
    net: Net,
    bounds: list[int | None],
    units: list[list[int]],
    order: list[int],
    limits: SymbolicLimits,
    deadline: _Deadline,
    start: float,
) -> SymbolicResult | None:
    """The reachable markings by saturation on MDD nodes (`analysis.symbolic.mdd`),
    then as a BDD whose counters have exactly the bits of the largest value each place
    took (so no counter can overflow: every place is `proven`), for the answers.

    None when the node-level run gives up (`MDD_MAX_CALLS` images, or `MDD_SHARE` of
    the time left): the caller then runs the set-level schedule, which wins where every
    transition reads the whole net (Dekker-PT-020: 3.8M node images, about 15 s, here;
    2-5 s by sets). A stopped fixpoint has no consistent partial set to
    count: it reports 0 states. ``order``: the places' static order (`place_order`)."""
    bits = initial_bits(net, bounds=bounds)
    try:
        deadline.check()
        levels = level_order(net, units, order)
    except _Budget as exc:
        return _stopped(net, bits, start, f"{exc} (setting up: ordering the levels)")
    order = [p for places in levels for p in places]
    top = (1 << limits.max_bits) - 1
    caps = [top if b is None else b for b in bounds]
    left = [limits.time_limit - (time.monotonic() - start)] if limits.time_limit else []
    remaining = limits.budget.remaining() if limits.budget is not None else None
    if remaining is not None:
        left.append(remaining)
    give_up = time.monotonic() + MDD_SHARE * min(left) if left else None

    def check(nodes: int) -> str | None:
        if run.calls > MDD_MAX_CALLS or (give_up is not None and time.monotonic() > give_up):
            raise _GiveUp
        return deadline.reason(nodes * MDD_NODE_WEIGHT)

    try:
        deadline.check()
        run = MddSaturation(net, levels, caps, check)
        deadline.check()
    except ValueError:  # a unit whose invariant the arcs break: never expected
        return None
    except _Budget as exc:
        return _stopped(net, bits, start, f"{exc} (setting up: the transitions' steps)")
    if run.widest_test() >= WIDE_TESTS:
        return None
    try:
        root = run.run([p.initial for p in net.places])
    except (_GiveUp, RecursionError):
        return None
    except Stopped as exc:
        return _stopped(net, bits, start, str(exc))
    except Unbounded as over:
        name = net.places[over.place].name
        return _stopped(
            net, bits, start, f"place(s) {name} exceed {top} tokens: the net may be unbounded"
        )
    largest = run.largest(root)
    bits = [max(1, v.bit_length()) for v in largest]
    try:
        return _node_answers(net, run, root, largest, order, limits, deadline, start)
    except _Budget as exc:
        return _stopped(net, bits, start, f"{exc} (after the fixpoint)")
    except _OUT_OF_MEMORY as exc:
        return _stopped(net, bits, start, _memory_reason(limits, exc))


def _node_answers(
    net: Net,
    run: MddSaturation,
    root: int,
    largest: list[int],
    order: list[int],
    limits: SymbolicLimits,
    deadline: _Deadline,
    start: float,
) -> SymbolicResult:
    """Count, bounds and dead markings on the MDD itself (tens of thousands of nodes
    where the BDD of the same set, with binary counters, has ten times more: the BDD
    passes took 10 of DoubleExponent-PT-003's 12 s). A BDD is built only for the
    shortest trace to a dead marking (`analysis.symbolic.trace`), over the dead
    markings alone. Raises `_Budget` on a limit."""
    bits = [max(1, v.bit_length()) for v in largest]
    states = run.count(root)
    heaviest = run.heaviest(root)
    dead = run.dead(root, deadline.check)
    witness: dict[str, int] | None = None
    trace = None
    peak = len(run.children)
    if dead != 0:
        marking = run.pick(dead)
        if limits.trace:
            sym = SymbolicNet(net, bits, limits, deadline, frozenset(range(len(bits))), order)
            try:
                marking, trace = shortest_to_dead(
                    sym, run.to_bdd(dead, sym.value, sym.bdd), deadline.check
                )
            except (_Budget, TraceError):
                trace = None  # the witness marking stands without its trace
            peak = max(peak, len(sym.bdd))
        witness = {net.places[p].name: v for p, v in enumerate(marking) if v}
    return SymbolicResult(
        complete=True,
        reason=None,
        states=states,
        max_tokens_place=max(largest, default=0),
        max_tokens_marking=heaviest,
        place_bounds={p.name: largest[i] for i, p in enumerate(net.places)},
        deadlock=dead != 0,
        deadlock_marking=witness,
        deadlock_trace=trace,
        seconds=time.monotonic() - start,
        peak_nodes=peak,
        iterations=run.calls,
        bits=bits,
    )


def _memory_reason(limits: SymbolicLimits, exc: BaseException) -> str:
    text = str(exc)
    if not isinstance(exc, MemoryError) and "memory" not in text and "NULL" not in text:
        raise exc
    budget = limits.budget
    if budget is not None and budget.memory is not None:
        return memory_limit_reason(budget.memory)
    first = text.splitlines()[0] if text else type(exc).__name__
    return f"memory: the decision diagram library could not allocate ({first})"


def _answers(
    sym: SymbolicNet,
    reached: Bdd,
    limits: _Deadline,
    reason: str | None,
    start: float,
    sweeps: int,
    peak: int,
) -> SymbolicResult:
    """Count, bounds and deadlock from the reached set; raises `_Budget` on a limit."""
    from analysis.symbolic import measures

    net = sym.net
    xvars = sym.xvars
    states = measures.count(reached, xvars, limits.check)
    weight = {}
    for p in range(len(net.places)):
        for i, name in enumerate(sym.enc.xs(p)):
            weight[name] = 1 << (sym.enc.bits[p] - 1 - i)
    bounds = {
        net.places[p].name: _max_value(sym, reached, p, limits) for p in range(len(net.places))
    }
    heaviest = max(0, measures.max_weight(reached, xvars, weight, limits.check))
    # the dead markings among the reached ones, narrowed one transition at a time: the
    # dead markings of the whole encoding space make a diagram far larger than the
    # reached set (17 s of Dekker-PT-010's 23 s)
    hit = reached
    for t in sym.transitions:
        limits.check()
        hit &= ~t.enabled
        if hit == sym.bdd.false:
            break
    deadlock: bool | None = hit != sym.bdd.false
    witness = None
    trace = None
    if deadlock:
        marking: list[int] | None = None
        if sym.limits.trace:
            try:
                marking, trace = shortest_to_dead(sym, hit, limits.check)
            except (_Budget, TraceError):
                marking, trace = None, None  # the witness marking stands without its trace
        if marking is None:
            pick = sym.bdd.pick(hit, care_vars=set(xvars))
            marking = decode(sym, pick or {})
        witness = {net.places[p].name: v for p, v in enumerate(marking) if v}
    elif reason is not None:
        deadlock = None  # none found among the markings reached so far
    return SymbolicResult(
        complete=reason is None,
        reason=reason,
        states=states,
        max_tokens_place=max(bounds.values(), default=0),
        max_tokens_marking=heaviest,
        place_bounds=bounds,
        deadlock=deadlock,
        deadlock_marking=witness,
        deadlock_trace=trace,
        seconds=time.monotonic() - start,
        peak_nodes=peak,
        iterations=sweeps,
        bits=list(sym.enc.bits),
    )


def _conserved_bits(net: Net) -> int:
    """Bits for the total of the initial tokens when no transition changes the token
    count (then no place can hold more); 0 when some transition does."""
    for tr in net.transitions:
        if sum(w for _, w in tr.inputs) != sum(w for _, w in tr.outputs):
            return 0
    return sum(p.initial for p in net.places).bit_length()


def _stopped(net: Net, bits: list[int], start: float, reason: str) -> SymbolicResult:
    return SymbolicResult(
        complete=False,
        reason=reason,
        states=0,
        max_tokens_place=0,
        max_tokens_marking=0,
        place_bounds={},
        deadlock=None,
        deadlock_marking=None,
        deadlock_trace=None,
        seconds=time.monotonic() - start,
        peak_nodes=0,
        iterations=0,
        bits=list(bits),
    )
