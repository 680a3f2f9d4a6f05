"""One-hot components: sets of places proven on the arcs never to hold more than one
token between them, stored as one field of "which place is marked".

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.encoding.compact import BoolArray, CompactNet, IntArray
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


def _flow_kind(cn: CompactNet, members: IntArray) -> str | None:
    """How many tokens the places ``members`` can hold between them, proven on the
    arcs (integer sums, exact): ``"exact"`` when they hold one initially and every
    transition puts back as many as it takes (a P-invariant: always exactly one),
    ``"at most"`` when none puts back more than it takes (``y.M`` never grows: at most
    one, in every part of the set too), else ``None``."""
    if int(cn.initial[members].sum()) != 1:
        return None
    inside = np.zeros(cn.n_places, dtype=bool)
    inside[members] = True
    took, put = _flow_through(cn, inside)
    if (put > took).any():
        return None
    return "exact" if np.array_equal(put, took) else "at most"


def _flow_through(cn: CompactNet, inside: BoolArray) -> tuple[npt.NDArray[Any], ...]:
    """Per transition, the tokens it takes from and puts into the places ``inside``."""
    n_t = cn.n_transitions
    took = np.bincount(
        cn.inputs.rows, weights=cn.inputs.values * inside[cn.inputs.places], minlength=n_t
    )
    put = np.bincount(
        cn.outputs.rows, weights=cn.outputs.values * inside[cn.outputs.places], minlength=n_t
    )
    return took, put


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
        candidates += [_grow_flow(cn, c) for c in classes[:GROW_CLASSES]]
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


def _grow_flow(cn: CompactNet, members: IntArray) -> IntArray:
    """``members`` plus, a few times over, the input places of the transitions that put
    more tokens into the set than they take: what a flow containing ``members`` needs
    (taking more than putting back is fine for an "at most one" flow)."""
    inside = np.zeros(cn.n_places, dtype=bool)
    inside[members] = True
    for _ in range(3):
        took, put = _flow_through(cn, inside)
        grows = put > took
        if not grows.any():
            break
        inside[cn.inputs.places[grows[cn.inputs.rows]]] = True
    return np.flatnonzero(inside)


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
    flows = [(c, kind) for c in candidates if (kind := _flow_kind(cn, c)) is not None]
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
