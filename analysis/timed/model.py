"""The timed model of a mission: its net, plus how long each step may take.

Built once from the `Net`, the vehicle profiles it was compiled against and the link
bounds; the explorer (`analysis.timed.semantics`) reads nothing else. Every time is an
integer number of microseconds, and every interval is rounded *outwards* (lower ends
down, upper ends up), so the model has at least the runs of the real system: a bound
proven on it holds for the real one. A ``time_out`` is rounded to the nearest
microsecond (it is an exact parameter, not an estimate).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from coral_lang import units
from coral_lang.net import AssertKind, Net, TransitionKind
from coral_lang.profile import TIME_OUT, CommandKind, VehicleProfile
from coral_lang.timing import LinkBounds

__all__ = [
    "US",
    "CommandModel",
    "Deadline",
    "ModelError",
    "TimedModel",
    "build_model",
    "seconds",
]

US = 1_000_000
"""Microseconds in a second: the model's unit of time."""


def _low(x: float) -> int:
    return math.floor(x * US)


def _high(x: float) -> int:
    return math.ceil(x * US)


def seconds(us: int) -> float:
    """Model time back to seconds."""
    return us / US


class ModelError(Exception):
    """The net cannot be given a timed model; the message says why (for a report)."""


@dataclass(frozen=True)
class CommandModel:
    """One COMMAND transition with what the vehicle may do with its command.

    Attributes:
        transition: index of the COMMAND transition in the net.
        name: its name.
        command: the command's name (``DEPTH?``).
        kind: the profile's kind of the command.
        resources: the vehicle resources it drives (or watches, for a query).
        replies: reply kind -> index of the net's REPLY transition for it.
        work: reply kind -> [min, max] work time, us (not for a watched query's
            ``timeout``: its time is the time-out).
        time_out: a watched query's time-out, us (converted from its parameter's
            unit); None for every other command.
        latency: longest delay between a reply falling due and its sending, us.
        tracked: a watched query's reply when its tracking completes: ``done``, or its
            first reply kind when it has no ``done`` (as the vehicles do).
    """

    transition: int
    name: str
    command: str
    kind: CommandKind
    resources: tuple[str, ...]
    replies: tuple[tuple[str, int], ...]
    work: tuple[tuple[str, int, int], ...]
    time_out: int | None
    latency: int
    tracked: str = "done"

    @property
    def watched(self) -> bool:
        """A query with a time-out: its ``done`` waits for the task it watches."""
        return self.time_out is not None

    def interval(self, kind: str) -> tuple[int, int]:
        """[min, max] work time of a ``kind`` reply, us."""
        for name, low, high in self.work:
            if name == kind:
                return low, high
        raise KeyError(kind)

    def reply_transition(self, kind: str) -> int | None:
        """The REPLY transition for ``kind``, if the net maps that reply."""
        for name, index in self.replies:
            if name == kind:
                return index
        return None

    @property
    def takes_resources(self) -> bool:
        """Tasks and actions take their resources on arrival; queries only watch."""
        return self.kind != "query" and bool(self.resources)


@dataclass(frozen=True)
class Deadline:
    """An ``assert within`` of the mission: ``places`` marked by ``deadline`` us."""

    index: int
    places: tuple[tuple[int, int], ...]
    named: dict[str, int]
    deadline: int

    def reached(self, marking: Sequence[int]) -> bool:
        """Whether ``marking`` has at least the asserted tokens."""
        return all(marking[p] >= w for p, w in self.places)


@dataclass(frozen=True)
class TimedModel:
    """Everything the timed explorer needs.

    Attributes:
        net: the mission.
        link: the link bounds, as given.
        link_low: shortest one-way delay, us.
        link_high: longest one-way delay, us.
        commands: one per COMMAND transition, by transition index.
        engine: indices of the transitions the engine fires (plain and command).
        deadlines: the mission's ``within`` assertions.
    """

    net: Net
    link: LinkBounds
    link_low: int
    link_high: int
    commands: dict[int, CommandModel]
    engine: tuple[int, ...]
    deadlines: tuple[Deadline, ...]


def build_model(net: Net, profiles: Sequence[VehicleProfile], link: LinkBounds) -> TimedModel:
    """The timed model of ``net``.

    Raises:
        ModelError: operator inputs (not modelled), a command with no profile, or a
            reply transition the model cannot place.
    """
    if any(t.kind is TransitionKind.INPUT for t in net.transitions):
        names = ", ".join(net.inputs)
        raise ModelError(
            f"the mission takes operator inputs ({names}): when an operator acts is not "
            "bounded, so timed analysis does not model it"
        )
    by_vehicle = {p.name: p for p in profiles}
    replies: dict[str, list[tuple[str, int]]] = {}
    for index, tr in enumerate(net.transitions):
        if tr.kind is TransitionKind.REPLY:
            if tr.reply_to is None or tr.reply is None:
                raise ModelError(f"reply transition {tr.name} names no command or reply kind")
            replies.setdefault(tr.reply_to, []).append((tr.reply, index))
    commands: dict[int, CommandModel] = {}
    for index, tr in enumerate(net.transitions):
        if tr.kind is not TransitionKind.COMMAND:
            continue
        command = tr.command
        if command is None:
            raise ModelError(f"command transition {tr.name} carries no command")
        profile = by_vehicle.get(command.system)
        if profile is None and len(profiles) == 1:
            profile = profiles[0]
        spec = None if profile is None else profile.command(command.name)
        if profile is None or spec is None:
            raise ModelError(
                f"{tr.name}: no vehicle profile describes {command.system}({command.name}): "
                "timed analysis needs the profile the mission was compiled against"
            )
        mapped = tuple(replies.get(tr.name, ()))
        params = dict(command.params)
        raw_time_out = params.get(TIME_OUT)
        watched = (
            spec.kind == "query"
            and isinstance(raw_time_out, int | float)
            and "timeout" in spec.replies
        )
        time_out = None
        if watched and isinstance(raw_time_out, int | float):
            unit = spec.param(TIME_OUT)
            seconds = float(raw_time_out)
            if unit is not None and unit.unit is not None:
                seconds = units.convert(seconds, unit.unit, "s")
            time_out = round(seconds * US)
        tracked = "done" if "done" in spec.replies else spec.replies[0]
        tolerance = profile.timing.tolerance
        work = []
        for kind, _ in mapped:
            if watched and kind == "timeout":
                continue
            low, high = spec.work_interval(kind, tolerance)
            work.append((kind, max(0, _low(low)), max(0, _high(high))))
        commands[index] = CommandModel(
            transition=index,
            name=tr.name,
            command=command.name,
            kind=spec.kind,
            resources=tuple(spec.resources),
            replies=mapped,
            work=tuple(work),
            time_out=time_out,
            latency=_high(profile.timing.reply_latency_s),
            tracked=tracked,
        )
    engine = tuple(
        i
        for i, t in enumerate(net.transitions)
        if t.kind in (TransitionKind.PLAIN, TransitionKind.COMMAND)
    )
    deadlines = []
    for number, assertion in enumerate(net.assertions, start=1):
        if assertion.kind is not AssertKind.WITHIN or assertion.deadline_s is None:
            continue
        deadlines.append(
            Deadline(
                index=number,
                places=tuple((net.place_index(p), w) for p, w in assertion.places),
                named=dict(assertion.places),
                deadline=round(assertion.deadline_s * US),
            )
        )
    return TimedModel(
        net=net,
        link=link,
        link_low=_low(link.min_delay_s),
        link_high=_high(link.max_delay_s),
        commands=commands,
        engine=engine,
        deadlines=tuple(deadlines),
    )
