"""A vehicle that fails on purpose: `FaultInjector` applies a fault plan to any model.

The mission's error and timeout branches are verified, but a healthy simulator rarely
takes them, so a fuzz campaign never rehearses them. `FaultInjector` wraps any
`VehicleModel` (ROMEO's physics simulator, the generic one, an adapter to hardware in a
test rig) and, where the `runtime.faultplan.FaultPlan` says so, answers a command itself
with the forced reply kind instead of passing it on. The wrapped vehicle never hears of
a forced command: a forced ``DEPTH=error`` leaves the vehicle where it was, as a real
refusal would, and the mission must cope with what that leaves behind.

When a forced reply comes (profile figures, so every simulator agrees):

* a task (kind ``task``): at once, from `command`, as a task's ``ack`` or ``error`` does;
* ``timeout``: when the command's ``time_out`` parameter says (a query's), else after its
  nominal ``duration_s``; this is checked before the task rule, so a task that can time
  out does so late, not at once;
* any other kind, for a query or an action: after the command's nominal ``duration_s``.

Forced replies that fall due later come out of `advance_to` merged in time order with
the wrapped vehicle's own replies (at equal times the vehicle's come first). Their
detail names the rule: ``forced by fault plan rule 'DEPTH?=timeout'``. Everything else
(the clock, the watchdog, telemetry) is the wrapped vehicle's; a forced command still
counts as a word from the controller for its watchdog. A make-safe request goes to the
wrapped vehicle.

Random draws (rates, ``any``) come from a generator seeded by the injector's seed, the
command's name and its use number, so whether the third DIVE is forced does not depend
on what other commands came before it: the same seed forces the same uses in every run,
however the link reorders the commands of concurrent branches.

This module imports only the vehicle contract, `runtime.faultplan` and ``coral_lang``.
"""

from __future__ import annotations

import heapq
import math
import random
from collections import Counter
from dataclasses import dataclass

from coral_lang.profile import TIME_OUT, CommandSpec, VehicleProfile
from runtime.faultplan import FaultPlan, FaultRule
from runtime.vehicle.model import Params, Reply, TelemetryRecord, VehicleModel

__all__ = ["FaultInjector", "InjectedFault", "forced_delay"]


@dataclass(frozen=True)
class InjectedFault:
    """One forced reply, for reports.

    Attributes:
        command_id: the vehicle-side id of the command.
        command: its name.
        occurrence: which use of that command it was (1-based).
        kind: the reply kind forced.
        rule: the text of the rule that forced it.
        received: vehicle time the command arrived, s.
        time: vehicle time of the forced reply, s.
    """

    command_id: int
    command: str
    occurrence: int
    kind: str
    rule: str
    received: float
    time: float

    def to_json(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "command_id": self.command_id,
            "command": self.command,
            "occurrence": self.occurrence,
            "kind": self.kind,
            "rule": self.rule,
            "received": self.received,
            "time": self.time,
        }


def forced_delay(spec: CommandSpec, kind: str, params: Params) -> float:
    """Seconds after the command's arrival at which its forced ``kind`` reply is due
    (the rules are in the module docstring)."""
    if kind == "timeout":
        value = params.get(TIME_OUT)
        if isinstance(value, int | float) and not isinstance(value, bool):
            seconds = float(value)
            if math.isfinite(seconds) and seconds >= 0.0:
                return seconds
        return spec.duration_s
    if spec.kind == "task":
        return 0.0
    return spec.duration_s


