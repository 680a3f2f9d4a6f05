"""Final markings in projected form (`Net.final_columns`, `Net.final_patterns`,
`Net.final_test`): the same markings as the expanded `Net.final_markings`, without
costing 2**k rows for k operator inputs."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.net import (
    MAX_INPUTS,
    FinalMarking,
    Net,
    NetError,
    Place,
    PlaceKind,
)


def _net(n_plain: int, n_inputs: int, finals: list[dict[str, int]], bounded: bool) -> Net:
    """Plain places ``p0..``, one armed place per input, and (when ``bounded``) a
    capacity-2 place ``b`` with its complement, so finals also fix complement values."""
    places = [Place(f"p{i}") for i in range(n_plain)]
    places += [Place(f"i{k}.armed", 1, PlaceKind.ARMED, armed_of=f"i{k}") for k in range(n_inputs)]
    if bounded:
        places += [
            Place("b", capacity=2),
            Place("b.free", 2, PlaceKind.COMPLEMENT, complement_of="b"),
        ]
    return Net(
        "finals",
        tuple(places),
        (),
        tuple(FinalMarking(tuple(sorted(f.items()))) for f in finals),
    )


@st.composite
def nets_and_markings(draw: st.DrawFn) -> tuple[Net, list[tuple[int, ...]]]:
    """A net with 0 to 3 inputs and 0 to 3 finals (duplicates allowed), and markings
    near its finals: each final with some places nudged to 0..2 (armed ones too, so
    an armed place holding 2 is covered)."""
    n_plain = draw(st.integers(1, 3))
    bounded = draw(st.booleans())
    names = [f"p{i}" for i in range(n_plain)] + (["b"] if bounded else [])
    finals = draw(
        st.lists(st.dictionaries(st.sampled_from(names), st.integers(0, 2), max_size=2), max_size=3)
    )
    net = _net(n_plain, draw(st.integers(0, 3)), finals, bounded)
    width = len(net.places)
    seeds = net.final_markings() or [net.initial_marking()]
    markings = []
    for _ in range(draw(st.integers(1, 12))):
        values = list(draw(st.sampled_from(seeds)))
        for i in draw(st.lists(st.integers(0, width - 1), max_size=2)):
            values[i] = draw(st.integers(0, 2))
        markings.append(tuple(values))
    return net, markings


@pytest.mark.slow
@given(nets_and_markings())
@settings(max_examples=200, deadline=None)
def test_projected_finals_accept_exactly_the_expanded_final_markings(
    case: tuple[Net, list[tuple[int, ...]]],
) -> None:
    net, markings = case
    expanded = set(net.final_markings())
    test = net.final_test()
    for marking in [*markings, *expanded]:
        assert net.is_final(marking) == (marking in expanded), marking
        assert test.matches(marking) == (marking in expanded), marking


def test_every_combination_of_armed_values_is_final_and_2_is_not() -> None:
    net = _net(2, 3, [{"p0": 1}], bounded=False)
    for given_ in itertools.product((0, 1), repeat=3):
        assert net.is_final((1, 0, *given_))
    assert not net.is_final((1, 0, 1, 2, 0))
    assert not net.is_final((1, 1, 1, 1, 1))
    assert not net.is_final((1, 0, 1))  # wrong length: not a marking of this net


def test_eight_inputs_cost_one_pattern_per_declared_final() -> None:
    """The memory regression: patterns do not grow with the number of inputs."""
    net = _net(4, MAX_INPUTS, [{"p0": 1}, {"p1": 1}, {"p0": 1}], bounded=True)
    assert len(net.final_columns()) == len(net.places) - MAX_INPUTS
    assert net.armed_columns() == tuple(range(4, 4 + MAX_INPUTS))
    # Two distinct finals (the third repeats the first), each over the 6 other places.
    assert net.final_patterns() == [(1, 0, 0, 0, 0, 2), (0, 1, 0, 0, 0, 2)]
    test = net.final_test()
    assert len(test.patterns) == 2 and test.columns == net.final_columns()
    # The expansion is still there for callers that need it, and is what we avoid.
    assert len(net.final_markings()) == 3 * 2**MAX_INPUTS


def test_no_final_means_no_pattern_and_nothing_final() -> None:
    net = _net(2, 2, [], bounded=False)
    assert net.final_patterns() == []
    assert not net.is_final(net.initial_marking())


def test_a_net_without_places_has_the_empty_marking_final_when_it_declares_one() -> None:
    net = Net("empty", (), (), (FinalMarking(()),))
    assert net.final_columns() == () and net.final_patterns() == [()]
    assert net.is_final(())


def test_too_many_armed_places_are_refused_with_a_clear_message() -> None:
    net = _net(1, MAX_INPUTS + 1, [{"p0": 1}], bounded=False)
    message = f"{MAX_INPUTS + 1} operator inputs; at most {MAX_INPUTS} are supported"
    for call in (net.final_patterns, net.final_markings, net.final_test):
        with pytest.raises(NetError, match=message):
            call()
