"""`FaultInjector`: forced replies at the profile's times, everything else untouched."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Literal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.profile import VehicleProfile, load_bundled_profile, parse_profile
from romeo_sim.vehicle import Vehicle
from runtime.faultplan import FaultPlan, parse_fault_rules
from runtime.vehicle.faults import FaultInjector, InjectedFault
from runtime.vehicle.model import Params, Reply, TelemetryRecord, VehicleModel

ROMEO = load_bundled_profile("ROMEO")
TOY = parse_profile(
    """
vehicle: TOY
resources: [arm]
commands:
  GRAB:
    kind: task
    params: [{name: force, type: float}]
    replies: [ack, error]
    resources: [arm]
    duration_s: 0.5
  GRABBED?:
    kind: query
    params: [{name: time_out, type: float, unit: s}]
    replies: [done, timeout]
    duration_s: 10.0
  WAIT:
    kind: action
    replies: [done, timeout, error]
    duration_s: 4.0
""",
    "toy.yaml",
)


class Fake:
    """A vehicle a test can see through: tasks ``ack`` at once, queries ``done`` after
    half their ``time_out`` (``timeout`` at it when ``force`` > 5 was last grabbed),
    actions the profile's first reply after ``duration_s``; unknown commands ``error``."""

    def __init__(self, profile: VehicleProfile) -> None:
        self.profile = profile
        self.clock = 0.0
        self.received: list[tuple[int, str]] = []
        self.heard = 0
        self.strong = False
        self._due: list[tuple[float, int, Reply]] = []
        self._seq = 0

    @property
    def time(self) -> float:
        return self.clock

    @property
    def watchdog_s(self) -> float:
        return 42.0

    def heard_from_controller(self) -> None:
        self.heard += 1

    def make_safe(self, reason: str) -> list[Reply]:
        return []  # nothing runs long enough here for a stop to matter

    def telemetry(self) -> TelemetryRecord:
        return TelemetryRecord(self.clock, 1.0, 2.0, 3.0, 90.0)

    def _later(self, at: float, reply: Reply) -> None:
        self._due.append((at, self._seq, reply))
        self._seq += 1

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        self.received.append((command_id, name))
        self.heard += 1
        spec = self.profile.command(name)
        now = self.clock
        if spec is None:
            return [Reply(command_id, name, "error", now, f"unknown command {name}")]
        if spec.kind == "task":
            force = params.get("force", 0.0)
            self.strong = isinstance(force, float | int) and force > 5
            return [Reply(command_id, name, "ack", now)]
        if spec.kind == "query":
            time_out = float(params.get("time_out", 10.0))
            if self.strong:
                self._later(now + time_out, Reply(command_id, name, "timeout", now + time_out))
            else:
                self._later(now + time_out / 2, Reply(command_id, name, "done", now + time_out / 2))
            return []
        at = now + spec.duration_s
        self._later(at, Reply(command_id, name, spec.replies[0], at))
        return []

    def advance_to(self, t: float) -> list[Reply]:
        assert t >= self.clock - 1e-12, "the clock went back"
        self.clock = max(self.clock, t)
        ready = sorted(d for d in self._due if d[0] <= t)
        self._due = [d for d in self._due if d[0] > t]
        return [reply for _, _, reply in ready]


def inject(rules: list[str], profile: VehicleProfile = TOY, seed: int = 0) -> FaultInjector:
    plan = parse_fault_rules(rules)
    plan.check(profile)
    return FaultInjector(Fake(profile), profile, plan, seed=seed)


def fake(injector: FaultInjector) -> Fake:
    assert isinstance(injector.inner, Fake)
    return injector.inner


FORCED = "forced by fault plan rule"


# --------------------------------------------------------------------------- identity

Step = tuple[Literal["command"], str, float] | tuple[Literal["advance"], float, float]

STEPS: st.SearchStrategy[Step] = st.one_of(
    st.tuples(
        st.just("command"),
        st.sampled_from(["GRAB", "GRABBED?", "WAIT", "BOGUS"]),
        st.floats(0.0, 10.0),
    ),
    st.tuples(st.just("advance"), st.floats(0.0, 8.0), st.just(0.0)),
)


def _drive(model: VehicleModel, steps: list[Step]) -> list[tuple[str, list[Reply]]]:
    out: list[tuple[str, list[Reply]]] = []
    for i, step in enumerate(steps):
        if step[0] == "command":
            params: Mapping[str, float] = {"force": step[2], "time_out": 1.0 + step[2]}
            out.append(("command", model.command(i, step[1], params)))
        else:
            out.append(("advance", model.advance_to(model.time + step[1])))
    out.append(("end", model.advance_to(model.time + 100.0)))
    return out


