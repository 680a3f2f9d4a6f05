"""`HandlerVehicle`: what the library does around an integrator's handlers.

A small profile (TESTBOT) exercises every rule: input checks, tasks holding resources and
being replaced, queries polled and timed out, actions interrupted, the watchdog, reply
kinds checked against the profile. Time is injected: every test drives the clock itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import pytest

from coral_lang.profile import VehicleProfile, parse_profile
from runtime.telemetry import TelemetryRecord
from runtime.vehicle import (
    HandlerVehicle,
    Job,
    Outcome,
    Refused,
    Reply,
    VehicleModel,
    check_params,
)

TESTBOT = """
vehicle: TESTBOT
resources: [depth, horizontal]
commands:
  INIT: {kind: action, replies: [done, error], duration_s: 1}
  DIVE:
    kind: task
    params: [{name: z, type: float, unit: m, min: 0.5, max: 100}]
    replies: [ack, error]
    resources: [depth]
  DEPTH?:
    kind: query
    params:
      - {name: z, type: float, unit: m, min: 0.5, max: 100}
      - {name: time_out, type: float, unit: s, min: 1, max: 600}
    replies: [done, timeout]
    resources: [depth]
  LINE:
    kind: task
    params: [{name: x, type: float, unit: m}, {name: y, type: float, unit: m}]
    replies: [ack, error]
    resources: [horizontal]
  LINE_END?:
    kind: query
    params: [{name: time_out, type: float, unit: min, min: 0.1, max: 60}]
    replies: [done, timeout, error]
    resources: [horizontal]
  FIX:
    kind: action
    replies: [done, error]
    resources: [horizontal]
  SURFACE: {kind: task, replies: [ack, error], resources: [depth, horizontal]}
  SAMPLE:
    kind: task
    params: [{name: n, type: int, min: 1, max: 5}, {name: label, type: string}]
    replies: [ack, error]
  SPARE: {kind: task, replies: [ack, error]}
"""


def profile() -> VehicleProfile:
    return parse_profile(TESTBOT, "testbot.yaml")


class Bot:
    """A fake robot whose handlers record every call, in order."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.depth = 0.0
        self.line_done = False
        self.fix_done = False
        self.safe = 0

    def vehicle(self, **kwargs: object) -> HandlerVehicle:
        v = HandlerVehicle(profile(), on_watchdog=self.make_safe, **kwargs)  # type: ignore[arg-type]
        v.on("INIT", start=self.record("start INIT"), poll=lambda job: "done")
        v.on("DIVE", start=self.dive, stop=self.record("stop DIVE"))
        v.on("DEPTH?", poll=self.depth_query, stop=self.record("stop DEPTH?"))
        v.on("LINE", start=self.record("start LINE"), stop=self.record("stop LINE"))
        v.on("LINE_END?", poll=lambda job: "done" if self.line_done else None)
        v.on(
            "FIX", poll=lambda job: "done" if self.fix_done else None, stop=self.record("stop FIX")
        )
        v.on("SURFACE", start=self.record("start SURFACE"), stop=self.record("stop SURFACE"))
        v.on("SAMPLE", start=self.sample)
        return v

    def record(self, what: str) -> Callable[[Job], None]:
        def call(job: Job) -> None:
            self.calls.append(f"{what} at {job.now:g}")

        return call

    def dive(self, job: Job) -> Outcome:
        self.calls.append(f"start DIVE z={job['z']!r} at {job.now:g}")
        if job["z"] > 50:
            raise Refused("too deep for today")
        self.depth = job["z"]
        return None

    def depth_query(self, job: Job) -> Outcome:
        self.calls.append(f"poll DEPTH? at {job.now:g}")
        return ("done", f"at {self.depth:g} m") if job.now >= 2.0 else None

    def sample(self, job: Job) -> Outcome:
        self.calls.append(f"SAMPLE {job.params['n']!r} {job.text('label')!r}")
        return None

    def make_safe(self) -> None:
        self.safe += 1


def kinds(replies: list[Reply]) -> list[tuple[int, str]]:
    return [(r.command_id, r.kind) for r in replies]


# ---------------------------------------------------------------------- registration


def test_a_handler_vehicle_is_a_vehicle_model() -> None:
    vehicle: VehicleModel = Bot().vehicle()
    assert isinstance(vehicle, VehicleModel)
    assert vehicle.watchdog_s == 30.0 and vehicle.time == 0.0