class FaultInjector:
    """A `VehicleModel` that forces replies where ``plan`` says and otherwise is ``inner``.

    Args:
        inner: the vehicle to wrap.
        profile: the profile its commands come from (reply kinds, kinds, durations).
        plan: the faults to inject; an empty plan makes the injector invisible.
        seed: seeds the rate and ``any`` draws.

    A command the profile does not know is passed on untouched (the vehicle refuses it).
    """

    def __init__(
        self, inner: VehicleModel, profile: VehicleProfile, plan: FaultPlan, *, seed: int
    ) -> None:
        self.inner = inner
        self.profile = profile
        self.plan = plan
        self.seed = seed
        self.injected: list[InjectedFault] = []
        """Every forced reply so far, in the order the commands arrived."""
        self._uses: Counter[str] = Counter()
        self._forced: dict[int, list[Reply]] = {}
        """Forced command id -> its replies given so far (a repeated id gets them again)."""
        self._passed: set[int] = set()
        self._pending: list[tuple[float, int, Reply]] = []
        self._sequence = 0

    # -- delegated ----------------------------------------------------------------------

    @property
    def time(self) -> float:
        """The wrapped vehicle's clock, s."""
        return self.inner.time

    @property
    def watchdog_s(self) -> float:
        """The wrapped vehicle's watchdog, s."""
        return self.inner.watchdog_s

    def heard_from_controller(self) -> None:
        """Reset the wrapped vehicle's watchdog."""
        self.inner.heard_from_controller()

    def telemetry(self) -> TelemetryRecord | None:
        """The wrapped vehicle's telemetry."""
        return self.inner.telemetry()

    def make_safe(self, reason: str) -> list[Reply]:
        """The wrapped vehicle makes itself safe; its replies, and the forced ones due now.

        A forced command's reply still due later keeps its time, as under the watchdog:
        the wrapped vehicle never heard of that command, so it has nothing to stop.
        """
        replies = self.inner.make_safe(reason)
        return sorted([*replies, *self._due_by(self.inner.time)], key=lambda reply: reply.time)

    # -- commands -------------------------------------------------------------------------

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        """Force this command's reply if the plan says so, else pass it on."""
        if command_id in self._forced:
            now = self.inner.time
            return [r for r in self._forced[command_id] if r.time <= now]
        if command_id in self._passed:
            return self.inner.command(command_id, name, params)
        spec = self.profile.command(name)
        self._uses[name] += 1
        occurrence = self._uses[name]
        decision = None
        if spec is not None and self.plan:
            rng = random.Random(f"coral-faults/{self.seed}/{name}/{occurrence}")
            decision = self.plan.forced_reply(spec, occurrence, rng)
        if spec is None or decision is None:
            self._passed.add(command_id)
            return self.inner.command(command_id, name, params)
        kind, rule = decision
        return self._force(command_id, spec, occurrence, kind, rule, params)

    def _force(
        self,
        command_id: int,
        spec: CommandSpec,
        occurrence: int,
        kind: str,
        rule: FaultRule,
        params: Params,
    ) -> list[Reply]:
        self.inner.heard_from_controller()
        now = self.inner.time
        due = now + forced_delay(spec, kind, params)
        reply = Reply(command_id, spec.name, kind, due, f"forced by fault plan rule '{rule.text}'")
        self.injected.append(
            InjectedFault(command_id, spec.name, occurrence, kind, rule.text, now, due)
        )
        self._forced[command_id] = [reply]
        if due <= now:
            return [reply]
        heapq.heappush(self._pending, (due, self._sequence, reply))
        self._sequence += 1
        return []

    def advance_to(self, t: float) -> list[Reply]:
        """Move the wrapped vehicle to ``t``; its replies and the forced ones due by then,
        in time order."""
        replies = self.inner.advance_to(t)
        if not self._pending or self._pending[0][0] > t:
            return replies
        # sorted() is stable and the vehicle's replies come first: at equal times they
        # keep their lead, and each list keeps its own order.
        return sorted([*replies, *self._due_by(t)], key=lambda reply: reply.time)

    def _due_by(self, t: float) -> list[Reply]:
        """The forced replies due by ``t``, taken off the queue in time order."""
        due: list[Reply] = []
        while self._pending and self._pending[0][0] <= t:
            due.append(heapq.heappop(self._pending)[2])
        return due
