"""Binary encoding of markings: each place a little-endian-free counter of a few BDD
variables, current (``x``) and next (``y``) copies interleaved bit by bit so that a
transition's relation stays a narrow band of the order (Burch et al. 1991; interleaving
is the classic static order for partitioned relations)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.lastnet import last_net
from coral_lang.net import Net, Transition

FORCE_WORK = 400_000
"""Most hyperedge entries `force` visits over all its rounds (every conformance net
keeps its 40 rounds)."""


def arc_weights(net: Net, tr: Transition) -> tuple[dict[int, int], dict[int, int]]:
    """A transition's input and output weights by place number (parallel arcs add up)."""
    pre: dict[int, int] = {}
    post: dict[int, int] = {}
    for name, w in tr.inputs:
        p = net.place_index(name)
        pre[p] = pre.get(p, 0) + w
    for name, w in tr.outputs:
        p = net.place_index(name)
        post[p] = post.get(p, 0) + w
    return pre, post


@last_net
def _supports(net: Net) -> list[list[int]]:
    """Each transition's places (inputs and outputs), sorted, by place number; the
    last net's are kept (`place_order` reads them three times, and on a net of 40,000
    arcs building them is a tenth of a second)."""
    index = {p.name: i for i, p in enumerate(net.places)}
    return [
        sorted({index[name] for name, _ in (*tr.inputs, *tr.outputs)}) for tr in net.transitions
    ]