@pytest.mark.parametrize(
    ("name", "handlers", "message"),
    [
        ("DIEV", {"start": lambda job: None}, r"no command 'DIEV' \(did you mean 'DIVE'\?\)"),
        ("DIVE", {"poll": lambda job: "ack"}, "DIVE is a task: .* not poll"),
        ("DEPTH?", {}, "DEPTH\\? is a query: give it a poll"),
        ("INIT", {"stop": lambda job: None}, "INIT is an action: give it a poll"),
        ("INIT", {"poll": "done"}, "poll of 'INIT' must be callable"),
    ],
)
def test_registration_is_checked_against_the_profile(
    name: str, handlers: Mapping[str, object], message: str
) -> None:
    vehicle = HandlerVehicle(profile())
    with pytest.raises(ValueError, match=message):
        vehicle.on(name, **handlers)  # type: ignore[arg-type]


def test_a_command_gets_handlers_once() -> None:
    vehicle = HandlerVehicle(profile())
    vehicle.on("SPARE")
    with pytest.raises(ValueError, match="'SPARE' already has handlers"):
        vehicle.on("SPARE")


@pytest.mark.parametrize(
    ("what", "value"), [("watchdog_s", 0.0), ("poll_s", -1.0), ("poll_s", math.nan)]
)
def test_bad_settings_are_refused(what: str, value: float) -> None:
    with pytest.raises(ValueError, match=what):
        HandlerVehicle(profile(), **{what: value})  # type: ignore[arg-type]


# ---------------------------------------------------------------------- input checks


@pytest.mark.parametrize(
    ("name", "params", "detail"),
    [
        ("DIVE", {}, "DIVE needs parameter 'z' (signature: DIVE(z) -> ack | error)"),
        ("DIVE", {"z": 2.0, "speed": 1.0}, "DIVE takes no parameter 'speed'"),
        ("DIVE", {"z": "deep"}, "parameter 'z' of DIVE must be a number, got 'deep'"),
        ("DIVE", {"z": True}, "parameter 'z' of DIVE must be a number, got True"),
        ("DIVE", {"z": math.inf}, "parameter 'z' of DIVE must be finite"),
        (
            "DIVE",
            {"z": 100.5},
            "DIVE: parameter z = 100.5 is out of range (z: float [m] in [0.5, 100])",
        ),
        ("DIVE", {"z": 0.4}, "parameter z = 0.4 is out of range"),
        ("SAMPLE", {"n": 2.0, "label": "a"}, "parameter 'n' of SAMPLE must be a whole number"),
        ("SAMPLE", {"n": 2, "label": 3}, "parameter 'label' of SAMPLE must be text, got 3"),
        ("SAMPLE", {"n": 9, "label": "a"}, "parameter n = 9 is out of range"),
        ("DIVR", {"z": 1.0}, "unknown command 'DIVR' (did you mean 'DIVE'?)"),
        ("SPARE", {}, "SPARE is not implemented on this vehicle"),
    ],
)
def test_bad_input_is_refused_before_any_handler_runs(
    name: str, params: dict[str, float | int | str], detail: str
) -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.advance_to(3.0)
    replies = vehicle.command(1, name, params)
    assert len(replies) == 1
    assert (replies[0].kind, replies[0].time, replies[0].command) == ("error", 3.0, name)
    assert detail in replies[0].detail
    assert bot.calls == []
    assert vehicle.holders == {} and vehicle.advance_to(10.0) == []


def test_handlers_get_parameters_typed_in_the_profiles_units() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    assert kinds(vehicle.command(1, "DIVE", {"z": 3})) == [(1, "ack")]
    assert kinds(vehicle.command(2, "SAMPLE", {"n": 4, "label": "core"})) == [(2, "ack")]
    # An int on the wire for a float parameter arrives as a float; int stays int.
    assert bot.calls == ["start DIVE z=3.0 at 0", "SAMPLE 4 'core'"]


def test_check_params_alone() -> None:
    spec = profile().command("SAMPLE")
    assert spec is not None
    assert check_params(spec, {"n": 1, "label": ""}) == {"n": 1, "label": ""}
    with pytest.raises(Refused, match="must be a mapping"):
        check_params(spec, [1, 2])  # type: ignore[arg-type]


def test_unhandled_commands_are_listed() -> None:
    assert Bot().vehicle().unhandled == ("SPARE",)
    assert HandlerVehicle(profile()).unhandled == profile().command_names


def test_a_reused_command_id_is_not_carried_out_twice() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "DIVE", {"z": 3.0})
    again = vehicle.command(1, "DIVE", {"z": 4.0})
    assert kinds(again) == [(1, "error")] and "already used" in again[0].detail
    assert bot.depth == 3.0


