"""One-hot components: sets of places proven on the arcs never to hold more than one
token between them, stored as one field of "which place is marked".

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.encoding.compact import CompactNet, IntArray, row_entries
from analysis.encoding.keystore import word_multipliers

# -- one-hot components ------------------------------------------------------------------

DENSE_SEARCH_CELLS = 400_000
"""Largest places x transitions for the elimination search of one-hot components;
larger nets only get the components their one-in-one-out transitions reveal."""

SEARCH_SECONDS = 0.5
"""Time budget of the elimination search; what it has proven by then is used."""

SEARCH_ROWS = 20_000
"""Most candidate rows the elimination keeps."""

SEARCH_PLACES = 2_000
"""Most places for the elimination search (its rows are dense place vectors)."""

GROW_CLASSES = 1_000
"""Most classes of `_components_by_unit_moves` grown into candidate flows."""


def _flow_kinds(cn: CompactNet, candidates: list[IntArray]) -> list[str | None]:
    """How many tokens each candidate set of places can hold between them, proven on
    the arcs (integer sums, exact): ``"exact"`` when they hold one initially and every
    transition puts back as many as it takes (a P-invariant: always exactly one),
    ``"at most"`` when none puts back more than it takes (``y.M`` never grows: at most
    one, in every part of the set too), else ``None``. All sets at once: one pass over
    the arcs for every set, not one per set (2,000 rings: 4,000 passes over 40,000
    arcs took 0.4 s)."""
    owner, place = _memberships(candidates)
    n = len(candidates)
    tokens = np.bincount(owner, weights=cn.initial[place], minlength=n)
    keys, took, put = _flows_through(cn, owner, place)
    by = keys // max(1, cn.n_transitions)
    grows = np.bincount(by[put > took], minlength=n) > 0
    uneven = np.bincount(by[put != took], minlength=n) > 0
    kinds: list[str | None] = []
    for k in range(n):
        if tokens[k] != 1 or grows[k]:
            kinds.append(None)
        else:
            kinds.append("at most" if uneven[k] else "exact")
    return kinds


def _memberships(candidates: list[IntArray]) -> tuple[IntArray, IntArray]:
    """``(owner, place)``: one pair per member of each candidate set."""
    sizes = np.fromiter((c.size for c in candidates), dtype=np.int64, count=len(candidates))
    owner = np.repeat(np.arange(len(candidates), dtype=np.int64), sizes)
    place = np.concatenate(candidates) if candidates else np.zeros(0, dtype=np.int64)
    return owner, place.astype(np.int64, copy=False)


def _flows_through(
    cn: CompactNet, owner: IntArray, place: IntArray
) -> tuple[IntArray, npt.NDArray[Any], npt.NDArray[Any]]:
    """For the place sets given as ``(owner, place)`` pairs: per (set, transition) pair
    that moves tokens in or out of the set, its key ``owner * transitions +
    transition`` (ascending, unique) and the tokens the transition takes from and puts
    into the set's places."""
    n_t = max(1, cn.n_transitions)
    order = np.argsort(place, kind="stable")
    member_of = owner[order]
    indptr = np.zeros(cn.n_places + 1, dtype=np.int64)
    np.cumsum(np.bincount(place, minlength=cn.n_places), out=indptr[1:])
    counts = np.diff(indptr)
    sides = []
    for arcs in (cn.inputs, cn.outputs):
        arc, member = row_entries(indptr, counts, arcs.places)
        sides.append((member_of[member] * n_t + arcs.rows[arc], arcs.values[arc]))
    (k_in, w_in), (k_out, w_out) = sides
    keys, inverse = np.unique(np.concatenate([k_in, k_out]), return_inverse=True)
    took = np.bincount(inverse[: k_in.size], weights=w_in, minlength=keys.size)
    put = np.bincount(inverse[k_in.size :], weights=w_out, minlength=keys.size)
    return keys, took, put


