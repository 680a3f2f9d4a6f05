"""Place bounds proven by P-invariants, for the widths of count fields.

A count field that is too narrow is widened when a marking overflows it, and every
widening re-packs the whole store; one that is too wide costs bits in every stored key.
A P-invariant ``y`` (``y >= 0``, ``y^T C = 0``) proves ``M(p) <= y.M0 // y(p)`` for every
reachable ``M``: a field is never given more bits than that bound needs, which is what
keeps a bounded net in the fewest key words (FMS-PT-00005: 58 bits, one word, where
widening by guesses reached 79 bits, two words).

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

import numpy as np

from analysis.budget import Budget
from analysis.encoding.compact import CompactNet, IntArray
from analysis.invariants import invariant_bounds, p_invariants

BOUNDS_SECONDS = 0.25
"""Time slice of the invariant search; the invariants found by then still bound."""

BOUNDS_ROWS = 20_000
"""Most working rows of the invariant search (Fourier-Motzkin elimination)."""

_CACHE = "_invariant_place_bounds"

UNBOUNDED = -1
"""`invariant_place_bounds` of a place no invariant found bounds."""


def invariant_place_bounds(cn: CompactNet, budget: Budget | None = None) -> IntArray:
    """Per place, the smallest bound the P-invariants found prove (`UNBOUNDED` where
    none does). Each listed invariant is genuine even when the search stopped at its
    limits, so the bounds are sound either way; they are only fewer."""
    known = cn.__dict__.get(_CACHE)  # (one search per net: queries explore it often)
    if known is not None:
        return np.array(known, dtype=np.int64)
    out = np.full(cn.n_places, UNBOUNDED, dtype=np.int64)
    if not cn.n_places:
        return out
    search = (budget or Budget()).child(seconds=BOUNDS_SECONDS)
    basis = p_invariants(cn.net, max_rows=BOUNDS_ROWS, budget=search)
    for name, bound in invariant_bounds(cn.net, basis).items():
        out[cn.net.place_index(name)] = min(bound, np.iinfo(np.int64).max)
    cn.__dict__[_CACHE] = out.copy()  # as `functools.cached_property` does
    return out
