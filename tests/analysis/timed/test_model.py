"""`analysis.timed.model.build_model`: what the explorer is told about time.

Small missions compiled here against a profile written here, so each number the model
holds can be traced to the line of YAML or CORAL that gave it: work intervals from
``duration_s`` and the tolerance or from ``work_s``, rounded outwards to the
microsecond (the model must have at least the real system's runs), a watched query's
time-out, the link bounds, the reply latency and the ``assert within`` deadlines.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.timed.model import US, ModelError, TimedModel, build_model, seconds
from coral_lang.compiler import compile_source
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile, parse_profile
from coral_lang.timing import LinkBounds

BOT = parse_profile(
    """\
vehicle: BOT
resources: [depth, heading]
timing: {tolerance: 0.1, reply_latency_s: 0.25}
commands:
  DEPTH:
    kind: task
    params: [{name: z, type: float, unit: m}]
    replies: [ack, error]
    resources: [depth]
    duration_s: 0.5
    work_s: {error: [0.0, 0.2]}
  DEPTH?:
    kind: query
    params: [{name: z, type: float, unit: m}, {name: time_out, type: float, unit: s}]
    replies: [done, timeout, error]
    resources: [depth]
    duration_s: 2.0
    work_s: {done: [10.0, 90.0]}
  PING:
    kind: action
    replies: [done, error]
    duration_s: 1.0
""",
    "bot.yaml",
)
OTHER = parse_profile(
    """\
vehicle: OTHER
commands:
  PING:
    kind: action
    replies: [done, error]
    duration_s: 1.0
""",
    "other.yaml",
)
LINK = LinkBounds("lab", 0.05, 1.5)

MISSION = """\
mission m
vehicle BOT
const T_TRACK = 1 min
place start = 1, set, ok, failed, pinged
final { pinged }
final { failed }
transition dive wait { start } action { BOT(DEPTH, z = 2 m) -> { ack: set, error: failed } }
transition check
    wait { set }
    action { BOT(DEPTH?, z = 2 m, time_out = T_TRACK) -> { done: ok, timeout: failed, error: failed } }