# ---------------------------------------------------------------------- tasks and resources


def test_a_task_acks_at_once_and_holds_its_resources() -> None:
    vehicle = Bot().vehicle()
    vehicle.advance_to(1.5)
    assert vehicle.command(1, "DIVE", {"z": 3.0}) == [Reply(1, "DIVE", "ack", 1.5)]
    assert vehicle.advance_to(20.0) == []  # a task replies once
    assert vehicle.holders == {"depth": "DIVE"}
    assert vehicle.status() == ["DIVE (task) since 1.5 s, holds depth"]


def test_a_refused_task_replies_error_with_the_reason_and_holds_nothing() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "DEPTH?", {"z": 3.0, "time_out": 60.0})
    replies = vehicle.command(3, "DIVE", {"z": 60.0})
    assert replies == [Reply(3, "DIVE", "error", 0.0, "too deep for today")]
    # The old DIVE was stopped before the new one's start refused: the resource is free,
    # and the query watching it timed out.
    assert vehicle.holders == {}
    assert bot.calls[-3:] == ["stop DIVE at 0", "stop DEPTH? at 0", "start DIVE z=60.0 at 0"]
    assert kinds(vehicle.advance_to(0.0)) == [(2, "timeout")]


def test_a_task_on_a_busy_resource_stops_the_holder_and_its_queries_time_out() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "LINE", {"x": 10.0, "y": 0.0})
    vehicle.command(3, "DEPTH?", {"z": 3.0, "time_out": 60.0})
    vehicle.command(4, "LINE_END?", {"time_out": 10.0})
    vehicle.advance_to(1.0)
    bot.calls.clear()
    # SURFACE takes depth and horizontal: both tasks stop, before SURFACE starts. A
    # watching query with a poll handler gets one last look first (an answer due now
    # wins over the stop, as at a time-out).
    assert vehicle.command(5, "SURFACE", {}) == [Reply(5, "SURFACE", "ack", 1.0)]
    assert bot.calls == [
        "poll DEPTH? at 1",
        "stop DIVE at 1",
        "stop DEPTH? at 1",
        "stop LINE at 1",
        "start SURFACE at 1",
    ]
    # The watching queries' time-outs come from the next advance, stamped with 1.0.
    assert vehicle.advance_to(1.0) == [
        Reply(3, "DEPTH?", "timeout", 1.0, "its task DIVE was replaced by SURFACE"),
        Reply(4, "LINE_END?", "timeout", 1.0, "its task LINE was replaced by SURFACE"),
    ]
    assert vehicle.holders == {"depth": "SURFACE", "horizontal": "SURFACE"}
    assert [e.text for e in vehicle.events] == [
        "DIVE stopped: replaced by SURFACE",
        "LINE stopped: replaced by SURFACE",
    ]


def test_queries_never_replace_each_other() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "DEPTH?", {"z": 3.0, "time_out": 60.0})
    vehicle.command(3, "DEPTH?", {"z": 3.0, "time_out": 60.0})
    assert vehicle.holders == {"depth": "DIVE"}
    replies = vehicle.advance_to(2.0)
    assert kinds(replies) == [(2, "done"), (3, "done")]
    assert {r.time for r in replies} == {2.0} and replies[0].detail == "at 3 m"


def test_an_action_holding_a_resource_is_interrupted_with_an_error() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "FIX", {})
    assert vehicle.holders == {"horizontal": "FIX"}
    vehicle.command(2, "LINE_END?", {"time_out": 1.0})
    vehicle.advance_to(0.5)
    assert kinds(vehicle.command(3, "LINE", {"x": 1.0, "y": 2.0})) == [(3, "ack")]
    assert vehicle.advance_to(0.5) == [
        Reply(1, "FIX", "error", 0.5, "interrupted: replaced by LINE"),
        Reply(2, "LINE_END?", "timeout", 0.5, "its action FIX was replaced by LINE"),
    ]
    assert "stop FIX at 0.5" in bot.calls


def test_an_action_that_finishes_releases_its_resources_without_touching_queries() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "FIX", {})
    vehicle.command(2, "LINE_END?", {"time_out": 0.1})  # 6 s
    vehicle.advance_to(0.25)
    bot.fix_done = True
    replies = vehicle.advance_to(0.35)
    assert replies == [Reply(1, "FIX", "done", 0.3)]
    assert vehicle.holders == {}
    assert vehicle.advance_to(5.9) == []
    assert vehicle.advance_to(6.5) == [
        Reply(2, "LINE_END?", "timeout", 6.0, "time-out of 0.1 min passed")
    ]
    assert "stop FIX" not in " ".join(bot.calls)


