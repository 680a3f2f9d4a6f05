"""Engine-level schedules: the vehicle and the network as one virtual-time event queue.

The product's claim is that a verified mission behaves as verified *whatever the network
does*. Testing that claim means trying very many orders and timings of replies, and
when one breaks the mission, shrinking it to the few delays that matter. Running the
controller, the link emulator and the simulator costs about half a second per pool
mission, and its timings come from seeds, which do not shrink. So this module runs the
`Engine` alone against a `Schedule`: for the i-th command sent, which of its replies
the vehicle gives and how long each leg takes. Replies reach `Engine.on_reply` in
delivery-time order; a schedule is a plain value, so hypothesis can draw it, shrink it
and print it (`runtime.schedule_strategies`).

The model of one command, all times in whole milliseconds so that ties are exact:

* the command leaves at the engine's step and reaches the vehicle ``up_ms`` later;
* the vehicle answers after its work time: the command's nominal duration from the
  mission's vehicle profile (``duration_s``; `Timing`) scaled by ``work_permille`` / 1000, or, for a
  ``timeout`` reply, the command's own ``time_out`` (the vehicle says timeout only when
  it has passed);
* the reply reaches the engine ``down_ms`` later;
* an `Outage` holds everything that would arrive while the link is down (either way)
  until it comes back, in the order it was due: the controller reconnects, re-sends the
  commands in flight and the vehicle re-sends the replies not yet acknowledged;
* replies due at the same instant go in ``rank`` order, then in the order sent.

Every reply of every command is eventually delivered, so each schedule is one in which
"the vehicle eventually replies". Reordering of concurrent replies comes from the
delays and ranks; nothing else is random, so a schedule replays exactly.
"""

from __future__ import annotations

import enum
import heapq
from collections.abc import Callable
from dataclasses import dataclass, field

from coral_lang.diagnostics import CoralError
from coral_lang.net import Command, Net
from coral_lang.profile import TIME_OUT, VehicleProfile, load_bundled_profile
from runtime.emulator import Outage
from runtime.engine import Engine, Firing, Outcome, SentCommand, StepResult, UnexpectedReply

__all__ = [
    "DEFAULT_WORK_S",
    "Delivery",
    "MessageFate",
    "Observer",
    "Outage",
    "Schedule",
    "ScheduleRun",
    "Timing",
    "run_schedule",
]

DEFAULT_WORK_S = 1.0
"""Work time of a command the vehicle profile does not describe (a PNML net, say)."""

TIMEOUT_REPLY = "timeout"


@dataclass(frozen=True)
class MessageFate:
    """What happens to one command and its reply (times in milliseconds).

    Attributes:
        reply: which of the command's reply kinds the vehicle gives, as an index taken
            modulo the number of kinds, so every integer is valid; 0 is the first kind
            (``ack``, ``done``: the expected answer).
        up_ms: delay from the controller to the vehicle.
        work_permille: the vehicle's work time in thousandths of the command's nominal
            duration (1000: nominal); ignored for a ``timeout`` reply.
        down_ms: delay from the vehicle back to the controller.
        rank: order among replies due at the same millisecond (lower first).
    """

    reply: int = 0
    up_ms: int = 0
    work_permille: int = 1000
    down_ms: int = 0
    rank: int = 0

    def __post_init__(self) -> None:
        for name in ("reply", "up_ms", "work_permille", "down_ms", "rank"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"MessageFate.{name} must be an int >= 0, got {value!r}")

    def describe(self) -> str:
        """The fields that differ from the default, e.g. ``reply 1, down 9501 ms``."""
        parts = []
        if self.reply:
            parts.append(f"reply {self.reply}")
        if self.up_ms:
            parts.append(f"up {self.up_ms} ms")
        if self.work_permille != 1000:
            parts.append(f"work x{self.work_permille / 1000:g}")
        if self.down_ms:
            parts.append(f"down {self.down_ms} ms")
        if self.rank:
            parts.append(f"rank {self.rank}")
        return ", ".join(parts) or "nominal"


@dataclass(frozen=True)
class Schedule:
    """The fate of every command, by the order it was sent, and the link's outages.

    Attributes:
        messages: ``messages[i]`` is the fate of the (i+1)-th command sent (command id
            i + 1); commands beyond the list get ``default``.
        outages: when the link is down, in the schedule's milliseconds.
        default: the fate of the commands ``messages`` does not cover.
    """

    messages: tuple[MessageFate, ...] = ()
    outages: tuple[Outage[int], ...] = ()
    default: MessageFate = field(default_factory=MessageFate)

    def fate(self, index: int) -> MessageFate:
        """The fate of the command sent ``index``-th (0-based)."""
        return self.messages[index] if index < len(self.messages) else self.default

    def arrival(self, t_ms: int) -> int:
        """When something due at ``t_ms`` arrives: after every outage covering it."""
        moved = True
        while moved:
            moved = False
            for outage in self.outages:
                if outage.covers(t_ms):
                    t_ms = outage.end
                    moved = True
        return t_ms

    def describe(self) -> str:
        """One line per command whose fate is not nominal, then the outages."""
        lines = [
            f"command #{i + 1}: {fate.describe()}"
            for i, fate in enumerate(self.messages)
            if fate != MessageFate()
        ]
        lines += [f"outage from {o.start} ms for {o.length} ms" for o in self.outages]
        return "\n".join(lines) or "every command nominal, no outage"


class _Bundled(enum.Enum):
    """The default of `Timing`'s ``profile``: look the bundled profile up by name."""

    BY_VEHICLE_NAME = "bundled"


