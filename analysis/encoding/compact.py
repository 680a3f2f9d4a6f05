"""The net as numpy arrays (`CompactNet`), built once from its arcs: presets and effects
are sparse, grouped by preset size, so that enabling over a whole frontier is a handful
of vectorised gathers.

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from coral_lang.net import Net

IntArray = npt.NDArray[np.int64]
KeyArray = npt.NDArray[np.uint64]
BoolArray = npt.NDArray[np.bool_]


MAX_FIELD_BITS = 60
"""Widest bit field for one place. Token counts at or above ``2**60`` stop exploration
(such a count only arises in unbounded nets, long after any sensible budget)."""

FIELD_LOOP = 256
"""Up to this many fields, re-packing loops over fields (fast passes over one word
row); beyond, it works on whole blocks of fields at once."""

NEVER = 1 << 62
"""Field limit of a component's place: it holds at most one token, it never
overflows."""


@dataclass(frozen=True)
class PresetGroup:
    """Transitions that share a preset size ``s``: their input places and weights.

    Attributes:
        transitions: indices of the transitions in the group, shape ``(g,)``.
        places: input place of each arc, shape ``(g, s)``.
        weights: arc weight of each arc, shape ``(g, s)``.
    """

    transitions: IntArray
    places: IntArray
    weights: IntArray


def row_entries(indptr: IntArray, counts: IntArray, rows: IntArray) -> tuple[IntArray, IntArray]:
    """For compressed rows (row ``i`` is entries ``indptr[i]:indptr[i+1]``, ``counts``
    their lengths) and a sequence of ``rows``: ``(owner, entry)``, one pair per entry
    of each row, ``owner`` being the position in ``rows``."""
    taken = counts.take(rows)
    owner = np.repeat(np.arange(rows.size, dtype=np.int64), taken)
    offsets = np.cumsum(taken) - taken
    entry = np.arange(owner.size, dtype=np.int64) - offsets.take(owner)
    entry += indptr.take(rows).take(owner)
    return owner, entry


@dataclass(frozen=True)
class Arcs:
    """One sparse row per transition (compressed rows): ``places[indptr[t]:indptr[t+1]]``
    with ``values`` alongside, places ascending within a row."""

    indptr: IntArray
    places: IntArray
    values: IntArray

    @cached_property
    def counts(self) -> IntArray:
        """Entries per transition."""
        return np.diff(self.indptr)

    @cached_property
    def rows(self) -> IntArray:
        """The transition of every entry."""
        return np.repeat(np.arange(self.counts.size, dtype=np.int64), self.counts)

    def dense(self, n_places: int) -> IntArray:
        """The matrix ``(transitions, n_places)`` these rows describe."""
        out = np.zeros((self.counts.size, n_places), dtype=np.int64)
        out[self.rows, self.places] = self.values
        return out

    def expand(self, transitions: IntArray) -> tuple[IntArray, IntArray]:
        """For a sequence of transitions: ``(owner, entry)``, one pair per entry of each
        one's row, ``owner`` being the position in ``transitions``."""
        return row_entries(self.indptr, self.counts, transitions)

    @classmethod
    def of(cls, rows: Sequence[dict[int, int]]) -> Arcs:
        """From one ``{place: value}`` dict per transition (zero values dropped)."""
        counts = [sum(1 for v in row.values() if v) for row in rows]
        indptr = np.zeros(len(rows) + 1, dtype=np.int64)
        indptr[1:] = np.cumsum(counts)
        places = [p for row in rows for p in sorted(row) if row[p]]
        values = [row[p] for row in rows for p in sorted(row) if row[p]]
        return cls(indptr, np.array(places, dtype=np.int64), np.array(values, dtype=np.int64))


