"""What the two timed explorers share: the net's arcs as indices, and witness steps.

`analysis.timed.semantics` (one global clock) and `analysis.timed.eventtime` (event
times) read the same net the same way, and both let the explorer carry a point of a
successor's zone back to its predecessor (`SemanticsBase.raw_step`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Generic, Protocol, TypeVar

from analysis.timed.model import TimedModel
from analysis.timed.zones import Zone, ZoneLike

__all__ = ["SemanticsBase", "watched_start"]


class _Holding(Protocol):
    @property
    def resource(self) -> str: ...
    @property
    def var(self) -> int: ...
    @property
    def task(self) -> bool: ...


def watched_start(
    holders: Sequence[_Holding], resources: Sequence[str], arrival: int
) -> tuple[tuple[int, ...], int]:
    """For a query arriving at ``arrival`` (a variable) on ``resources``: the holders it
    watches (their variables) and when its tracking starts: the arrival of the one task
    holding all of them, else its own arrival."""
    held = {h.resource: h for h in holders}
    watch = tuple(sorted({held[r].var for r in resources if r in held}))
    owners = {(held[r].var, held[r].task) for r in resources if r in held}
    if len(owners) == 1 and all(r in held for r in resources):
        var, task = next(iter(owners))
        if task:
            return watch, var
    return watch, arrival


class _Labelled(Protocol):
    @property
    def label(self) -> str: ...


S = TypeVar("S")
T = TypeVar("T", bound=_Labelled)


class SemanticsBase(ABC, Generic[S, T]):
    """The net's arcs by index (``_inputs``, ``_outputs``: per transition, (place,
    weight) pairs; ``_consumers``, ``_producers``: per place, the engine transitions
    taking from or putting into it) and the zone every run starts from.

    Subclasses give `initial` and `successors`, and store, for each successor they
    make, its zone before projection and the variables it keeps in
    ``last_raw_by_label``.
    """

    def __init__(self, model: TimedModel, initial_zone: ZoneLike | None) -> None:
        self.model = model
        self.keep = initial_zone is not None
        self.last_raw: tuple[ZoneLike, list[int]] | None = None
        """The last successor's zone before projection, and which of its variables
        the projected state keeps (in order)."""
        self.last_raw_by_label: dict[str, tuple[ZoneLike, list[int]] | None] = {}
        self._initial_zone: ZoneLike = Zone.initial() if initial_zone is None else initial_zone
        net = model.net
        self._inputs = [
            tuple((net.place_index(p), w) for p, w in t.inputs) for t in net.transitions
        ]
        self._outputs = [
            tuple((net.place_index(p), w) for p, w in t.outputs) for t in net.transitions
        ]
        self._engine = model.engine
        consumers: dict[int, list[int]] = {}
        producers: dict[int, list[int]] = {}
        for t in self._engine:
            for p, _ in self._inputs[t]:
                consumers.setdefault(p, []).append(t)
            for p, _ in self._outputs[t]:
                producers.setdefault(p, []).append(t)
        self._consumers = consumers
        self._producers = producers
        self._prioritised = len({net.transitions[t].priority for t in self._engine}) > 1

    @abstractmethod
    def initial(self) -> Sequence[T]:
        """The states the mission can rest in at time 0."""

    @abstractmethod
    def successors(self, state: S) -> Sequence[T]:
        """The successors of ``state``."""

    def raw_step(self, state: S, label: str) -> tuple[Zone, list[int]] | None:
        """The zone of the step ``label`` from ``state`` before projection (the
        variables of ``state`` first, then the step's own) and the variables the
        successor keeps, in its order; None if there is no such step. Used to carry a
        point of a successor back to its predecessor (witness runs)."""
        steps = self.initial() if label.startswith("start") else self.successors(state)
        for successor in steps:
            raw = self.last_raw_by_label.get(label)
            if successor.label == label and raw is not None:
                zone, order = raw
                assert isinstance(zone, Zone)
                return zone, order
        return None