class Timing:
    """How long the vehicle works on each command, from the mission's vehicle profile.

    The nominal duration is the profile's ``duration_s``; a ``timeout`` reply takes the
    command's ``time_out`` parameter. Pass the profile the mission was compiled against
    (``Timing(mission.net, profile=mission.profile)``, `coral_lang.mission.Mission`):
    that works for any vehicle, including one whose profile was given with
    ``--profile``. ``profile=None`` (a net without a profile, such as a PNML model)
    gives every command `DEFAULT_WORK_S`.

    Without ``profile``, the bundled profile of the net's vehicle is looked up by name,
    as before profiles travelled with the mission; a vehicle without a bundled profile
    then takes the default for every command.

    Raises:
        ValueError: ``profile`` is for another vehicle than the net's.
    """

    def __init__(
        self,
        net: Net,
        default_s: float = DEFAULT_WORK_S,
        *,
        profile: VehicleProfile | _Bundled | None = _Bundled.BY_VEHICLE_NAME,
    ) -> None:
        self._nominal: dict[str, float] = {}
        self._default = default_s
        if isinstance(profile, _Bundled):
            profile = _bundled(net)
        if profile is None:
            return
        if net.vehicle is not None and profile.name != net.vehicle:
            raise ValueError(
                f"profile {profile.name} ({profile.file}) is not for the net's vehicle "
                f"{net.vehicle}"
            )
        for spec in profile.commands:
            self._nominal[spec.name] = spec.duration_s

    def nominal_s(self, command: Command) -> float:
        """The profile's nominal duration of ``command``."""
        return self._nominal.get(command.name, self._default)

    def work_ms(self, command: Command, kind: str, permille: int) -> int:
        """The vehicle's work time for ``command`` answered with ``kind``."""
        if kind == TIMEOUT_REPLY:
            limit = dict(command.params).get(TIME_OUT)
            if isinstance(limit, int | float):
                return round(float(limit) * 1000)
        return round(self.nominal_s(command) * permille)


def _bundled(net: Net) -> VehicleProfile | None:
    """The bundled profile of ``net``'s vehicle, or None (no vehicle, or not bundled)."""
    if net.vehicle is None:
        return None
    try:
        return load_bundled_profile(net.vehicle)
    except CoralError:
        return None


@dataclass(frozen=True)
class Delivery:
    """One reply handed to the engine."""

    time_ms: int
    command_id: int
    transition: str
    kind: str


Observer = Callable[[Engine, StepResult, Delivery | None], None]
"""Called after `Engine.start` (delivery None) and after each `Engine.on_reply`."""


@dataclass
class ScheduleRun:
    """What one schedule did to the engine.

    Attributes:
        outcome: FINAL or DEADLOCK (RUNNING only if ``max_deliveries`` stopped it).
        marking: the marking at the end.
        time_ms: the schedule time of the last delivery.
        sent: every command sent, in order.
        deliveries: every reply delivered, in order.
        firings: every transition fired, in order (replies included).
        unexpected: replies the engine refused (none, unless the engine is wrong).
    """

    outcome: Outcome
    marking: dict[str, int]
    time_ms: int
    sent: list[SentCommand]
    deliveries: list[Delivery]
    firings: list[Firing]
    unexpected: list[UnexpectedReply]

    @property
    def trace(self) -> list[str]:
        """The names of the transitions fired, in order."""
        return [f.transition for f in self.firings]


def run_schedule(
    engine: Engine,
    schedule: Schedule,
    timing: Timing,
    *,
    observe: Observer | None = None,
    max_deliveries: int = 100_000,
) -> ScheduleRun:
    """Start ``engine`` and feed it the replies ``schedule`` decides, until none is left.

    Args:
        engine: a fresh engine (not started).
        schedule: the fate of each command and the outages.
        timing: the vehicle's work times.
        observe: called after every step, e.g. to check a property at each marking.
        max_deliveries: stop after this many replies (a mission that loops forever).

    Raises:
        runtime.engine.EngineError: the engine refused to go on (started twice, a cycle
            of engine transitions that never waits for the vehicle).
    """
    queue: list[tuple[int, int, int, int, str, str]] = []
    sent: list[SentCommand] = []
    deliveries: list[Delivery] = []
    firings: list[Firing] = []
    unexpected: list[UnexpectedReply] = []

    def post(step: StepResult, now_ms: int) -> None:
        firings.extend(step.firings)
        if step.unexpected is not None:
            unexpected.append(step.unexpected)
        for command in step.commands:
            fate = schedule.fate(command.command_id - 1)
            kinds = command.command.replies
            kind = kinds[fate.reply % len(kinds)] if kinds else ""
            at_vehicle = schedule.arrival(now_ms + fate.up_ms)
            answered = at_vehicle + timing.work_ms(command.command, kind, fate.work_permille)
            due = answered + fate.down_ms
            arrives = schedule.arrival(due)
            heapq.heappush(
                queue,
                (arrives, due, fate.rank, command.command_id, command.transition, kind),
            )
            sent.append(command)

    now_ms = 0
    first = engine.start(0.0)
    post(first, now_ms)
    if observe is not None:
        observe(engine, first, None)
    while queue and len(deliveries) < max_deliveries:
        arrives, _, _, command_id, transition, kind = heapq.heappop(queue)
        now_ms = arrives
        delivery = Delivery(arrives, command_id, transition, kind)
        deliveries.append(delivery)
        step = engine.on_reply(command_id, kind, arrives / 1000.0)
        post(step, now_ms)
        if observe is not None:
            observe(engine, step, delivery)
    return ScheduleRun(
        outcome=engine.outcome(),
        marking=engine.marking_dict(),
        time_ms=now_ms,
        sent=sent,
        deliveries=deliveries,
        firings=firings,
        unexpected=unexpected,
    )
