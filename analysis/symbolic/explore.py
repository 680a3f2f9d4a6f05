"""The reachable markings as a BDD, by chained fixpoints over per-transition relations.

Each transition gets its own relation over only the places it touches (a partitioned
relation): places it reads without changing are a guard on the current bits, places it
changes map current bits to next bits. Images are `and_exists` then a rename, and the
transitions are applied in a chain ordered by their lowest place in the variable order,
so one sweep carries tokens along a whole causal chain (Roig, Cortadella and Pastor,
"Verification of asynchronous circuits by BDD-based model checking of Petri nets",
1995: chaining). Counters that would outgrow their bits are detected before any image
is taken, the encoding widened and the fixpoint restarted: a value never wraps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import dd.cudd as cudd

from analysis.symbolic.encoding import Encoding, initial_bits, place_order
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


@dataclass
class SymbolicResult:
    """What the fixpoint learned. `complete` False means `reason` says which budget
    stopped it; the counts then describe the markings found so far (a lower bound)."""

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
    pass


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


class SymbolicNet:
    """A net's encoding in one BDD manager: the initial marking, transitions, helpers."""

    def __init__(self, net: Net, bits: list[int], limits: SymbolicLimits) -> None:
        self.net = net
        self.enc = Encoding(tuple(place_order(net)), tuple(bits))
        self.bdd = cudd.BDD()
        self.bdd.configure(reordering=False)
        if limits.max_memory is not None:
            self.bdd.configure(max_memory=limits.max_memory)
        self.bdd.declare(*self.enc.declaration())
        self.level_of_place = {p: i for i, p in enumerate(self.enc.order)}
        self.xvars = [v for p in self.enc.order for v in self.enc.xs(p)]
        index = {p.name: i for i, p in enumerate(net.places)}
        self.initial = self.marking_cube([p.initial for p in net.places], current=True)
        self.transitions: list[_Transition] = []
        for tr in net.transitions:
            pre: dict[int, int] = {}
            post: dict[int, int] = {}
            for name, w in tr.inputs:
                pre[index[name]] = pre.get(index[name], 0) + w
            for name, w in tr.outputs:
                post[index[name]] = post.get(index[name], 0) + w
            self.transitions.append(self._transition(tr.name, pre, post))
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

    def marking_cube(self, marking: list[int], *, current: bool) -> Bdd:
        cube = self.bdd.true
        for p, v in enumerate(marking):
            cube &= self.value(p, v, current=current)
        return cube

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
            update = bdd.false
            for v in range(w_in, cap + 1):
                if v + delta <= cap:
                    update |= self.value(p, v) & self.value(p, v + delta, current=False)
            relation &= update
            overflow[p] = bdd.false  # filled in below, once the guard is complete
            if delta > 0:
                overflow[p] = self.at_least(p, max(w_in, cap - delta + 1))
            qvars.update(self.enc.xs(p))
            rename.update(zip(self.enc.ys(p), self.enc.xs(p), strict=True))
        overflow = {p: enabled & cond for p, cond in overflow.items()}
        support = set(pre) | set(post)
        top = min((self.level_of_place[p] for p in support), default=0)
        return _Transition(name, relation, enabled, overflow, changed, qvars, rename, top)

    def image(self, states: Bdd, t: _Transition) -> Bdd:
        if not t.changed:
            return states & t.relation
        return self.bdd.let(t.rename, cudd.and_exists(states, t.relation, t.qvars))

    def overflowing(self, states: Bdd, t: _Transition) -> set[int]:
        """Places `t` would push past their counters from some marking of `states`."""
        false = self.bdd.false
        return {p for p, cond in t.overflow.items() if cond != false and (states & cond) != false}


def _fixpoint(
    sym: SymbolicNet, limits: SymbolicLimits, start: float
) -> tuple[Bdd, int, int, str | None]:
    """Chained fixpoint; returns (reached, sweeps, peak nodes, reason it stopped early)."""
    reached = sym.initial
    sweeps = 0
    peak = len(sym.bdd)
    overflow: set[int] = set()
    while True:
        sweeps += 1
        before = reached
        for t in sym.transitions:
            overflow |= sym.overflowing(reached, t)
            reached = reached | sym.image(reached, t)
            nodes = len(sym.bdd)
            peak = max(peak, nodes)
            if limits.time_limit is not None and time.monotonic() - start > limits.time_limit:
                return reached, sweeps, peak, f"time limit of {limits.time_limit:g} s"
            if limits.max_nodes is not None and nodes > limits.max_nodes:
                return reached, sweeps, peak, f"node budget of {limits.max_nodes} BDD nodes"
        if reached == before:
            if overflow:
                # every counter that overflows within the markings its bits can hold,
                # found in one fixpoint: widen them all at once, then start again
                raise _Overflow(overflow)
            return reached, sweeps, peak, None


def _max_value(sym: SymbolicNet, states: Bdd, place: int) -> int:
    """Largest value of `place` in `states`, MSB first: keep a bit set when some
    marking allows it."""
    value = 0
    names = sym.enc.xs(place)
    for i, name in enumerate(names):
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
    wider; past `limits.max_bits` the run ends inconclusive ("may be unbounded").
    """
    from analysis.symbolic import measures

    limits = limits or SymbolicLimits()
    start = time.monotonic()
    bits = initial_bits(net)
    conserved_bits = _conserved_bits(net)
    while True:
        sym = SymbolicNet(net, bits, limits)
        try:
            reached, sweeps, peak, reason = _fixpoint(sym, limits, start)
            break
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
            for p in over.places:
                bits[p] = min(limits.max_bits, max(bits[p] + 1, conserved_bits))
    xvars = sym.xvars
    states = measures.count(reached, xvars)
    weight = {}
    for p in range(len(net.places)):
        for i, name in enumerate(sym.enc.xs(p)):
            weight[name] = 1 << (sym.enc.bits[p] - 1 - i)
    bounds = {net.places[p].name: _max_value(sym, reached, p) for p in range(len(net.places))}
    dead = sym.bdd.true
    for t in sym.transitions:
        dead &= ~t.enabled
    hit = reached & dead
    deadlock: bool | None = hit != sym.bdd.false
    witness = None
    if deadlock:
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
        max_tokens_marking=max(0, measures.max_weight(reached, xvars, weight)),
        place_bounds=bounds,
        deadlock=deadlock,
        deadlock_marking=witness,
        deadlock_trace=None,
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