def _components_by_unit_moves(cn: CompactNet) -> list[IntArray]:
    """Candidate flows from transitions that move one token from one place to another
    (missions are mostly made of them): the classes of "a token can move between these
    places", once over all such moves and once without the places several moves lead
    into (a shared ``abort`` would join every branch of a mission into one class),
    each grown (`_grow_flow`) by the places of the transitions that put tokens into it
    (a fork's input place, say). Verified by the caller."""
    i, o = cn.inputs.indptr[:-1], cn.outputs.indptr[:-1]
    unit = (cn.inputs.counts == 1) & (cn.outputs.counts == 1)
    moves = np.flatnonzero(unit)
    moves = moves[(cn.inputs.values[i[moves]] == 1) & (cn.outputs.values[o[moves]] == 1)]
    src, dst = cn.inputs.places[i[moves]], cn.outputs.places[o[moves]]
    keep = src != dst
    src, dst = src[keep], dst[keep]
    feeds = np.bincount(dst, minlength=cn.n_places)
    candidates: list[IntArray] = []
    for single in (False, True):
        chosen = feeds[dst] == 1 if single else np.ones(dst.size, dtype=bool)
        classes = _classes(cn.n_places, src[chosen], dst[chosen])
        candidates += _grow_flows(cn, classes[:GROW_CLASSES])
    return candidates


def _classes(n: int, a: IntArray, b: IntArray) -> list[IntArray]:
    """Connected classes (of two or more) of the graph with edges ``a[k] - b[k]`` on
    ``n`` nodes, largest first."""
    parent = np.arange(n)

    def root(p: int) -> int:
        while parent[p] != p:
            parent[p] = parent[parent[p]]
            p = int(parent[p])
        return p

    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        rx, ry = root(x), root(y)
        if rx != ry:
            parent[rx] = ry
    roots = np.array([root(p) for p in range(n)], dtype=np.int64)
    order = np.argsort(roots, kind="stable")
    bounds = np.flatnonzero(np.diff(roots[order])) + 1
    return sorted((c for c in np.split(order, bounds) if c.size > 1), key=len, reverse=True)