@pytest.mark.slow
@settings(max_examples=150)
@given(
    steps=st.lists(STEPS, max_size=40),
    plan=st.sampled_from([FaultPlan(), parse_fault_rules(["GRAB#1000=error", "NOPE=error"])]),
    seed=st.integers(0, 2**32),
)
def test_a_plan_that_forces_nothing_leaves_the_vehicle_as_it_is(
    steps: list[Step], plan: FaultPlan, seed: int
) -> None:
    bare = Fake(TOY)
    wrapped = FaultInjector(Fake(TOY), TOY, plan, seed=seed)
    assert _drive(wrapped, steps) == _drive(bare, steps)
    assert fake(wrapped).received == bare.received
    assert wrapped.time == bare.time and wrapped.injected == []


def test_the_injector_is_a_vehicle_model_delegating_clock_watchdog_and_telemetry() -> None:
    injector = inject(["GRAB=error"])
    assert isinstance(injector, VehicleModel)
    assert injector.watchdog_s == 42.0
    injector.advance_to(3.0)
    assert injector.time == 3.0 == fake(injector).clock
    telemetry = injector.telemetry()
    assert telemetry is not None and telemetry.vehicle_time == 3.0 and telemetry.psi == 90.0
    before = fake(injector).heard
    injector.heard_from_controller()
    assert fake(injector).heard == before + 1


# --------------------------------------------------------------------------- when replies come


def test_a_forced_task_replies_at_once_and_the_vehicle_never_gets_it() -> None:
    injector = inject(["GRAB=error"])
    injector.advance_to(2.5)
    heard = fake(injector).heard
    replies = injector.command(7, "GRAB", {"force": 9.0})
    assert replies == [Reply(7, "GRAB", "error", 2.5, f"{FORCED} 'GRAB=error'")]
    assert fake(injector).received == []
    assert fake(injector).heard == heard + 1  # still a word from the controller
    assert not fake(injector).strong  # the vehicle did not do it
    assert injector.advance_to(100.0) == []
    assert injector.injected == [InjectedFault(7, "GRAB", 1, "error", "GRAB=error", 2.5, 2.5)]


def test_a_forced_timeout_comes_when_the_time_out_runs_out() -> None:
    injector = inject(["GRABBED?=timeout"])
    injector.advance_to(1.0)
    assert injector.command(3, "GRABBED?", {"time_out": 12.0}) == []
    assert injector.advance_to(12.9) == []
    assert fake(injector).clock == 12.9  # the vehicle's clock moves while the reply waits
    replies = injector.advance_to(13.5)
    assert replies == [Reply(3, "GRABBED?", "timeout", 13.0, f"{FORCED} 'GRABBED?=timeout'")]
    assert fake(injector).received == []


def test_a_forced_timeout_without_a_usable_time_out_comes_after_the_duration() -> None:
    injector = inject(["WAIT=timeout", "GRABBED?=timeout"])
    injector.command(1, "WAIT", {})
    injector.command(2, "GRABBED?", {"time_out": "soon"})
    injector.command(3, "GRABBED?", {"time_out": math.inf})
    replies = injector.advance_to(50.0)
    assert [(r.command_id, r.kind, r.time) for r in replies] == [
        (1, "timeout", 4.0),
        (2, "timeout", 10.0),
        (3, "timeout", 10.0),
    ]


@pytest.mark.parametrize(
    ("name", "kind", "after"), [("WAIT", "error", 4.0), ("GRABBED?", "done", 10.0)]
)
def test_other_forced_kinds_come_after_the_nominal_duration(
    name: str, kind: str, after: float
) -> None:
    injector = inject([f"{name}={kind}"])
    injector.advance_to(1.0)
    assert injector.command(1, name, {"time_out": 3.0}) == []
    assert injector.advance_to(1.0 + after - 0.01) == []
    assert [(r.kind, r.time) for r in injector.advance_to(1.0 + after)] == [(kind, 1.0 + after)]


def test_forced_and_vehicle_replies_come_out_in_time_order() -> None:
    injector = inject(["GRABBED?#2=done", "WAIT#1=error"])
    injector.command(1, "GRABBED?", {"time_out": 8.0})  # the vehicle: done at 4
    injector.command(2, "GRABBED?", {"time_out": 2.0})  # forced: done at 10
    injector.command(3, "WAIT", {})  # forced: error at 4, ties with the vehicle's
    injector.command(4, "GRABBED?", {"time_out": 30.0})  # the vehicle: done at 15
    replies = injector.advance_to(20.0)
    assert [(r.command_id, r.kind, r.time) for r in replies] == [
        (1, "done", 4.0),
        (3, "error", 4.0),
        (2, "done", 10.0),
        (4, "done", 15.0),
    ]
    assert [r.command_id for r in replies if FORCED in r.detail] == [3, 2]
    assert fake(injector).received == [(1, "GRABBED?"), (4, "GRABBED?")]


# --------------------------------------------------------------------------- which uses


