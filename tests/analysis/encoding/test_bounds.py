"""Place bounds from P-invariants, and the field widths they cap."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.encoding import UNBOUNDED, CompactNet, Layout, bounds, invariant_place_bounds
from analysis.statespace import explore
from coral_lang.net import Net
from tests.analysis.nets import make_net
from tests.analysis.strategies import small_nets


def _ring(places: int, tokens: int) -> Net:
    """Tokens moving round a ring of places, one at a time: every place is bounded by
    ``tokens`` (one invariant, the ring's sum)."""
    names = [f"p{i}" for i in range(places)]
    return make_net(
        "ring",
        {name: tokens if i == 0 else 0 for i, name in enumerate(names)},
        {f"t{i}": ({names[i]: 1}, {names[(i + 1) % places]: 1}) for i in range(places)},
    )


def test_a_ring_is_bounded_by_its_tokens() -> None:
    cn = CompactNet.from_net(_ring(4, 5))
    assert invariant_place_bounds(cn).tolist() == [5, 5, 5, 5]


def test_a_growing_place_has_no_bound() -> None:
    net = make_net("grow", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})
    bounds = invariant_place_bounds(CompactNet.from_net(net))
    assert bounds.tolist() == [1, UNBOUNDED]


def test_weights_divide_the_invariant() -> None:
    # 2 tokens of a make one of b: 2*b + a = 4 always, so b <= 2 and a <= 4
    net = make_net(
        "pairs", {"a": 4, "b": 0}, {"join": ({"a": 2}, {"b": 1}), "split": ({"b": 1}, {"a": 2})}
    )
    assert invariant_place_bounds(CompactNet.from_net(net)).tolist() == [4, 2]


@settings(max_examples=60, deadline=None)
@given(small_nets(max_places=5, max_transitions=5))
def test_bounds_hold_in_every_reachable_marking(net: Net) -> None:
    cn = CompactNet.from_net(net)
    bounds = invariant_place_bounds(cn)
    space = explore(cn, max_states=2_000)
    bounded = bounds != UNBOUNDED
    assert (space.place_bounds[bounded] <= bounds[bounded]).all()


def test_bounded_fields_start_at_their_cap_and_never_widen_past_it() -> None:
    cn = CompactNet.from_net(_ring(20, 5))  # 20 places of 3 bits: one word
    layout = Layout.initial_guess(cn, [], invariant_place_bounds(cn))
    assert layout.bits == (3,) * 20
    assert layout.caps == (3,) * 20
    assert layout.widened({0: 5}, growing=list(range(20))).bits == (3,) * 20
    space = explore(cn, max_states=None)
    assert space.layout.n_words == 1
    assert space.states == math.comb(5 + 20 - 1, 5)  # 5 tokens over 20 places


def test_without_bounds_widening_is_unchanged() -> None:
    cn = CompactNet.from_net(_ring(3, 5))
    layout = Layout.initial_guess(cn, [])
    assert layout.caps == (60,) * 3
    assert layout.widened({0: 5}).bits[int(layout.field_of[0])] == 4  # 3 bits + headroom


@given(st.lists(st.integers(0, 63), min_size=30, max_size=30))  # what 6 bits hold
def test_tight_widths_never_take_more_words_and_hold_the_values(reached: list[int]) -> None:
    layout = Layout.for_bits([6] * 30)  # 180 bits: 3 words
    values = np.asarray(reached, dtype=np.int64)
    grown = layout.widened({0: 1000}, reached=values)
    assert grown.n_words <= layout.widened({0: 1000}).n_words
    assert all(grown.bits[f] >= int(v).bit_length() for f, v in enumerate(reached))
    assert grown.bits[0] >= 11  # 1000 and headroom


def test_tight_widths_save_the_word_generous_ones_add() -> None:
    layout = Layout.for_bits([6] * 30)
    assert layout.n_words == 3
    assert layout.widened({0: 1000}).n_words == 4  # 11 + 29 * 6 bits
    small = np.full(30, 3, dtype=np.int64)  # 2 bits each, 3 with headroom
    tight = layout.widened({0: 1000}, reached=small)
    assert tight.n_words == 2
    assert tight.bits[1:] == (3,) * 29


def test_the_search_runs_once_per_net(monkeypatch: pytest.MonkeyPatch) -> None:
    cn = CompactNet.from_net(_ring(3, 2))
    first = invariant_place_bounds(cn)
    monkeypatch.setattr(bounds, "p_invariants", None)  # a second search would fail
    again = invariant_place_bounds(cn)
    assert again.tolist() == first.tolist() == [2, 2, 2]
    again[0] = 99  # callers get their own copy
    assert invariant_place_bounds(cn).tolist() == [2, 2, 2]