@dataclass(frozen=True)
class CompactNet:
    """A `Net` as arrays: everything the vectorised explorer needs, computed once.

    Attributes:
        net: the net this was built from.
        initial: initial marking, shape ``(P,)``.
        inputs: input arcs (weights) per transition; parallel arcs add up.
        outputs: output arcs per transition.
        effects: non-zero entries of ``post - pre`` per transition.
        groups: sparse presets grouped by size (size 0 = always enabled).
        inc_places: for every transition, the places it strictly increases, padded
            with ``-1``; shape ``(T, k)`` with ``k`` the largest such count (>= 1).
        inc_amounts: the matching increases (0 in the padding).
        max_increase: largest increase of each place by any single firing.
    """

    net: Net
    initial: IntArray
    inputs: Arcs
    outputs: Arcs
    effects: Arcs
    groups: tuple[PresetGroup, ...]
    inc_places: IntArray
    inc_amounts: IntArray
    max_increase: IntArray

    @property
    def n_places(self) -> int:
        """Number of places (columns of a marking)."""
        return int(self.initial.size)

    @property
    def n_transitions(self) -> int:
        """Number of transitions."""
        return int(self.inputs.counts.size)

    @cached_property
    def pre(self) -> IntArray:
        """``pre[t, p]`` = weight of arc ``p -> t`` (0 if none), shape ``(T, P)``; dense,
        built on first use."""
        return self.inputs.dense(self.n_places)

    @cached_property
    def post(self) -> IntArray:
        """``post[t, p]`` = weight of arc ``t -> p``, shape ``(T, P)``; dense."""
        return self.outputs.dense(self.n_places)

    @cached_property
    def delta(self) -> IntArray:
        """``post - pre``, the effect of firing ``t``; dense."""
        return self.effects.dense(self.n_places)

    @cached_property
    def self_loops(self) -> BoolArray:
        """Transitions whose firing changes nothing (their successor is the marking
        itself)."""
        loops: BoolArray = self.effects.counts == 0
        return loops

    @classmethod
    def from_net(cls, net: Net) -> CompactNet:
        """Build the arrays of ``net`` from its arcs (never a dense scan: a mission can
        have thousands of places and transitions)."""
        index = {p.name: i for i, p in enumerate(net.places)}
        pre_rows: list[dict[int, int]] = []
        post_rows: list[dict[int, int]] = []
        effect_rows: list[dict[int, int]] = []
        for tr in net.transitions:
            pre: dict[int, int] = {}
            post: dict[int, int] = {}
            for name, weight in tr.inputs:
                pre[index[name]] = pre.get(index[name], 0) + weight
            for name, weight in tr.outputs:
                post[index[name]] = post.get(index[name], 0) + weight
            pre_rows.append(pre)
            post_rows.append(post)
            effect_rows.append({p: post.get(p, 0) - pre.get(p, 0) for p in {*pre, *post}})
        inputs, outputs, effects = Arcs.of(pre_rows), Arcs.of(post_rows), Arcs.of(effect_rows)
        initial = np.array([p.initial for p in net.places], dtype=np.int64)

        sizes = inputs.counts
        groups = []
        for size in sorted(set(sizes.tolist())):
            members = np.flatnonzero(sizes == size)
            take = (inputs.indptr[members][:, None] + np.arange(size)).reshape(-1)
            places = inputs.places[take].reshape(members.size, size)
            weights = inputs.values[take].reshape(members.size, size)
            groups.append(PresetGroup(members.astype(np.int64), places, weights))

        raised = [sorted(p for p, d in row.items() if d > 0) for row in effect_rows]
        width = max(1, max((len(r) for r in raised), default=0))
        inc_places = np.full((len(raised), width), -1, dtype=np.int64)
        inc_amounts = np.zeros((len(raised), width), dtype=np.int64)
        for t, cols in enumerate(raised):
            inc_places[t, : len(cols)] = cols
            inc_amounts[t, : len(cols)] = [effect_rows[t][p] for p in cols]
        max_increase = np.zeros(len(net.places), dtype=np.int64)
        up = effects.values > 0
        np.maximum.at(max_increase, effects.places[up], effects.values[up])
        return cls(
            net,
            initial,
            inputs,
            outputs,
            effects,
            tuple(groups),
            inc_places,
            inc_amounts,
            max_increase,
        )
