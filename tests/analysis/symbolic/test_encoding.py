"""The static variable order: a permutation of the places, never worse (by the sum of
transition spans) than the PNML order or the greedy locality order."""

from __future__ import annotations

import pytest

from analysis.symbolic.encoding import (
    force_order,
    initial_bits,
    invariant_bounds,
    locality_order,
    place_order,
    span_sum,
)
from coral_lang.pnml.read import read_pnml
from tests.conftest import CONFORMANCE


@pytest.mark.parametrize(
    "model", ["Kanban-PT-00005", "Peterson-PT-2", "Dekker-PT-010", "Philosophers-PT-000010"]
)
def test_place_order_is_the_smaller_span_of_its_candidates(model: str) -> None:
    net = read_pnml(CONFORMANCE / "pnml" / f"{model}.pnml")
    order = place_order(net)
    assert sorted(order) == list(range(len(net.places)))
    cost = span_sum(net, order)
    assert cost <= span_sum(net, locality_order(net))
    assert cost <= span_sum(net, list(range(len(net.places))))


def test_span_sum_counts_each_transition_band() -> None:
    net = read_pnml(CONFORMANCE / "pnml" / "Philosophers-PT-000005.pnml")
    identity = list(range(len(net.places)))
    reverse = identity[::-1]
    # reversing the order keeps every band's width
    assert span_sum(net, identity) == span_sum(net, reverse)
    assert span_sum(net, identity) > 0


def test_invariant_bounds_size_the_counters() -> None:
    """Peterson-PT-2 is covered by P-invariants: every place is safe, one bit each,
    where the arcs alone would ask as much (and an unproven place starts from them)."""
    net = read_pnml(CONFORMANCE / "pnml" / "Peterson-PT-2.pnml")
    bounds = invariant_bounds(net, 5.0)
    assert bounds == [1] * len(net.places)
    assert initial_bits(net, bounds=bounds) == [1] * len(net.places)
    heavy = read_pnml(CONFORMANCE / "pnml" / "SatelliteMemory-PT-X00100Y0003.pnml")
    proven = invariant_bounds(heavy, 5.0)
    assert all(b is not None for b in proven) and max(b or 0 for b in proven) == 100
    bits = initial_bits(heavy, bounds=proven)
    assert bits == [max(1, b or 0).bit_length() for b in proven]
    assert initial_bits(heavy, bounds=[None] * len(heavy.places)) == initial_bits(heavy)


@pytest.mark.parametrize("model", ["Dekker-PT-010", "Referendum-PT-0010", "Peterson-PT-2"])
def test_force_order_never_widens_the_bands_it_starts_from(model: str) -> None:
    """FORCE keeps the best order it sees: a permutation no worse than its start, and
    on these nets (PNML order lists all flags, then all control places) strictly better."""
    net = read_pnml(CONFORMANCE / "pnml" / f"{model}.pnml")
    start = list(range(len(net.places)))
    order = force_order(net, start)
    assert sorted(order) == start
    assert span_sum(net, order) < span_sum(net, start)
