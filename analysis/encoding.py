"""Compact, array-based views of a `Net` for fast exploration.

What lives here:

* `CompactNet`: the net as numpy arrays, built once from its arcs. Presets and effects
  are sparse (one entry per arc), grouped by preset size so that enabling over a whole
  frontier is a handful of vectorised gathers. Dense ``pre``/``post``/``delta``
  matrices (transitions x places) are built only when asked for: a mission with
  10,000 transitions and places would need gigabytes for them.
* `one_hot_components`: sets of places proven (on the arcs, exactly) never to hold more
  than one token between them, e.g. the control states of a process or a branch of a
  mission.
* `Layout`: how a marking is packed into a few ``uint64`` words. Each *field* is either
  one place's token count (wide enough for the tokens seen so far) or a component,
  stored as which of its ``k`` places is marked: ``log2 k`` bits instead of ``k``.
  Packing is linear and injective on reachable markings, so two markings are equal
  exactly when their keys are, and the key of ``m + delta(t)`` is
  ``key(m) + key_delta(t)`` (mod ``2**64`` per word) as long as no count field
  overflows, which the explorer checks before it trusts a successor key.
* `FieldNet`: the net seen through the fields, so that the frontier holds field values
  (11 per Peterson marking instead of 244 place counts).
* `KeyStore`: the packed keys in discovery order plus an open-addressing hash table of
  them, with batch insertion vectorised over whole frontiers.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

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
        counts = self.counts.take(transitions)
        owner = np.repeat(np.arange(transitions.size, dtype=np.int64), counts)
        offsets = np.cumsum(counts) - counts
        entry = np.arange(owner.size, dtype=np.int64) - offsets.take(owner)
        entry += self.indptr.take(transitions).take(owner)
        return owner, entry

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


def _components_by_elimination(cn: CompactNet, deadline: float) -> list[IntArray]:
    """Place sets with unit weights that form a P-invariant holding one token:
    Fourier-Motzkin elimination (as for P-semiflows) restricted to 0/1 rows with at
    most one initial token, which keeps the rows few. Verified by the caller."""
    incidence = cn.delta.T.astype(np.int32)  # (P, T)
    keep = cn.initial <= 1
    rows = np.eye(cn.n_places, dtype=bool)[keep]
    residual = incidence[keep]
    tokens = cn.initial[keep]
    pending = np.flatnonzero((residual != 0).any(axis=0))
    while pending.size and rows.shape[0]:
        if time.perf_counter() > deadline:
            break
        sub = residual[:, pending]
        cost = (sub > 0).sum(axis=0) * (sub < 0).sum(axis=0) - (sub != 0).sum(axis=0)
        k = int(np.argmin(cost))
        t = int(pending[k])
        pending = np.delete(pending, k)
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
                digest = packed @ _multipliers(packed.shape[1])
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


def one_hot_components(cn: CompactNet, seconds: float = SEARCH_SECONDS) -> list[Component]:
    """Disjoint sets of places that never hold more than one token between them, each
    proven on the arcs by a *flow*: unit weights, one initial token, and no transition
    putting back more than it takes (see `_flow_kind`). When every transition puts
    back exactly what it takes, the flow always holds exactly one token. Flows are
    taken largest first; one overlapping chosen ones contributes what is left.

    Args:
        cn: the net.
        seconds: budget of the elimination search (small nets only).

    Returns:
        The components, each saving bits over one count field per place.
    """
    candidates = _components_by_unit_moves(cn)
    if cn.n_places * cn.n_transitions <= DENSE_SEARCH_CELLS and cn.n_places <= SEARCH_PLACES:
        candidates += _components_by_elimination(cn, time.perf_counter() + seconds)
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


# -- packing -----------------------------------------------------------------------------


def _bits_for(value: int) -> int:
    return int(value).bit_length()


def _count_bits(value: int) -> int:
    return max(1, _bits_for(value))


@dataclass(frozen=True)
class Layout:
    """Where each place's token count sits inside the packed key of a marking.

    A key is a row of ``n_words`` ``uint64`` words; each word holds fields side by side
    with its top bit always 0 (so a key plus one, the table's tag, never wraps). A field
    is a place's count (``onehot`` false) or, for a `Component`, which of its places
    holds the token: ``first[f] + i`` for its ``i``-th place, 0 for none when
    ``first[f]`` is 1.

    Attributes:
        bits: width of each field.
        members: places of each field.
        onehot: whether each field is a component.
        word: which word holds each field.
        shift: bit offset of each field inside its word.
        n_words: words per marking.
        n_places: places of the net.
        first: per field, the value of its first place (0 for counts and components
            that always hold a token, 1 for the others); empty means all 0.
    """

    bits: tuple[int, ...]
    members: tuple[tuple[int, ...], ...]
    onehot: tuple[bool, ...]
    word: IntArray
    shift: npt.NDArray[np.uint64]
    n_words: int
    n_places: int
    first: tuple[int, ...] = ()

    @classmethod
    def build(
        cls,
        bits: Sequence[int],
        members: Sequence[Sequence[int]],
        onehot: Sequence[bool],
        n_places: int,
        first: Sequence[int] = (),
    ) -> Layout:
        """Pack the fields first-fit, widest first (fewest words), never past bit 62."""
        word = np.zeros(len(bits), dtype=np.int64)
        shift = np.zeros(len(bits), dtype=np.uint64)
        used: list[int] = []
        for f in sorted(range(len(bits)), key=lambda f: -bits[f]):
            w = next((w for w, u in enumerate(used) if u + bits[f] <= 63), len(used))
            if w == len(used):
                used.append(0)
            word[f], shift[f] = w, used[w]
            used[w] += bits[f]
        return cls(
            tuple(int(b) for b in bits),
            tuple(tuple(int(p) for p in m) for m in members),
            tuple(bool(o) for o in onehot),
            word,
            shift,
            max(1, len(used)),
            n_places,
            tuple(int(v) for v in first) or (0,) * len(bits),
        )

    @classmethod
    def for_bits(cls, bits: Sequence[int]) -> Layout:
        """One count field per place, of the given widths."""
        return cls.build(bits, [(p,) for p in range(len(bits))], [False] * len(bits), len(bits))

    @classmethod
    def initial_guess(cls, cn: CompactNet, components: Sequence[Component] | None = None) -> Layout:
        """One field per component, and count fields wide enough for the initial
        marking and one firing's increase for the other places."""
        components = list(components or [])
        covered = np.zeros(cn.n_places, dtype=bool)
        for c in components:
            covered[c.places] = True
        bits = [_bits_for(c.values - 1) for c in components]
        members: list[Sequence[int]] = [c.places.tolist() for c in components]
        onehot = [True] * len(components)
        first = [0 if c.exact else 1 for c in components]
        for p in np.flatnonzero(~covered).tolist():
            bits.append(_count_bits(max(int(cn.initial[p]), int(cn.max_increase[p]))))
            members.append((p,))
            onehot.append(False)
            first.append(0)
        return cls.build(bits, members, onehot, cn.n_places, first)

    def widened(self, needed: dict[int, int], growing: Sequence[int] = ()) -> Layout:
        """A layout where place ``p`` holds at least ``needed[p]`` (the largest count
        about to be reached; never a one-hot place).

        Every re-packing costs a pass over all stored keys, and every extra word slows
        every later step, so: a needed field gets one bit of headroom; then the spare
        bits of the words that are needed anyway go to the ``growing`` places (counts
        close to their limit, widened three times already), each at most doubling. A
        place that keeps growing is thus re-packed about ``log log bound`` times, and
        a bounded net keeps the fewest words its bounds allow.
        """
        bits = list(self.bits)
        for p, value in needed.items():
            f = int(self.field_of[p])
            bits[f] = max(bits[f] + 1, _count_bits(value) + 1)
        words = self._rebuilt(bits).n_words
        for p in growing:
            f = int(self.field_of[p])
            trial = list(bits)
            trial[f] = min(2 * bits[f], MAX_FIELD_BITS)
            fits = trial[f] > bits[f] and sum(trial) <= 63 * words
            if fits and self._rebuilt(trial).n_words == words:
                bits = trial
        return self._rebuilt(bits)

    def _rebuilt(self, bits: Sequence[int]) -> Layout:
        """This layout with other field widths."""
        return Layout.build(bits, self.members, self.onehot, self.n_places, self.first)

    def repack(self, keys: KeyArray, other: Layout) -> KeyArray:
        """``keys`` (packed with this layout) packed with ``other``, which has the same
        fields, possibly wider: field by field, never through full markings, in blocks
        of rows (a widening re-packs the whole store)."""
        out = np.empty((keys.shape[0], other.n_words), dtype=np.uint64)
        fields = len(self.bits)
        step = 1 << 16 if fields <= FIELD_LOOP else max(1, (1 << 22) // fields)
        for start in range(0, keys.shape[0], step):
            block = keys[start : start + step]
            if fields <= FIELD_LOOP:
                out[start : start + step] = self._repack_by_field(block, other)
            else:
                out[start : start + step] = self._repack_at_once(block, other)
        return out

    def _masks(self) -> KeyArray:
        return (np.uint64(1) << np.asarray(self.bits, dtype=np.uint64)) - np.uint64(1)

    def _repack_by_field(self, keys: KeyArray, other: Layout) -> KeyArray:
        """Few fields: one pass per field over contiguous word rows."""
        words = np.ascontiguousarray(keys.T)
        out = np.zeros((other.n_words, keys.shape[0]), dtype=np.uint64)
        masks = self._masks()
        for f in range(len(self.bits)):
            value = words[self.word[f]] >> self.shift[f]
            value &= masks[f]
            value <<= other.shift[f]
            out[other.word[f]] |= value
        return out.T

    def _repack_at_once(self, keys: KeyArray, other: Layout) -> KeyArray:
        """Many fields: 2-D passes (a per-field loop would cost a numpy call each)."""
        fields = (keys[:, self.word] >> self.shift) & self._masks()
        fields <<= other.shift
        out = np.zeros((keys.shape[0], other.n_words), dtype=np.uint64)
        for w in range(other.n_words):
            cols = other.word == w
            if cols.any():
                out[:, w] = fields[:, cols].sum(axis=1, dtype=np.uint64)
        return out

    # -- per place views ------------------------------------------------------------

    @cached_property
    def field_of(self) -> IntArray:
        """The field of each place."""
        out = np.zeros(self.n_places, dtype=np.int64)
        for f, places in enumerate(self.members):
            out[list(places)] = f
        return out

    @cached_property
    def place_onehot(self) -> BoolArray:
        """Whether each place belongs to a one-hot component."""
        return (
            np.asarray(self.onehot, dtype=bool)[self.field_of]
            if self.n_places
            else np.zeros(0, bool)
        )

    @cached_property
    def coefficient(self) -> KeyArray:
        """What one token on each place adds to its field: 1 for a count, the place's
        value in its component (``first`` plus its index) for a component's place."""
        out = np.ones(self.n_places, dtype=np.uint64)
        for places, onehot, first in zip(self.members, self.onehot, self.first, strict=True):
            if onehot:
                out[list(places)] = np.arange(len(places), dtype=np.uint64) + np.uint64(first)
        return out

    @cached_property
    def multiplier(self) -> KeyArray:
        """What one token on each place adds to its word of the key."""
        if not self.n_places:
            return np.zeros(0, dtype=np.uint64)
        return self.coefficient << self.shift[self.field_of]

    @cached_property
    def place_word(self) -> IntArray:
        """The word holding each place's field."""
        return self.word[self.field_of] if self.n_places else np.zeros(0, np.int64)

    @property
    def limits(self) -> IntArray:
        """Per place, the first token count that no longer fits (`NEVER` for one-hot
        places, which hold at most one token)."""
        widths = np.asarray(self.bits, dtype=np.int64)[self.field_of]
        out = np.left_shift(np.int64(1), widths)
        out[self.place_onehot] = NEVER
        return out

    @property
    def count_bits(self) -> IntArray:
        """Per place, the width of its count field (0 for one-hot places)."""
        widths = np.asarray(self.bits, dtype=np.int64)[self.field_of]
        widths[self.place_onehot] = 0
        return widths

    @property
    def boundary(self) -> KeyArray:
        """Per word, the bit just above every count field: an addition that overflows a
        field carries into it."""
        out = np.zeros(self.n_words, dtype=np.uint64)
        for f, width in enumerate(self.bits):
            if not self.onehot[f]:
                out[self.word[f]] |= np.uint64(1 << (int(self.shift[f]) + width))
        return out

    # -- packing ---------------------------------------------------------------------

    def pack(self, rows: npt.NDArray[np.integer]) -> KeyArray:
        """Keys of reachable markings ``rows`` (shape ``(n, P)``), shape
        ``(n, n_words)``."""
        keys = np.zeros((rows.shape[0], self.n_words), dtype=np.uint64)
        if not self.n_places:
            return keys
        values = rows.astype(np.uint64) * self.multiplier
        for w in range(self.n_words):
            cols = self.place_word == w
            if cols.any():
                keys[:, w] = values[:, cols].sum(axis=1, dtype=np.uint64)
        return keys

    def unpack(self, keys: KeyArray, dtype: npt.DTypeLike = np.int64) -> npt.NDArray[np.integer]:
        """Markings of ``keys`` (shape ``(n, n_words)``) as rows of ``dtype``."""
        if not self.n_places:
            return np.zeros((keys.shape[0], 0), dtype=dtype)
        widths = np.asarray(self.bits, dtype=np.uint64)[self.field_of]
        masks = (np.uint64(1) << widths) - np.uint64(1)
        fields = (keys[:, self.place_word] >> self.shift[self.field_of]) & masks
        onehot = self.place_onehot
        if onehot.any():
            fields[:, onehot] = fields[:, onehot] == self.coefficient[onehot]
        return fields.astype(dtype)

    def key_deltas(self, arcs: Arcs) -> KeyArray:
        """Per transition, what adding its ``arcs`` (e.g. its effect) adds to each key
        word (mod ``2**64``)."""
        n_t = arcs.counts.size
        out = np.zeros(n_t * self.n_words, dtype=np.uint64)
        if arcs.places.size:
            amounts = arcs.values.astype(np.int64).view(np.uint64)
            with np.errstate(over="ignore"):
                contribution = amounts * self.multiplier[arcs.places]
            slot = arcs.rows * self.n_words + self.place_word[arcs.places]
            np.add.at(out, slot, contribution)
        return out.reshape(n_t, self.n_words)


@dataclass(frozen=True)
class FieldGroup:
    """Transitions with the same number of input fields, as `PresetGroup` but per
    field: a transition is enabled when, for every column ``k``, its input field
    ``fields[:, k]`` holds at least ``low[:, k]`` (a count) or exactly ``low[:, k]``
    (``exact``: the index of a one-hot place)."""

    transitions: IntArray
    fields: IntArray
    low: IntArray
    exact: BoolArray


class FieldNet:
    """The net seen through the fields of a `Layout`: enabling, effects and overflow
    checks on field values, so a frontier marking is ``fields`` small integers instead
    of ``places`` (a 56-place process is one field holding the index of its marked
    place). Widening changes field widths, never the fields, so this is built once per
    exploration.

    Attributes:
        n_fields: fields per marking.
        initial: field values of the initial marking.
        groups: presets by size, per field.
        never: transitions that can never be enabled (two tokens asked of a
            component).
        effects: per transition, the change of each field it changes.
        inc_fields: per transition, the count fields it increases, padded with ``-1``.
        inc_amounts: the matching increases.
        max_increase: per field, the largest increase of one firing (0 for one-hot).
        onehot: per field, whether it is a one-hot component.
        count_place: per field, its place if it is a count field, else ``-1``.
        offsets: per component field, where its values start in a flat array of
            (field, value) flags; ``seen_slot`` is that flag for each component place.
        exact: per field, whether it is a component that always holds a token;
            ``partial`` the other components.
    """

    def __init__(self, cn: CompactNet, layout: Layout) -> None:
        field_of, coefficient = layout.field_of, layout.coefficient.astype(np.int64)
        onehot_place = layout.place_onehot
        self.n_fields = len(layout.bits)
        self.onehot = np.asarray(layout.onehot, dtype=bool)
        self.count_place = np.array(
            [m[0] if not o else -1 for m, o in zip(layout.members, layout.onehot, strict=True)],
            dtype=np.int64,
        )
        kinds = list(zip(layout.members, layout.onehot, layout.first, strict=True))
        sizes = np.array([len(m) + first if o else 0 for m, o, first in kinds], dtype=np.int64)
        self.offsets = np.cumsum(sizes) - sizes
        self.n_seen = int(sizes.sum())
        self.onehot_places = np.array([p for m, o, _ in kinds if o for p in m], dtype=np.int64)
        self.seen_slot = (self.offsets[field_of] + coefficient)[self.onehot_places]
        self.exact = self.onehot & (np.asarray(layout.first, dtype=np.int64) == 0)
        self.partial = self.onehot & ~self.exact
        self.initial = self.values(cn.initial[None, :], layout)[0]
        groups, never = [], []
        for g in cn.groups:
            exact = onehot_place[g.places]
            low = np.where(exact, coefficient[g.places], g.weights)
            never.append(g.transitions[(exact & (g.weights > 1)).any(axis=1)])
            groups.append(FieldGroup(g.transitions, field_of[g.places], low, exact))
        self.groups = tuple(groups)
        self.never = np.concatenate(never) if never else np.zeros(0, dtype=np.int64)
        self.effects = self._field_effects(cn, field_of, coefficient)
        eff = self.effects
        raise_ = (eff.values > 0) & ~self.onehot[eff.places]
        rows, fields, amounts = eff.rows[raise_], eff.places[raise_], eff.values[raise_]
        counts = np.bincount(rows, minlength=cn.n_transitions)
        width = max(1, int(counts.max(initial=0)))
        self.inc_fields = np.full((cn.n_transitions, width), -1, dtype=np.int64)
        self.inc_amounts = np.zeros((cn.n_transitions, width), dtype=np.int64)
        slot = np.arange(rows.size) - (np.cumsum(counts) - counts)[rows]
        self.inc_fields[rows, slot] = fields
        self.inc_amounts[rows, slot] = amounts
        self.max_increase = np.zeros(self.n_fields, dtype=np.int64)
        np.maximum.at(self.max_increase, fields, amounts)

    @staticmethod
    def _field_effects(cn: CompactNet, field_of: IntArray, coefficient: IntArray) -> Arcs:
        """Per transition, the net change of each field (a move inside a one-hot
        component changes its field by the difference of the two indices)."""
        eff = cn.effects
        n_f = int(field_of.max(initial=-1)) + 1
        key = eff.rows * n_f + field_of[eff.places]
        unique, inverse = np.unique(key, return_inverse=True)
        total = np.bincount(inverse, weights=eff.values * coefficient[eff.places])
        total = np.rint(total).astype(np.int64)
        keep = total != 0
        rows, fields = unique[keep] // max(1, n_f), unique[keep] % max(1, n_f)
        indptr = np.zeros(cn.n_transitions + 1, dtype=np.int64)
        indptr[1:] = np.cumsum(np.bincount(rows, minlength=cn.n_transitions))
        return Arcs(indptr, fields, total[keep])

    @staticmethod
    def values(rows: npt.NDArray[np.integer], layout: Layout) -> IntArray:
        """Field values of markings ``rows`` (shape ``(n, P)``), shape ``(n, fields)``."""
        out = np.zeros((rows.shape[0], len(layout.bits)), dtype=np.int64)
        if layout.n_places:
            weighted = rows.astype(np.int64) * layout.coefficient.astype(np.int64)
            np.add.at(out.T, layout.field_of, weighted.T)
        return out

    def places(self, cols: npt.NDArray[np.integer], layout: Layout) -> IntArray:
        """Place counts ``(P, n)`` of markings given as field columns ``(fields, n)``."""
        out = cols.take(layout.field_of, axis=0).astype(np.int64)
        onehot = layout.place_onehot
        if onehot.any():
            coefficient = layout.coefficient.astype(np.int64)[onehot]
            out[onehot] = out[onehot] == coefficient[:, None]
        return out


def row_dtype(layout: Layout, cn: CompactNet) -> np.dtype[np.signedinteger]:
    """Smallest signed integer type for frontier rows (field values): holds every field
    value plus one firing's effect, and every arc weight, so comparisons and
    ``row + delta`` never wrap (a value past its field's limit shows as such)."""
    effect = int(np.abs(cn.effects.values).max(initial=0))
    largest = max(
        (1 << max(layout.bits, default=1)) - 1 + effect,
        int(cn.inputs.values.max(initial=0)),
    )
    for candidate in (np.int8, np.int16, np.int32):
        if largest <= np.iinfo(candidate).max:
            return np.dtype(candidate)
    return np.dtype(np.int64)


# -- hashing -----------------------------------------------------------------------------

_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
EMPTY = np.uint64(0)
"""Marks a free slot: tags are never 0 (a one-word key plus one, its top bit being 0,
or a 63-bit hash plus one), so a table is born free from zeroed memory."""

MAX_LOAD = 0.5
"""Largest fill of the table after a batch (linear probing stays ~1.5 probes)."""

BATCH_LOAD = 0.75
"""Largest fill while a batch is placed (batches are cut to stay below it)."""

_S1, _S27, _S29, _S30, _S31, _S32 = (np.uint64(k) for k in (1, 27, 29, 30, 31, 32))

FILL_CHUNK = 1 << 18
"""Keys placed per step when a table is rebuilt (bounds its temporaries)."""

PROBE_WINDOW_BELOW = 8192
"""Probe batches up to this size look at `_WINDOW` consecutive slots per round."""

_WINDOW = np.arange(8, dtype=np.int64)


WIDE_KEYS = 8
"""From this many words per key, hash and compare with whole-array operations: one
numpy call per word costs more than the 2-D work once keys are wide (missions with
thousands of places pack into dozens of words)."""

_WORD_MULTIPLIERS = np.random.default_rng(0x5EED).integers(
    1, np.iinfo(np.int64).max, size=4096, dtype=np.int64
).astype(np.uint64) | np.uint64(1)


def _multipliers(words: int) -> KeyArray:
    if words <= _WORD_MULTIPLIERS.size:
        return _WORD_MULTIPLIERS[:words]
    reps = -(-words // _WORD_MULTIPLIERS.size)
    return np.tile(_WORD_MULTIPLIERS, reps)[:words] * np.uint64(0x9E37)


def _mix(h: KeyArray) -> KeyArray:
    """Finaliser of splitmix64, in place: every input bit affects every output bit."""
    h ^= h >> _S30
    h *= _MIX1
    h ^= h >> _S27
    h *= _MIX2
    h ^= h >> _S31
    return h


def _hash(keys: KeyArray) -> KeyArray:
    """A well-mixed 64-bit hash of each key row.

    The hash only chooses slots (and, for keys of several words, the tag kept in the
    table); keys are always compared in full, so its quality affects speed, never
    exactness.
    """
    if keys.shape[1] == 1:
        h = keys[:, 0] * _GOLDEN
        h ^= h >> _S32
        h *= _MIX1
        return h
    with np.errstate(over="ignore"):
        if keys.shape[1] >= WIDE_KEYS:
            mixed: KeyArray = (keys * _multipliers(keys.shape[1])).sum(axis=1, dtype=np.uint64)
            return _mix(mixed)
        h = keys[:, 0] ^ (keys[:, 0] >> _S30)
        for w in range(1, keys.shape[1]):
            h = (h ^ (h >> _S29)) * _GOLDEN + keys[:, w]
            h ^= h >> _S30
        return _mix(h)


def _rows_differ(a: KeyArray, b: KeyArray) -> BoolArray:
    """Row-wise ``a != b`` over all words, one word at a time (no 2-D reduction)
    unless the keys are wide."""
    if a.shape[1] >= WIDE_KEYS:
        wide: BoolArray = (a != b).any(axis=1)
        return wide
    out: BoolArray = a[:, 0] != b[:, 0]
    for w in range(1, a.shape[1]):
        out |= a[:, w] != b[:, w]
    return out


def first_occurrences(keys: KeyArray) -> tuple[IntArray, IntArray]:
    """Distinct rows of ``keys`` by first occurrence.

    Returns:
        ``(first, leader)``: ascending positions of the first occurrence of each
        distinct row, and for every row the position of its first occurrence.
    """
    m = keys.shape[0]
    if m == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if keys.shape[1] == 1:
        order = np.argsort(keys[:, 0], kind="stable")
        ordered = keys[order, 0]
        starts = np.empty(m, dtype=bool)
        starts[0] = True
        np.not_equal(ordered[1:], ordered[:-1], out=starts[1:])
    else:
        # Sort by a 64-bit hash (cheaper than a lexicographic sort of W words); equal
        # rows are adjacent. A hash collision between different rows (vanishingly
        # rare) would make them adjacent too: then fall back to the exact sort.
        order = np.argsort(_hash(keys), kind="stable")
        ordered2 = keys[order]
        differs = _rows_differ(ordered2[1:], ordered2[:-1])
        hashes = _hash(ordered2)
        if (differs & (hashes[1:] == hashes[:-1])).any():
            order = np.lexsort(keys.T[::-1])  # stable: equal rows keep batch order
            ordered2 = keys[order]
            differs = _rows_differ(ordered2[1:], ordered2[:-1])
        starts = np.empty(m, dtype=bool)
        starts[0] = True
        starts[1:] = differs
    group_first = order[starts]
    leader = np.empty(m, dtype=np.int64)
    leader[order] = group_first[np.cumsum(starts) - 1]
    return np.sort(group_first), leader


@dataclass(frozen=True)
class Added:
    """What `KeyStore.add` did with a batch of candidate keys.

    Attributes:
        first: positions of the candidates stored as new states, ascending; the new
            states are numbered ``start, start + 1, ...`` in this order, and each is
            the first candidate with its key.
        start: the state number given to ``first[0]``.
        cut: whether the state limit turned new states away.
        ids: when asked for, the state number of every candidate (``-1`` for one the
            limit turned away).
    """

    first: IntArray
    start: int
    cut: bool
    ids: IntArray | None = None

    @property
    def known(self) -> BoolArray:
        """Per candidate, whether its key was stored before the batch (needs ``ids``)."""
        assert self.ids is not None, "add(..., want_ids=True) gives ids"
        return (self.ids >= 0) & (self.ids < self.start)


class Growable:
    """An array that grows along its first axis. Its capacity is reserved up front as
    zeroed memory, which costs only address space until rows are written (the kernel
    hands out pages as they are touched, and here touching a fresh page costs far more
    than writing it), so growing within the reservation never copies or re-touches."""

    def __init__(self, tail: tuple[int, ...], dtype: npt.DTypeLike, reserve: int) -> None:
        self._data: npt.NDArray[Any] = _reserved((reserve, *tail), dtype)
        self.size = 0

    @property
    def view(self) -> npt.NDArray[Any]:
        """The rows written so far (a view)."""
        return self._data[: self.size]

    @property
    def capacity(self) -> int:
        """Rows that fit without copying."""
        return int(self._data.shape[0])

    def ensure(self, rows: int) -> None:
        """Room for ``rows`` rows (copies only past the reservation, doubling)."""
        if rows > self._data.shape[0]:
            shape = (max(rows, 2 * self._data.shape[0]), *self._data.shape[1:])
            grown = np.zeros(shape, dtype=self._data.dtype)
            grown[: self.size] = self._data[: self.size]
            self._data = grown

    def append(self, rows: npt.NDArray[Any]) -> None:
        """Add ``rows`` at the end."""
        end = self.size + rows.shape[0]
        self.ensure(end)
        self._data[self.size : end] = rows
        self.size = end


RESERVE_LIMIT = 1 << 26
"""Most states a store reserves address space for up front (beyond, it doubles)."""

RESERVE_BYTES = 1 << 30
"""Most bytes of address space one reserved array takes (wide keys reserve fewer
rows), so a reservation never approaches what the kernel would refuse."""


def _reserved(shape: tuple[int, ...], dtype: npt.DTypeLike) -> npt.NDArray[Any]:
    """Zeroed memory for up to ``shape[0]`` rows, fewer past `RESERVE_BYTES` or when the
    address space is refused (callers grow past it anyway)."""
    row = max(1, int(np.prod(shape[1:], dtype=np.int64)) * np.dtype(dtype).itemsize)
    rows = max(1, min(shape[0], RESERVE_BYTES // row))
    try:
        return np.zeros((rows, *shape[1:]), dtype=dtype)
    except MemoryError:
        return np.zeros((min(rows, 1 << 12), *shape[1:]), dtype=dtype)


class KeyStore:
    """Packed markings in discovery order plus an open-addressing set of them.

    ``keys[i]`` is the packed marking of state ``i``. The table has one ``uint64`` *tag*
    per slot (``EMPTY`` = free) and the state number stored there. For one-word keys the
    tag is the key plus one; for wider keys it is a 63-bit hash plus one, and a tag
    match is only trusted after the full keys compare equal, so hash collisions cost a
    probe, never a wrong answer. Slots are probed linearly from a hash of the key;
    inserts are vectorised over whole batches, equal keys in one batch resolved in the
    table. The table lives in a prefix of a buffer reserved for ``reserve`` states and
    doubles in place (see `Growable` for why).
    """

    def __init__(
        self,
        n_words: int,
        capacity: int = 1 << 12,
        wide_index: bool = False,
        reserve: int | None = None,
    ) -> None:
        self.n_words = n_words
        self._index_type = np.int64 if wide_index else np.int32
        reserve = min(max(capacity, reserve or 0), RESERVE_LIMIT)
        self._keys = Growable((n_words,), np.uint64, reserve)
        self._log = max(4, (int(capacity / MAX_LOAD) - 1).bit_length())
        room = 1 << (int(reserve / MAX_LOAD) - 1).bit_length()
        self._tag_buffer = _reserved((room,), np.uint64)
        self._index_buffer = _reserved((room,), self._index_type)
        self._use_table(self._log)

    @classmethod
    def of(cls, keys: KeyArray, wide_index: bool = False, reserve: int = 0) -> KeyStore:
        """A store holding ``keys`` (pairwise distinct) as states ``0 .. len-1``."""
        store = cls(keys.shape[1], max(1 << 12, keys.shape[0]), wide_index, reserve)
        store._insert_distinct(np.ascontiguousarray(keys))
        return store

    @property
    def size(self) -> int:
        """Number of stored states."""
        return self._keys.size

    @property
    def keys(self) -> KeyArray:
        """Keys of all stored states, shape ``(size, n_words)`` (a view)."""
        keys: KeyArray = self._keys.view
        return keys

    @property
    def nbytes(self) -> int:
        """Bytes of the stored keys and of the table in use."""
        return int(self.keys.nbytes + self._tags.nbytes + self._index.nbytes)

    def rekey(self, keys: KeyArray) -> None:
        """Replace every stored key by ``keys`` (same states, same order, a new packing,
        pairwise distinct) and rebuild the table in place: a widening re-packs the
        store without allocating (and touching) a new table."""
        keys = np.ascontiguousarray(keys)
        if keys.shape[1] == self.n_words:
            self._keys.view[:] = keys
        else:
            self.n_words = keys.shape[1]
            self._keys = Growable((self.n_words,), np.uint64, self._keys.capacity)
            self._keys.append(keys)
        self._tags[:] = EMPTY
        tags, slots = self._locate(keys)
        self._fill(tags, slots, np.arange(keys.shape[0], dtype=np.int64))

    # -- slots -----------------------------------------------------------------------

    def _locate(self, keys: KeyArray) -> tuple[KeyArray, IntArray]:
        """Tag and home slot of each key."""
        h = _hash(keys)
        slots = (h >> np.uint64(64 - self._log)).view(np.int64)
        if self.n_words == 1:
            tags = keys[:, 0] + np.uint64(1)
        else:
            tags = h >> _S1
            tags += np.uint64(1)
        return tags, slots

    def _same_keys(self, cand: KeyArray, which: IntArray, slots: IntArray) -> BoolArray:
        """Whether candidates ``which`` equal the key in ``slots`` (tags already match;
        only wide keys get here). A negative index refers to a candidate of the batch
        being placed."""
        ref = self._index.take(slots).astype(np.int64)
        other = np.empty((which.size, self.n_words), dtype=np.uint64)
        old = ref >= 0
        other[old] = self.keys.take(ref[old], axis=0)
        other[~old] = cand.take(-1 - ref[~old], axis=0)
        return ~_rows_differ(cand.take(which, axis=0), other)

    def _resize(self, log: int) -> None:
        """A table of ``2**log`` slots, holding every stored key. Reads the old table
        in slot order (no pass over the keys themselves): the new home slots are then
        almost sorted already, which `_fill` likes."""
        occupied = np.flatnonzero(self._tags)
        tags, ids = self._tags.take(occupied), self._index.take(occupied)
        del occupied
        if self.n_words == 1:
            keys = tags - np.uint64(1)
            slots = (_hash(keys[:, None]) >> np.uint64(64 - log)).view(np.int64)
        else:  # the tag is the hash shifted right by one, plus one
            slots = ((tags - np.uint64(1)) >> np.uint64(63 - log)).view(np.int64)
        self._tags[:] = EMPTY  # pages already touched; the rest of a buffer is still zero
        self._use_table(log)
        self._fill(tags, slots, ids)

    def _use_table(self, log: int) -> None:
        """Make the table the first ``2**log`` slots of the buffers (new, larger
        buffers if they are too small)."""
        size = 1 << log
        if size > min(self._tag_buffer.size, self._index_buffer.size):
            self._tag_buffer = np.zeros(size, dtype=np.uint64)
            self._index_buffer = np.zeros(size, dtype=self._index_type)
        self._log = log
        self._tags = self._tag_buffer[:size]
        self._index = self._index_buffer[:size]

    def _fill(self, tags: KeyArray, slots: IntArray, ids: npt.NDArray[np.integer]) -> None:
        """Place distinct keys into an empty table at once: in home-slot order, linear
        probing puts the ``i``-th key at ``max(slot_i, position_{i-1} + 1)``, a running
        maximum, computed a chunk at a time (small temporaries); the few keys that run
        past the end wrap around through `_place`."""
        order = np.argsort(slots, kind="stable")
        last, size, chunk = -1, self._tags.size, FILL_CHUNK
        for start in range(0, order.size, chunk):
            part = order[start : start + chunk]
            steps = np.arange(part.size, dtype=np.int64)
            position = slots.take(part) - steps
            position[0] = max(int(position[0]), last + 1)
            np.maximum.accumulate(position, out=position)
            position += steps
            last = int(position[-1])
            inside = position < size
            rest = part[~inside]
            part, position = part[inside], position[inside]
            self._tags[position] = tags.take(part)
            self._index[position] = ids.take(part)
            if rest.size:  # after the others: they wrap around to the first free slots
                self._place(tags.take(rest), slots.take(rest), ids.take(rest).astype(np.int64))

    def _reserve(self, need: int, load: float) -> None:
        """Grow the table until ``need`` keys fill it at most ``load``."""
        log = self._log
        while need > load * (1 << log):
            log += 1
        if log != self._log:
            self._resize(log)

    def _place(self, tags: KeyArray, slots: IntArray, ids: IntArray) -> None:
        """Write pairwise distinct keys (by tag and home slot) that are not in the table
        yet, as states ``ids``."""
        mask = (1 << self._log) - 1
        table, index = self._tags, self._index
        while slots.size:
            free = np.flatnonzero(table.take(slots) == EMPTY)
            fs, ft, fi = slots.take(free), tags.take(free), ids.take(free)
            table[fs] = ft
            ok = np.flatnonzero(table.take(fs) == ft)
            index[fs.take(ok)] = fi.take(ok)
            placed = np.zeros(slots.size, dtype=bool)
            placed[free.take(ok)] = index.take(fs.take(ok)) == fi.take(ok)
            more = np.flatnonzero(~placed)
            slots = slots.take(more)
            slots += 1
            slots &= mask
            tags, ids = tags.take(more), ids.take(more)

    def _insert_distinct(self, keys: KeyArray) -> None:
        """Store pairwise distinct new keys as the next states."""
        need = self.size + keys.shape[0]
        self._reserve(need, MAX_LOAD)
        tags, slots = self._locate(keys)
        ids = np.arange(self.size, need, dtype=np.int64)
        if self.size:
            self._place(tags, slots, ids)
        else:
            self._fill(tags, slots, ids)
        self._keys.append(keys)

    # -- queries and inserts ------------------------------------------------------------

    def _probe(self, slots: IntArray, tags: KeyArray) -> tuple[BoolArray, BoolArray, IntArray]:
        """One probing round from ``slots``: per candidate, whether it found its tag,
        whether it found a free slot (never both), and that slot (the last one looked
        at when neither). Small batches look at `_WINDOW` consecutive slots at once
        (fewer rounds, fewer numpy calls); large ones at one (less work per candidate).
        """
        if slots.size > PROBE_WINDOW_BELOW:
            content = self._tags.take(slots)
            return content == tags, content == EMPTY, slots
        mask = (1 << self._log) - 1
        window = slots[:, None] + _WINDOW
        window &= mask
        contents = self._tags.take(window)
        hits = contents == tags[:, None]
        stops = contents == EMPTY
        stops |= hits
        first = stops.argmax(axis=1)
        rows = np.arange(slots.size)
        hit = hits[rows, first]
        free = stops[rows, first] & ~hit
        return hit, free, window[rows, first]

    def _onward(self, at: IntArray, stopped: BoolArray, more: IntArray) -> IntArray:
        """Where the candidates ``more`` probe next: after the slot they stopped at (a
        claim lost, or a tag match that was another key), or after the window when they
        found neither their tag nor a free slot (``at`` is then its first slot)."""
        onward = at.take(more)
        if stopped.size > PROBE_WINDOW_BELOW:
            onward += 1
        else:
            onward += np.where(stopped.take(more), 1, _WINDOW.size)
        onward &= (1 << self._log) - 1
        return onward

    def find(self, cand: KeyArray) -> IntArray:
        """State number of each candidate key, ``-1`` if it is not stored."""
        cand = np.ascontiguousarray(cand)
        tags, slots = self._locate(cand)
        out = np.full(cand.shape[0], -1, dtype=np.int64)
        pos = np.arange(cand.shape[0], dtype=np.int64)
        while pos.size:
            hit, free, at = self._probe(slots, tags)
            stopped = hit | free
            where = np.flatnonzero(hit)
            if self.n_words > 1 and where.size:
                same = self._same_keys(cand, pos.take(where), at.take(where))
                hit[where[~same]] = False
                where = where[same]
            out[pos.take(where)] = self._index.take(at.take(where))
            more = np.flatnonzero(~(hit | free))
            slots = self._onward(at, stopped, more)
            pos, tags = pos.take(more), tags.take(more)
        return out

    def contains(self, cand: KeyArray) -> BoolArray:
        """Which candidate keys are stored."""
        found: BoolArray = self.find(cand) >= 0
        return found

    def add(self, cand: KeyArray, limit: int | None = None, want_ids: bool = False) -> Added:
        """Store the candidate keys not seen before; the batch may repeat keys.

        Args:
            cand: candidate keys, shape ``(m, n_words)``.
            limit: store at most this many new states (the budget left).
            want_ids: also return every candidate's state number.

        Returns:
            An `Added` record; the new states are numbered ``size_before, ...`` in
            the order of their first occurrence in ``cand``.
        """
        cand = np.ascontiguousarray(cand)
        m, start = cand.shape[0], self.size
        if limit is not None and m > limit:
            return self._add_capped(cand, limit)
        firsts: list[IntArray] = []
        ids: list[IntArray] = []
        done = 0
        while done < m:
            room = int(BATCH_LOAD * (1 << self._log)) - self.size
            if room < min(m - done, 1 << (self._log - 3)):
                self._resize(self._log + 1)
                continue
            first, piece_ids = self._claim(cand[done : done + room], want_ids)
            firsts.append(first + done)
            if piece_ids is not None:
                ids.append(piece_ids)
            done += min(room, m - done)
            self._reserve(self.size, MAX_LOAD)
        first = np.concatenate(firsts) if firsts else np.zeros(0, dtype=np.int64)
        all_ids = np.concatenate(ids) if want_ids and ids else None
        if want_ids and all_ids is None:
            all_ids = np.zeros(0, dtype=np.int64)
        return Added(first, start, False, all_ids)

    def _claim(self, cand: KeyArray, want_ids: bool) -> tuple[IntArray, IntArray | None]:
        """Insert a batch that fits in the table below `BATCH_LOAD`: the first
        occurrence of every new key becomes a new state. Returns the positions of those
        first occurrences (ascending) and, if asked, every candidate's state number."""
        m = cand.shape[0]
        tags, slots = self._locate(cand)
        index = self._index
        final = np.empty(m, dtype=np.int64) if want_ids else None
        pos = np.arange(m, dtype=np.int64)
        claimed: list[IntArray] = []
        while True:
            done, empty, at = self._probe(slots, tags)
            stopped = done | empty
            if self.n_words > 1 and done.any():
                hit = np.flatnonzero(done)
                done[hit] = self._same_keys(cand, pos.take(hit), at.take(hit))
            free = np.flatnonzero(empty)
            if free.size:
                done[free] = self._claim_free(cand, pos.take(free), at.take(free), tags, free)
                claimed.append(self._reps)
            if final is not None:
                settled = np.flatnonzero(done)
                final[pos.take(settled)] = at.take(settled)
            more = np.flatnonzero(~done)
            if not more.size:
                break
            slots = self._onward(at, stopped, more)
            pos, tags = pos.take(more), tags.take(more)
        new_slots = np.concatenate(claimed) if claimed else np.zeros(0, dtype=np.int64)
        reps = -1 - index.take(new_slots).astype(np.int64)
        is_first = np.zeros(m, dtype=bool)
        is_first[reps] = True
        first = np.flatnonzero(is_first)
        slot_of = np.empty(m, dtype=np.int64)
        slot_of[reps] = new_slots
        need = self.size + first.size
        index[slot_of.take(first)] = np.arange(self.size, need, dtype=np.int64)
        self._keys.append(cand.take(first, axis=0))
        return first, (index.take(final).astype(np.int64) if final is not None else None)

    def _claim_free(
        self, cand: KeyArray, fp: IntArray, fs: IntArray, tags: KeyArray, free: IntArray
    ) -> BoolArray:
        """Candidates ``fp`` (batch positions) found free slots ``fs``: write their tags,
        then among the candidates whose tag stayed, the first (smallest position) is
        recorded in the slot as the new key's representative, the others with the same
        key are its repeats. Returns which candidates are settled (representative or
        repeat); sets ``self._reps`` to the slots that got a representative."""
        ft = tags.take(free)
        table, index = self._tags, self._index
        # Several candidates may claim one slot: written in reverse, so the smallest
        # position normally writes last and wins (checked below, never assumed).
        table[fs[::-1]] = ft[::-1]
        ok = np.flatnonzero(table.take(fs) == ft)
        fs_ok, fp_ok = fs.take(ok), fp.take(ok)
        refs = -1 - fp_ok
        index[fs_ok[::-1]] = refs[::-1]
        rep = -1 - index.take(fs_ok).astype(np.int64)
        if (rep > fp_ok).any():  # numpy assigned repeats in another order
            np.maximum.at(index, fs_ok, refs.astype(self._index_type))
            rep = -1 - index.take(fs_ok).astype(np.int64)
        settled = np.zeros(fs.size, dtype=bool)
        if self.n_words == 1:
            settled[ok] = True
        else:  # equal tags, different keys: only repeats of the representative settle
            settled[ok] = ~_rows_differ(cand.take(fp_ok, axis=0), cand.take(rep, axis=0))
        self._reps = fs_ok.compress(rep == fp_ok)
        return settled

    def _add_capped(self, cand: KeyArray, limit: int) -> Added:
        """`add` when the budget may turn new keys away: look up first, keep the first
        ``limit`` new keys by first occurrence, place only those."""
        start = self.size
        ids = self.find(cand)
        unknown = np.flatnonzero(ids < 0)
        first_u, leader_u = first_occurrences(cand.take(unknown, axis=0))
        cut = first_u.size > limit
        kept = first_u[:limit]
        self._insert_distinct(cand.take(unknown.take(kept), axis=0))
        rank = np.searchsorted(first_u, leader_u)
        ids[unknown] = np.where(rank < limit, start + rank, -1)
        return Added(unknown.take(kept), start, cut, ids)