def _grow_flows(cn: CompactNet, classes: list[IntArray]) -> list[IntArray]:
    """Each class plus, a few times over, the input places of the transitions that put
    more tokens into the set than they take: what a flow containing the class needs
    (taking more than putting back is fine for an "at most one" flow). All classes at
    once (see `_flow_kinds`)."""
    if not classes:
        return []
    n_t = max(1, cn.n_transitions)
    owner, place = _memberships(classes)
    active = np.ones(len(classes), dtype=bool)
    for _ in range(3):
        keys, took, put = _flows_through(cn, owner, place)
        growing = keys[(put > took) & active[keys // n_t]]
        if not growing.size:
            break
        active[:] = False
        active[growing // n_t] = True
        grower, entry = cn.inputs.expand(growing % n_t)
        pairs = np.concatenate(
            [
                owner * cn.n_places + place,
                (growing // n_t)[grower] * cn.n_places + cn.inputs.places[entry],
            ]
        )
        pairs = np.unique(pairs)
        owner, place = pairs // cn.n_places, pairs % cn.n_places
    bounds = np.searchsorted(owner, np.arange(1, len(classes)))
    return np.split(place, bounds)


def _components_by_elimination(cn: CompactNet, budget: Budget) -> list[IntArray]:
    """Place sets with unit weights that form a P-invariant holding one token:
        Fourier-Motzkin elimination (as for P-semiflows) restricted to 0/1 rows with at
        most one initial token, which keeps the rows few. Verified by the caller. What is
    proven when ``budget`` runs out is kept."""
    incidence = cn.delta.T.astype(np.int32)  # (P, T)
    keep = cn.initial <= 1
    rows = np.eye(cn.n_places, dtype=bool)[keep]
    # Only the columns some row touches; an eliminated column is zero in every row
    # left (a row is kept where it is zero, or paired to cancel it), so it never
    # counts again: no list of pending columns to copy out each round.
    residual = incidence[keep]
    residual = np.ascontiguousarray(residual[:, (residual != 0).any(axis=0)])
    tokens = cn.initial[keep]
    while residual.shape[1] and rows.shape[0]:
        if budget.expired():
            break
        pos = np.count_nonzero(residual > 0, axis=0)
        neg = np.count_nonzero(residual < 0, axis=0)
        touched = pos + neg
        if not touched.any():
            break
        if 2 * np.count_nonzero(touched) < touched.size:  # most columns done: drop them
            live = touched > 0
            residual = np.ascontiguousarray(residual[:, live])
            pos, neg, touched = pos[live], neg[live], touched[live]
        # the cheapest column to eliminate (fewest new rows), the first on ties
        cost = np.where(touched > 0, pos * neg - touched, np.iinfo(np.int64).max)
        t = int(np.argmin(cost))
        column = residual[:, t]
        pos, neg = np.flatnonzero(column > 0), np.flatnonzero(column < 0)
        zero = column == 0
        i, j = np.repeat(pos, neg.size), np.tile(neg, pos.size)
        ok = (column[i] == -column[j]) & (tokens[i] + tokens[j] <= 1)
        ok &= ~(rows[i] & rows[j]).any(axis=1)
        i, j = i[ok], j[ok]
        rows = np.concatenate([rows[zero], rows[i] | rows[j]])
        residual = np.concatenate([residual[zero], residual[i] + residual[j]])
        tokens = np.concatenate([tokens[zero], tokens[i] + tokens[j]])
        if i.size:  # drop repeated rows (by a hash: merging two rows only loses one)
            packed = np.packbits(rows, axis=1).astype(np.uint64)
            with np.errstate(over="ignore"):
                digest = packed @ word_multipliers(packed.shape[1])
            _, unique = np.unique(digest, return_index=True)
            rows, residual, tokens = rows[unique], residual[unique], tokens[unique]
        if rows.shape[0] > SEARCH_ROWS:
            break
    done = ~(residual != 0).any(axis=1) & (tokens == 1)
    return [np.flatnonzero(r) for r in rows[done]]


@dataclass(frozen=True)
class Component:
    """Places that never hold more than one token between them, stored as one field.

    Attributes:
        places: the places, ascending.
        exact: whether they always hold exactly one (a whole flow that is a
            P-invariant); else the field also has a value for "no token here".
    """

    places: IntArray
    exact: bool

    @property
    def values(self) -> int:
        """How many field values the component needs."""
        return int(self.places.size) + (0 if self.exact else 1)


def one_hot_components(cn: CompactNet, budget: Budget | None = None) -> list[Component]:
    """Disjoint sets of places that never hold more than one token between them, each
    proven on the arcs by a *flow*: unit weights, one initial token, and no transition
    putting back more than it takes (see `_flow_kind`). When every transition puts
    back exactly what it takes, the flow always holds exactly one token. Flows are
    taken largest first; one overlapping chosen ones contributes what is left.

    Args:
        cn: the net.
        budget: the caller's budget; the elimination search (small nets only) takes a
            slice of at most `SEARCH_SECONDS` of it. None: a fresh one on the real clock.

    Returns:
        The components, each saving bits over one count field per place.
    """
    candidates = _components_by_unit_moves(cn)
    if cn.n_places * cn.n_transitions <= DENSE_SEARCH_CELLS and cn.n_places <= SEARCH_PLACES:
        search = (budget or Budget()).child(seconds=SEARCH_SECONDS)
        candidates += _components_by_elimination(cn, search)
    kinds = _flow_kinds(cn, candidates)
    flows = [(c, kind) for c, kind in zip(candidates, kinds, strict=True) if kind is not None]
    flows.sort(key=lambda f: f[0].size, reverse=True)
    used = np.zeros(cn.n_places, dtype=bool)
    chosen: list[Component] = []
    for flow, kind in flows:
        free = flow[~used[flow]]
        part = Component(free, exact=kind == "exact" and free.size == flow.size)
        if (part.exact and free.size) or free.size > 2:  # fewer bits than count fields
            used[free] = True
            chosen.append(part)
    return chosen
