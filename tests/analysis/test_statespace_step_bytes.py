"""The explorer's steps stay within `STEP_BYTES` of successor keys: a block whose edges
would pass it is split, and a narrow layer whose first level would is expanded by
blocks instead; neither changes what is found."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings

import analysis.statespace as statespace
from analysis.encoding import CompactNet
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net
from tests.analysis.strategies import small_nets
from tests.analysis.wide_nets import count_rings


def _summary(space: StateSpace) -> tuple[object, ...]:
    return (
        space.states,
        space.edges,
        space.complete,
        space.place_bounds.tolist(),
        len(space.deadlocks),
        space.fired_transitions.tolist(),
    )


@settings(max_examples=40, deadline=None)
@given(small_nets(max_places=5, max_transitions=6))
def test_splitting_every_block_finds_the_same_space(net: Net) -> None:
    whole = explore(net, max_states=400)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(statespace, "STEP_BYTES", 1)  # every block and narrow layer split
        split = explore(net, max_states=400)
    assert (split.states, split.complete) == (whole.states, whole.complete)
    if whole.complete:  # (a search cut by its budget counts the edges it expanded so far)
        assert _summary(split) == _summary(whole)
        assert sorted(map(tuple, split.keys.tolist())) == sorted(map(tuple, whole.keys.tolist()))


def test_a_wide_layer_is_split_into_steps_of_bounded_size(monkeypatch: pytest.MonkeyPatch) -> None:
    # 300 rings of 3 tokens: 900 edges per marking, keys of 100+ words; the first wide
    # layer enables 270,000 edges (over 800 MB of keys in one step before the split)
    cn = CompactNet.from_net(count_rings(300, 20, 3))
    calls: list[int] = []
    split = statespace._Explorer.split_step

    def counted(self: statespace._Explorer, *args: object) -> object:
        calls.append(1)
        return split(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(statespace._Explorer, "split_step", counted)
    tracemalloc.start()
    try:
        space = explore(cn, max_states=5_000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert space.states == 5_000
    assert calls
    assert peak < 8 * statespace.STEP_BYTES
    assert int(np.asarray(space.place_bounds).max()) <= 3