# ---------------------------------------------------------------------- queries, actions, time


def test_queries_are_polled_every_poll_s_and_reply_at_that_poll() -> None:
    bot = Bot()
    vehicle = bot.vehicle(poll_s=0.5)
    vehicle.advance_to(0.2)
    vehicle.command(1, "DEPTH?", {"z": 3.0, "time_out": 60.0})
    assert vehicle.advance_to(1.9) == []
    assert bot.calls == ["poll DEPTH? at 0.5", "poll DEPTH? at 1", "poll DEPTH? at 1.5"]
    replies = vehicle.advance_to(5.0)
    assert replies == [Reply(1, "DEPTH?", "done", 2.0, "at 0 m")]
    assert bot.calls[-1] == "poll DEPTH? at 2"  # and never again once answered
    vehicle.advance_to(9.0)
    assert bot.calls[-1] == "poll DEPTH? at 2"


def test_a_query_times_out_at_its_time_out_exactly_in_its_unit() -> None:
    bot = Bot()
    vehicle = bot.vehicle(watchdog_s=100.0)
    vehicle.advance_to(0.03)
    vehicle.command(1, "LINE_END?", {"time_out": 0.5})  # minutes
    assert vehicle.advance_to(30.0) == []
    replies = vehicle.advance_to(31.0)
    assert replies == [Reply(1, "LINE_END?", "timeout", 30.03, "time-out of 0.5 min passed")]


def test_replies_come_in_time_order_each_with_its_own_time() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    vehicle.command(1, "LINE_END?", {"time_out": 0.1})  # 6 s
    vehicle.command(2, "DEPTH?", {"z": 1.0, "time_out": 4.0})
    vehicle.command(3, "DEPTH?", {"z": 1.0, "time_out": 1.0})
    replies = vehicle.advance_to(100.0)
    assert [(r.command_id, r.kind, r.time) for r in replies] == [
        (3, "timeout", 1.0),
        (2, "done", 2.0),
        (1, "timeout", 6.0),
    ]


def test_an_action_is_polled_until_it_says_a_kind() -> None:
    bot = Bot()
    vehicle = bot.vehicle()
    assert vehicle.command(1, "INIT", {}) == []
    assert bot.calls == ["start INIT at 0"]
    assert vehicle.advance_to(1.0) == [Reply(1, "INIT", "done", 0.1)]


def test_the_clock_never_goes_back() -> None:
    vehicle = Bot().vehicle()
    vehicle.advance_to(5.0)
    with pytest.raises(ValueError, match="back to 4"):
        vehicle.advance_to(4.0)
    with pytest.raises(ValueError):
        vehicle.advance_to(math.nan)


# ---------------------------------------------------------------------- replies checked


def test_a_kind_the_profile_does_not_list_becomes_an_error_naming_it() -> None:
    vehicle = HandlerVehicle(profile())
    vehicle.on("INIT", start=lambda job: "ok")
    vehicle.on("DEPTH?", poll=lambda job: ("finished", "reached"))
    vehicle.on("LINE_END?", poll=lambda job: 42)  # type: ignore[arg-type,return-value]
    vehicle.on("SPARE", start=lambda job: "done")
    (init,) = vehicle.command(1, "INIT", {})
    assert init.kind == "error"
    assert init.detail == (
        "the handler of INIT answered 'ok', which is not a reply of INIT in the profile "
        "(done, error)"
    )
    vehicle.command(2, "DEPTH?", {"z": 1.0, "time_out": 5.0})
    vehicle.command(3, "LINE_END?", {"time_out": 1.0})
    (spare,) = vehicle.command(4, "SPARE", {})
    assert spare.kind == "error" and "'done'" in spare.detail
    replies = vehicle.advance_to(1.0)
    assert kinds(replies) == [(2, "error"), (3, "error")]
    assert "'finished'" in replies[0].detail and "returned 42" in replies[1].detail


def test_a_handler_that_raises_gets_an_error_and_the_vehicle_goes_on() -> None:
    vehicle = HandlerVehicle(profile())

    def broken(job: Job) -> Outcome:
        raise OSError("serial port gone")

    vehicle.on("DIVE", start=broken)
    vehicle.on("INIT", poll=lambda job: "done")
    (reply,) = vehicle.command(1, "DIVE", {"z": 2.0})
    assert reply.kind == "error"
    assert reply.detail == "vehicle fault in DIVE: OSError: serial port gone"
    assert vehicle.holders == {}
    assert vehicle.events[-1].text == "DIVE: handler raised OSError: serial port gone"
    vehicle.command(2, "INIT", {})
    assert kinds(vehicle.advance_to(1.0)) == [(2, "done")]