def span_sum(net: Net, order: Sequence[int]) -> int:
    """The sum over transitions of the distance between their first and last place in
    `order`: the classic cost a static order minimises (each transition's relation and
    image work spread over that band of levels)."""
    supports = [s for s in _supports(net) if s]
    if not supports:
        return 0
    position = np.empty(len(net.places), dtype=np.int64)
    position[np.asarray(order, dtype=np.int64)] = np.arange(len(order), dtype=np.int64)
    lengths = np.fromiter((len(s) for s in supports), dtype=np.int64, count=len(supports))
    flat = np.fromiter(
        itertools.chain.from_iterable(supports), dtype=np.int64, count=int(lengths.sum())
    )
    starts = np.zeros(len(supports), dtype=np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    at = position[flat]
    return int((np.maximum.reduceat(at, starts) - np.minimum.reduceat(at, starts)).sum())


def place_order(net: Net) -> list[int]:
    """The static order of places with the smaller `span_sum`: the greedy locality
    order (`locality_order`) or the PNML order (MCC nets list places by NUPN units,
    often already the better one)."""
    pnml = list(range(len(net.places)))
    candidates = [locality_order(net), pnml, force_order(net, pnml)]
    return min(candidates, key=lambda order: span_sum(net, order))


def force_order(net: Net, start: Sequence[int], rounds: int = 40) -> list[int]:
    """FORCE (Aloul, Markov and Sakallah, "FORCE: a fast and easy-to-implement
    variable-ordering heuristic", GLSVLSI 2003) over the places, each transition a
    hyperedge (`force`)."""
    supports = _supports(net)
    return force(len(net.places), [s for s in supports if s], list(start), rounds)


def locality_order(net: Net) -> list[int]:
    """A static order of places that keeps each transition's places close together.

    Greedy by arc locality: start with the first place of the PNML order (MCC nets list
    places by their NUPN units, which is already local), then repeatedly take the
    unplaced place that shares the most transitions with the most recently placed
    ones. Close places mean short bands per transition, hence small relations and
    images (Siminiceanu and Ciardo's observation behind variable-order heuristics).
    """
    n = len(net.places)
    neighbours: list[set[int]] = [set() for _ in range(n)]
    for support in _supports(net):
        if len(support) > 64:  # a hub transition says nothing about locality
            continue
        for a in support:
            neighbours[a].update(support)
    placed: list[int] = []
    seen = [False] * n
    score = [0] * n
    for start in range(n):
        if seen[start]:
            continue
        frontier = {start}
        while frontier:
            best = max(frontier, key=lambda i: (score[i], -i))
            frontier.discard(best)
            seen[best] = True
            placed.append(best)
            for other in neighbours[best]:
                if not seen[other]:
                    score[other] += 1 + len(placed)
                    frontier.add(other)
    return placed


@dataclass(frozen=True)
class Encoding:
    """Where each place's bits live: ``bits[p]`` variables, most significant first,
    named ``x{p}_{b}`` (current) and ``y{p}_{b}`` (next)."""

    order: tuple[int, ...]
    bits: tuple[int, ...]

    def xs(self, place: int) -> list[str]:
        return [f"x{place}_{b}" for b in reversed(range(self.bits[place]))]

    def ys(self, place: int) -> list[str]:
        return [f"y{place}_{b}" for b in reversed(range(self.bits[place]))]

    def declaration(self) -> list[str]:
        """All variables in level order: places by `order`, bits MSB first, x then y."""
        names: list[str] = []
        for place in self.order:
            for x, y in zip(self.xs(place), self.ys(place), strict=True):
                names += [x, y]
        return names

    def capacity(self, place: int) -> int:
        return (1 << self.bits[place]) - 1


def initial_bits(
    net: Net, grown: Sequence[int] | None = None, bounds: Sequence[int | None] | None = None
) -> list[int]:
    """At least enough bits for the initial marking and the largest arc into each
    place; `grown` (from an earlier overflow) wins where larger. A place with a proven
    bound (`bounds`, from P-invariants) gets exactly the bits of its bound: never
    widened, and one bit for a safe place."""
    need = [max(1, p.initial) for p in net.places]
    index = {p.name: i for i, p in enumerate(net.places)}
    for tr in net.transitions:
        for name, weight in (*tr.inputs, *tr.outputs):
            need[index[name]] = max(need[index[name]], weight)
    if bounds is not None:
        # an arc heavier than the bound never fires; the bound is what the place holds
        need = [n if b is None else max(1, b) for n, b in zip(need, bounds, strict=True)]
    bits = [v.bit_length() for v in need]
    if grown is not None:
        bits = [max(a, b) for a, b in zip(bits, grown, strict=True)]
    return bits


def invariant_bounds(net: Net, seconds: float) -> list[int | None]:
    """Per place, the bound its P-invariants prove (``y·M0 // y(p)``, Martinez-Silva
    semiflows from `analysis.invariants`), None where no invariant covers it or the
    search ran out of `seconds` first (each invariant found is genuine, so a partial
    basis still gives sound bounds). Tens of milliseconds on the conformance nets."""
    return invariant_facts(net, seconds)[0]


def invariant_facts(
    net: Net, seconds: float, budget: Budget | None = None
) -> tuple[list[int | None], list[list[int]]]:
    """The bounds of `invariant_bounds` and the *units*: disjoint sets of at least two
    places that always hold exactly one token together (a P-invariant of weights 1
    whose initial value is 1), the largest first. A unit is one multi-valued level of
    `analysis.symbolic.mdd` (the place that holds the token), the NUPN units of MCC
    nets recovered from the net itself. The search takes `seconds` of ``budget`` (the
    caller's, so its clock and deadline; None: a fresh one on the real clock)."""
    from analysis.invariants import invariant_bounds as bounds_of
    from analysis.invariants import p_invariants

    seconds = max(0.0, seconds)
    search = Budget(seconds) if budget is None else budget.child(seconds=seconds)
    basis = p_invariants(net, budget=search)
    found = bounds_of(net, basis)
    initial = [p.initial for p in net.places]
    candidates = [
        sorted(inv.support)
        for inv in basis.invariants
        if len(inv.support) > 1
        and all(w in (0, 1) for w in inv.weights)
        and inv.value(initial) == 1
    ]
    candidates.sort(key=lambda support: (-len(support), support))
    units: list[list[int]] = []
    taken: set[int] = set()
    for support in candidates:
        if taken.isdisjoint(support):
            units.append(support)
            taken.update(support)
    return [found.get(p.name) for p in net.places], units


def level_order(net: Net, units: Sequence[Sequence[int]], order: Sequence[int]) -> list[list[int]]:
    """The levels of a multi-valued diagram: every unit one level, every other place
    its own, each unit's places in `order`; the levels sorted by the mean position of
    their places in `order`, then moved by FORCE over levels (each transition pulls
    the levels it touches together) when that shortens the total span."""
    position = {p: i for i, p in enumerate(order)}
    in_unit = {p for unit in units for p in unit}
    levels = [sorted(unit, key=position.__getitem__) for unit in units]
    levels += [[p] for p in order if p not in in_unit]
    levels.sort(key=lambda places: sum(position[p] for p in places) / len(places))
    level_of = {p: k for k, places in enumerate(levels) for p in places}
    index = {p.name: i for i, p in enumerate(net.places)}
    supports = [
        sorted({level_of[index[name]] for name, _ in (*tr.inputs, *tr.outputs)})
        for tr in net.transitions
    ]
    start = force(len(levels), [s for s in supports if len(s) > 1], list(range(len(levels))))
    return [levels[k] for k in start]


def force(
    size: int, supports: Sequence[Sequence[int]], start: list[int], rounds: int = 40
) -> list[int]:
    """FORCE (Aloul, Markov and Sakallah 2003) on items 0..size-1 with hyperedges
    `supports`: each hyperedge pulls its items towards their centre of gravity; every
    round moves each item to the mean centre of the hyperedges touching it and sorts.
    The order of least total span seen wins, `start` (a permutation of the items)
    included. At most `FORCE_WORK` hyperedge entries are visited in all (fewer rounds
    on wide nets).

    Each round is a handful of numpy passes over the entries (a round over the 40,000
    arcs of 2,000 rings took 0.1 s as Python loops, and a wide net's order was seconds
    past any time limit). The sums run in the order the Python loops summed, so the
    order found is the same to the last tie."""
    supports = [s for s in supports if len(s)]
    entries = sum(len(s) for s in supports)
    rounds = min(rounds, max(1, FORCE_WORK // max(1, entries)))
    if not supports:
        return list(start)
    lengths = np.fromiter((len(s) for s in supports), dtype=np.int64, count=len(supports))
    flat = np.fromiter(itertools.chain.from_iterable(supports), dtype=np.int64, count=entries)
    edge = np.repeat(np.arange(len(supports), dtype=np.int64), lengths)
    starts = np.zeros(len(supports), dtype=np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    degree = np.bincount(flat, minlength=size)
    touched = degree > 0
    items = np.arange(size, dtype=np.int64)

    def positions(order: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        position = np.empty(size, dtype=np.int64)
        position[order] = items
        return position

    def span(position: npt.NDArray[np.int64]) -> int:
        at = position[flat]
        return int((np.maximum.reduceat(at, starts) - np.minimum.reduceat(at, starts)).sum())

    order = np.asarray(start, dtype=np.int64)
    best, best_cost = order, span(positions(order))
    for _ in range(rounds):
        position = positions(order)
        # a hyperedge's centre: the exact sum of its positions over its size
        centre = np.add.reduceat(position[flat], starts) / lengths
        # an item's pull: its hyperedges' centres summed in hyperedge order (bincount
        # adds in array order, as the Python sum did), over their number
        pull = np.bincount(flat, weights=centre[edge], minlength=size)
        target = position.astype(np.float64)
        target[touched] = pull[touched] / degree[touched]
        order = np.lexsort((position, target))
        cost = span(positions(order))
        if cost < best_cost:
            best, best_cost = order, cost
    return [int(p) for p in best]