transition ping wait { ok } action { BOT(PING) -> { done: pinged, error: failed } }
assert reachable { pinged }
assert within 2 min { pinged }
assert never { ok, failed }
assert within 1500 ms { set, ok }
"""


def compile_mission(text: str, profile: VehicleProfile = BOT) -> Net:
    return compile_source(text, "m.coral", [profile]).raise_for_errors()


NET = compile_mission(MISSION)


def model(net: Net = NET, profiles: tuple[VehicleProfile, ...] = (BOT,)) -> TimedModel:
    return build_model(net, profiles, LINK)


def by_name(timed: TimedModel, name: str) -> int:
    """The index of the COMMAND transition called ``name``."""
    (index,) = (i for i, c in timed.commands.items() if c.name == name)
    return index


# -- work intervals ----------------------------------------------------------------------


def test_work_defaults_to_the_duration_spread_by_the_tolerance() -> None:
    timed = model()
    dive = timed.commands[by_name(timed, "dive")]
    assert dive.interval("ack") == (450_000, 550_000)  # 0.5 s x (1 -+ 0.1)
    ping = timed.commands[by_name(timed, "ping")]
    assert ping.interval("done") == (900_000, 1_100_000)
    assert ping.interval("error") == (900_000, 1_100_000)


def test_a_profile_without_timing_takes_the_default_tolerance_and_latency() -> None:
    net = compile_mission(
        "mission m\nvehicle OTHER\nplace start = 1, done, failed\n"
        "final { done }\nfinal { failed }\n"
        "transition ping wait { start } action { OTHER(PING) -> { done: done, error: failed } }\n",
        OTHER,
    )
    (ping,) = build_model(net, [OTHER], LINK).commands.values()
    assert ping.interval("done") == (800_000, 1_200_000)  # 1 s x (1 -+ 0.2)
    assert ping.latency == 100_000


def test_declared_work_times_are_honoured() -> None:
    timed = model()
    dive = timed.commands[by_name(timed, "dive")]
    assert dive.interval("error") == (0, 200_000)
    check = timed.commands[by_name(timed, "check")]
    assert check.interval("done") == (10_000_000, 90_000_000)
    assert check.interval("error") == (1_800_000, 2_200_000)  # not declared: duration


def test_a_reply_the_mission_ignores_still_takes_its_time() -> None:
    # 'error: ignore' drops the reply, but the vehicle still sends it after its work:
    # the pending command ends then, so the model needs its interval.
    net = compile_mission(
        MISSION.replace("timeout: failed, error: failed", "timeout: failed, error: ignore")
    )
    check = model(net).commands[by_name(model(net), "check")]
    assert check.reply_transition("error") is not None
    assert check.interval("error") == (1_800_000, 2_200_000)


decimals = st.integers(0, 7).flatmap(
    lambda places: st.integers(0, 10 ** (places + 5)).map(lambda n: Fraction(n, 10**places))
)
"""Work times as a profile writes them: up to 10^5 s, up to 7 decimals."""


def _with_work(low: float, high: float) -> VehicleProfile:
    spec = BOT.command("DEPTH")
    assert spec is not None
    changed = dataclasses.replace(spec, work_s=(("ack", low, high),))
    commands = tuple(changed if c.name == "DEPTH" else c for c in BOT.commands)
    return dataclasses.replace(BOT, commands=commands)


@given(decimals, decimals)
def test_declared_work_is_rounded_outwards_to_the_microsecond(a: Fraction, b: Fraction) -> None:
    low_s, high_s = sorted((a, b))
    profile = _with_work(float(low_s), float(high_s))
    timed = build_model(NET, [profile], LINK)
    low, high = timed.commands[by_name(timed, "dive")].interval("ack")
    assert low_s * US - 1 <= low <= low_s * US
    assert high_s * US <= high <= high_s * US + 1


@given(
    st.integers(0, 10**6).map(lambda n: Fraction(n, 1000)),
    st.integers(0, 99).map(lambda n: Fraction(n, 100)),
)
def test_the_tolerance_spread_is_rounded_outwards(duration: Fraction, tolerance: Fraction) -> None:
    commands = tuple(
        dataclasses.replace(c, duration_s=float(duration)) if c.name == "PING" else c
        for c in BOT.commands
    )
    timing = dataclasses.replace(BOT.timing, tolerance=float(tolerance))
    profile = dataclasses.replace(BOT, commands=commands, timing=timing)
    timed = build_model(NET, [profile], LINK)
    low, high = timed.commands[by_name(timed, "ping")].interval("done")
    exact_low = duration * (1 - tolerance) * US
    exact_high = duration * (1 + tolerance) * US
    assert exact_low - 1 <= low <= exact_low
    assert exact_high <= high <= exact_high + 1


def test_sub_microsecond_times_round_outwards() -> None:
    timed = build_model(NET, [_with_work(0.1234567, 0.7654321)], LinkBounds("x", 1.5e-6, 2.5e-6))
    assert timed.commands[by_name(timed, "dive")].interval("ack") == (123_456, 765_433)
    assert (timed.link_low, timed.link_high) == (1, 3)
    latency = dataclasses.replace(BOT, timing=dataclasses.replace(BOT.timing, reply_latency_s=1e-7))
    (first, *_) = build_model(NET, [latency], LINK).commands.values()
    assert first.latency == 1


# -- link, latency, engine -----------------------------------------------------------------


def test_link_bounds_and_reply_latency_in_microseconds() -> None:
    timed = model()
    assert timed.link is LINK
    assert (timed.link_low, timed.link_high) == (50_000, 1_500_000)
    assert {c.latency for c in timed.commands.values()} == {250_000}
    assert seconds(timed.link_high) == 1.5


def test_the_engine_fires_plain_and_command_transitions_never_replies() -> None:
    net = compile_mission(MISSION.replace("final { failed }", "final { failed }\nplace spare\n"))
    timed = model(net)
    kinds = {t.name: t.kind.value for t in net.transitions}
    assert sorted(net.transitions[i].name for i in timed.engine) == ["check", "dive", "ping"]
    assert all(kinds[net.transitions[i].name] != "reply" for i in timed.engine)
    assert set(timed.commands) <= set(timed.engine)


def test_commands_know_their_replies_and_resources() -> None:
    timed = model()
    net = timed.net
    dive = timed.commands[by_name(timed, "dive")]
    assert dive.kind == "task" and dive.resources == ("depth",) and dive.takes_resources
    ack = dive.reply_transition("ack")
    assert ack is not None and net.transitions[ack].name == "dive.ack"
    assert dive.reply_transition("timeout") is None
    check = timed.commands[by_name(timed, "check")]
    assert check.kind == "query" and not check.takes_resources  # it only watches depth
    ping = timed.commands[by_name(timed, "ping")]
    assert ping.kind == "action" and not ping.takes_resources  # it drives nothing


# -- queries -----------------------------------------------------------------------------


def test_a_watched_query_has_its_time_out_and_no_timeout_work() -> None:
    timed = model()
    check = timed.commands[by_name(timed, "check")]
    assert check.watched and check.time_out == 60 * US
    assert check.reply_transition("timeout") is not None
    with pytest.raises(KeyError):
        check.interval("timeout")
    for other in ("dive", "ping"):
        command = timed.commands[by_name(timed, other)]
        assert command.time_out is None and not command.watched


@pytest.mark.parametrize(
    ("written", "micros"),
    [
        ("1 min", 60_000_000),
        ("2500 ms", 2_500_000),
        ("1.0000004", 1_000_000),
        ("1.0000006", 1_000_001),
        ("0.25 min", 15_000_000),
    ],
)
def test_the_time_out_is_rounded_to_the_nearest_microsecond(written: str, micros: int) -> None:
    net = compile_mission(MISSION.replace("time_out = T_TRACK", f"time_out = {written}"))
    assert model(net).commands[by_name(model(net), "check")].time_out == micros


def _without_time_out(net: Net) -> Net:
    """``net`` with the query's ``time_out`` parameter taken away (as a net from
    elsewhere, e.g. PNML, may have it)."""
    transitions = []
    for tr in net.transitions:
        if tr.command is not None and tr.command.name == "DEPTH?":
            params = tuple(p for p in tr.command.params if p[0] != "time_out")
            tr = dataclasses.replace(tr, command=dataclasses.replace(tr.command, params=params))
        transitions.append(tr)
    return dataclasses.replace(net, transitions=tuple(transitions))


def test_a_query_without_a_time_out_is_not_watched() -> None:
    timed = model(_without_time_out(NET))
    check = timed.commands[by_name(timed, "check")]
    assert check.time_out is None and not check.watched
    # Its timeout is then a reply like any other, after the nominal work time.
    assert check.interval("timeout") == (1_800_000, 2_200_000)


def test_a_query_that_cannot_time_out_is_not_watched() -> None:
    spec = BOT.command("DEPTH?")
    assert spec is not None
    no_timeout = dataclasses.replace(spec, replies=("done", "error"))
    profile = dataclasses.replace(
        BOT, commands=tuple(no_timeout if c.name == "DEPTH?" else c for c in BOT.commands)
    )
    check = build_model(NET, [profile], LINK).commands[by_name(model(), "check")]
    assert check.time_out is None and not check.watched


# -- what cannot be modelled --------------------------------------------------------------


def test_operator_inputs_are_refused() -> None:
    net = compile_mission(
        "mission m\nvehicle BOT\ninput go\nplace start = 1, ready, done\n"
        "final { done }\n"
        "transition begin wait { start } action { BOT(PING) -> { done: ready, error: done } }\n"
        "transition finish wait { ready, go } signal { done }\n"
    )
    with pytest.raises(ModelError, match=r"operator inputs \(go\)"):
        model(net)


@pytest.mark.parametrize("profiles", [(), (OTHER,), (OTHER, OTHER)], ids=["none", "other", "two"])
def test_a_command_no_profile_describes_is_refused(
    profiles: tuple[VehicleProfile, ...],
) -> None:
    with pytest.raises(ModelError, match=r"^dive: no vehicle profile describes BOT\(DEPTH\)"):
        model(NET, profiles)


def test_the_profile_of_the_commands_vehicle_is_chosen_among_several() -> None:
    # OTHER also has PING (1 s, default tolerance 0.2): BOT's (tolerance 0.1) must win.
    timed = model(NET, (OTHER, BOT))
    assert timed.commands[by_name(timed, "ping")].interval("done") == (900_000, 1_100_000)


# -- deadlines -----------------------------------------------------------------------------


def test_deadlines_come_from_assert_within_only() -> None:
    timed = model()
    assert [d.index for d in timed.deadlines] == [2, 4]  # numbered among all assertions
    first, second = timed.deadlines
    assert first.deadline == 120 * US and first.named == {"pinged": 1}
    assert first.places == ((NET.place_index("pinged"), 1),)
    assert second.deadline == 1_500_000 and second.named == {"set": 1, "ok": 1}
    marking = [0] * len(NET.places)
    assert not second.reached(marking)
    marking[NET.place_index("set")] = 1
    assert not second.reached(marking)
    marking[NET.place_index("ok")] = 2
    assert second.reached(marking)


def test_a_mission_without_within_has_no_deadline() -> None:
    net = compile_mission(MISSION.replace("assert within", "# assert within"))
    assert model(net).deadlines == ()
    assert math.isclose(seconds(model().deadlines[0].deadline), 120.0)
