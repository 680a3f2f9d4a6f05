"""Helpers for the tests of the explicit explorer (`analysis.statespace`): what a search
found, compared whole, and how many edges it fired."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any
from unittest import mock

import analysis.statespace as statespace
from analysis.statespace import StateSpace


def fingerprint(space: StateSpace) -> tuple[object, ...]:
    """Everything a search numbers and records: two searches with equal fingerprints
    found the same states in the same order, layer by layer."""
    return (
        space.states,
        space.edges,
        space.keys.tolist(),
        space.deadlocks.tolist(),
        space.place_bounds.tolist(),
        space.fired_transitions.tolist(),
        space.layer_starts.tolist(),
    )


@contextmanager
def counting_fired() -> Iterator[list[int]]:
    """While active, counts the edges the explorer fires (offers to its store) in the
    one item of the list it yields."""
    fired = [0]
    insert = statespace._Explorer.insert

    def counting(self: Any, cols: Any, base: int, edges: Any, *args: Any, **kw: Any) -> Any:
        fired[0] += edges[0].size
        return insert(self, cols, base, edges, *args, **kw)

    with mock.patch.object(statespace._Explorer, "insert", counting):
        yield fired