def test_an_action_without_poll_whose_start_says_nothing_is_an_error() -> None:
    vehicle = HandlerVehicle(profile())
    vehicle.on("INIT", start=lambda job: None)
    (reply,) = vehicle.command(1, "INIT", {})
    assert reply.kind == "error" and "no poll" in reply.detail


# ---------------------------------------------------------------------- watchdog


def test_the_watchdog_counts_from_the_last_word_of_the_controller() -> None:
    bot = Bot()
    vehicle = bot.vehicle(watchdog_s=10.0)
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "FIX", {})
    vehicle.advance_to(1.0)
    vehicle.heard_from_controller()  # the controller is alive at 1 s...
    assert vehicle.advance_to(10.5) == []
    assert bot.safe == 0 and vehicle.holders == {"depth": "DIVE", "horizontal": "FIX"}
    # ...so the watchdog trips at 11 s, not 10 s.
    assert vehicle.advance_to(30.0) == [Reply(2, "FIX", "error", 11.0, "stopped by the watchdog")]
    assert bot.safe == 1 and vehicle.holders == {}
    assert bot.calls[-2:] == ["stop DIVE at 11", "stop FIX at 11"]
    assert vehicle.events[-1].text == (
        "watchdog: no word from the controller for 10.0 s; making safe"
    )


def test_the_watchdog_replies_for_what_is_pending_at_its_time() -> None:
    bot = Bot()
    vehicle = bot.vehicle(watchdog_s=10.0)
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "FIX", {})
    vehicle.command(3, "LINE_END?", {"time_out": 1.0})
    replies = vehicle.advance_to(20.0)
    assert replies == [
        Reply(2, "FIX", "error", 10.0, "stopped by the watchdog"),
        Reply(3, "LINE_END?", "timeout", 10.0, "stopped by the watchdog"),
    ]
    assert bot.safe == 1
    assert bot.calls[-2:] == ["stop DIVE at 10", "stop FIX at 10"]
    # It trips once per silence; hearing from the controller re-arms it.
    assert vehicle.advance_to(100.0) == [] and bot.safe == 1
    vehicle.heard_from_controller()
    vehicle.advance_to(111.0)
    assert bot.safe == 2


def test_the_watchdog_is_not_armed_before_the_controller_speaks() -> None:
    bot = Bot()
    vehicle = bot.vehicle(watchdog_s=10.0)
    vehicle.advance_to(1000.0)
    assert bot.safe == 0 and vehicle.events == ()


def test_a_failing_make_safe_is_noted_not_raised() -> None:
    def boom() -> None:
        raise RuntimeError("winch jammed")

    vehicle = HandlerVehicle(profile(), watchdog_s=1.0, on_watchdog=boom)
    vehicle.heard_from_controller()
    vehicle.advance_to(2.0)
    assert vehicle.events[-1].text == "on_watchdog raised RuntimeError: winch jammed"


# ---------------------------------------------------------------------- telemetry


def test_telemetry_comes_from_the_source_at_the_vehicle_time() -> None:
    assert HandlerVehicle(profile()).telemetry() is None
    vehicle = HandlerVehicle(
        profile(), telemetry=lambda now: TelemetryRecord(now, 1.0, 2.0, now / 10, 90.0)
    )
    vehicle.advance_to(5.0)
    assert vehicle.telemetry() == TelemetryRecord(5.0, 1.0, 2.0, 0.5, 90.0)


def test_a_failing_telemetry_source_gives_none_and_one_note() -> None:
    def source(now: float) -> TelemetryRecord:
        raise ValueError("no fix")

    vehicle = HandlerVehicle(profile(), telemetry=source)
    assert vehicle.telemetry() is None and vehicle.telemetry() is None
    assert [e.text for e in vehicle.events] == ["telemetry source raised ValueError: no fix"]


def test_a_source_returning_something_else_is_named_once_and_sends_nothing() -> None:
    """A source written against an older record, or returning a tuple, is caught here
    rather than failing inside the server."""
    vehicle = HandlerVehicle(profile(), telemetry=lambda now: (now, 1.0, 2.0, 0.0, 90.0))  # type: ignore[arg-type,return-value]
    assert vehicle.telemetry() is None and vehicle.telemetry() is None
    assert [e.text for e in vehicle.events] == [
        "telemetry source returned tuple, not a runtime.telemetry.TelemetryRecord: "
        "no telemetry is sent"
    ]