def test_uses_are_counted_per_command_and_a_repeated_id_is_not_a_new_use() -> None:
    injector = inject(["GRAB#2=error", "WAIT#1=error"])
    first = injector.command(1, "GRAB", {"force": 1.0})
    assert first[0].kind == "ack"
    assert injector.command(1, "GRAB", {"force": 1.0})[0].kind == "ack"  # a resend
    assert injector.command(2, "GRABBED?", {"time_out": 5.0}) == []
    forced = injector.command(3, "GRAB", {"force": 1.0})
    assert [r.kind for r in forced] == ["error"]
    assert injector.command(3, "GRAB", {"force": 1.0}) == forced  # a resend: the same
    assert injector.command(4, "GRAB", {"force": 1.0})[0].kind == "ack"
    assert [(f.command_id, f.occurrence) for f in injector.injected] == [(3, 2)]
    assert fake(injector).received == [(1, "GRAB"), (1, "GRAB"), (2, "GRABBED?"), (4, "GRAB")]


def test_an_unknown_command_goes_to_the_vehicle() -> None:
    injector = inject(["*=any"])
    assert [r.kind for r in injector.command(1, "FLY", {})] == ["error"]
    assert fake(injector).received == [(1, "FLY")]


def _forced_uses(injector: FaultInjector, name: str) -> list[int]:
    return [f.occurrence for f in injector.injected if f.command == name]


def test_rate_draws_follow_the_seed_not_the_other_commands() -> None:
    def run(seed: int, interleave: bool) -> list[int]:
        injector = inject(["GRAB=error@0.5"], seed=seed)
        for i in range(60):
            injector.command(2 * i, "GRAB", {"force": 1.0})
            if interleave:
                injector.command(2 * i + 1, "WAIT", {})
        return _forced_uses(injector, "GRAB")

    uses = run(11, interleave=False)
    assert 15 < len(uses) < 45
    assert uses == run(11, interleave=True)
    assert uses != run(12, interleave=False)


def test_any_forces_only_unexpected_kinds() -> None:
    injector = inject(["*=any"])
    for i in range(60):
        injector.command(i, "WAIT", {})
    kinds = {r.kind for r in injector.advance_to(10.0)}
    assert kinds == {"timeout", "error"}
    assert fake(injector).received == []


# --------------------------------------------------------------------------- with ROMEO


class SpyVehicle(Vehicle):
    """The simulated ROMEO, noting every command that reaches it."""

    def __init__(self) -> None:
        super().__init__(seed=3)
        self.received: list[str] = []

    def command(
        self, command_id: int, name: str, params: Mapping[str, float | int | str]
    ) -> list[Reply]:
        self.received.append(name)
        return super().command(command_id, name, params)


def romeo(rules: list[str]) -> tuple[FaultInjector, SpyVehicle]:
    vehicle = SpyVehicle()
    plan = parse_fault_rules(rules)
    plan.check(ROMEO)
    return FaultInjector(vehicle, ROMEO, plan, seed=1), vehicle


def test_romeo_a_forced_depth_query_times_out_at_its_time_out() -> None:
    injector, vehicle = romeo(["DEPTH?=timeout"])
    assert [r.kind for r in injector.command(1, "INIT", {})] == ["done"]
    assert injector.command(2, "DEPTH", {"z": 1.0})[0].kind == "ack"
    injector.advance_to(2.0)
    assert injector.command(3, "DEPTH?", {"z": 1.0, "time_out": 25.0}) == []
    early = injector.advance_to(26.95)
    assert all(r.command_id != 3 for r in early)
    late = [r for r in injector.advance_to(27.5) if r.command_id == 3]
    assert [(r.kind, r.time) for r in late] == [("timeout", 27.0)]
    assert "DEPTH?=timeout" in late[0].detail
    assert vehicle.received == ["INIT", "DEPTH"]
    assert vehicle.time == 27.5
    # The depth task the vehicle did get went on: it dived meanwhile.
    assert vehicle.telemetry().z > 0.5


def test_romeo_a_forced_task_error_comes_at_once_and_the_vehicle_stays_put() -> None:
    injector, vehicle = romeo(["DEPTH=error"])
    injector.advance_to(1.0)
    replies = injector.command(1, "DEPTH", {"z": 2.0})
    assert [(r.kind, r.time) for r in replies] == [("error", 1.0)]
    assert vehicle.received == []
    injector.advance_to(30.0)
    telemetry = vehicle.telemetry()
    assert telemetry.depth_task == "" and telemetry.z < 0.2
    # Without the fault, the same command starts a dive.
    plain, unfaulted = romeo([])
    plain.advance_to(1.0)
    assert plain.command(1, "DEPTH", {"z": 2.0})[0].kind == "ack"
    plain.advance_to(30.0)
    assert unfaulted.received == ["DEPTH"] and unfaulted.telemetry().z > 1.0
