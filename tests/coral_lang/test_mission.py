"""`Mission`: a compiled mission with the profile behind it, and what a certificate
records of that profile (`Mission.profile_content`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from coral_lang import CompileError, Mission, compile_source, load_mission, load_profile
from coral_lang.mission import profile_content, profile_digest
from coral_lang.profile import VehicleProfile, parse_profile
from tests.conftest import EXAMPLES

SURVEY = EXAMPLES / "survey_auv" / "survey.coral"
MINNOW = EXAMPLES / "profiles" / "minnow.yaml"
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"

TOY_PROFILE = """\
vehicle: TOY
description: a toy vehicle
resources: [depth]
commands:
  DIVE:
    kind: task
    description: go down
    params:
      - {name: z, type: float, unit: m, min: 0.0, max: 50.0, description: target depth}
    replies: {ack: started, error: refused}
    resources: [depth]
    duration_s: 2.0
  DEPTH?:
    kind: query
    params:
      - {name: z, type: float, unit: m, min: 0.0, max: 50.0}
      - {name: time_out, type: float, unit: s, min: 1.0, max: 600.0}
    replies: {done: reached, timeout: too slow}
    resources: [depth]
    duration_s: 30.0
    space_trap: {signal: depth, order: 0, eps: [0.2], window_s: 2.0}
  BEEP:
    kind: action
    replies: [done]
    duration_s: 1.0
"""

TOY_MISSION = """\
mission toy
vehicle TOY
place start = 1, down, ok, failed
final { ok }
final { failed }
transition dive wait { start } action { TOY(DIVE, z = 10.0) -> { ack: down, error: failed } }
transition check wait { down }
    action { TOY(DEPTH?, z = 10.0, time_out = 60 s) -> { done: ok, timeout: failed } }
"""


def toy(text: str = TOY_PROFILE, file: str = "toy.yaml") -> VehicleProfile:
    return parse_profile(text, file)


def toy_mission(profile: VehicleProfile) -> Mission:
    return Mission.from_result(compile_source(TOY_MISSION, "toy.coral", [profile]), None, [profile])


def test_a_mission_keeps_its_path_sources_net_and_the_profile_it_compiled_against() -> None:
    minnow = load_profile(MINNOW)
    mission = load_mission(SURVEY, [minnow])
    assert mission.path == SURVEY
    assert mission.net.name == "survey" and mission.net.vehicle == "MINNOW"
    assert mission.profiles == (minnow,) and mission.profile is minnow
    assert str(SURVEY) in mission.sources
    assert "vehicle MINNOW" in mission.sources[str(SURVEY)]
    assert mission.diagnostics == ()
    with pytest.raises(TypeError):
        mission.sources["other"] = "edited"  # type: ignore[index]


def test_the_bundled_profile_the_compiler_fell_back_to_is_kept() -> None:
    mission = load_mission(POOL)
    assert [p.name for p in mission.profiles] == ["ROMEO"]
    assert mission.profile is not None and mission.profile.name == "ROMEO"


def test_given_profiles_come_first_and_the_vehicles_one_is_the_profile() -> None:
    mine = toy()
    unrelated = load_profile(MINNOW)
    mission = Mission.from_result(
        compile_source(TOY_MISSION, "toy.coral", [unrelated, mine]), None, [unrelated, mine]
    )
    assert mission.profiles == (unrelated, mine)
    assert mission.profile is mine
    assert mission.path is None


def test_a_mission_exists_only_when_it_compiled() -> None:
    with pytest.raises(CompileError, match="no vehicle profile for 'MINNOW'"):
        load_mission(SURVEY)
    broken = compile_source("mission m\nvehicle ROMEO\nplace a = 1\ntransition t wait { b }\n")
    with pytest.raises(CompileError, match="<mission>:4:"):
        Mission.from_result(broken, None)


def test_profile_content_covers_only_the_commands_the_net_sends() -> None:
    content = toy_mission(toy()).profile_content()
    assert content["vehicle"] == "TOY" and content["file"] == "toy.yaml"
    commands = content["commands"]
    assert isinstance(commands, dict) and list(commands) == ["DEPTH?", "DIVE"]  # no BEEP
    assert commands["DEPTH?"] == {
        "kind": "query",
        "params": [
            {"name": "z", "type": "float", "unit": "m", "min": 0.0, "max": 50.0},
            {"name": "time_out", "type": "float", "unit": "s", "min": 1.0, "max": 600.0},
        ],
        "replies": ["done", "timeout"],
        "resources": ["depth"],
        "duration_s": 30.0,
        "space_trap": {"signal": "depth", "order": 0, "eps": [0.2], "window_s": 2.0},
    }
    assert commands["DIVE"]["space_trap"] is None


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("description: go down", "description: descend, slowly"),
        ("description: target depth", "description: where to stop"),
        ("{done: reached, timeout: too slow}", "{done: arrived, timeout: gave up}"),
        ("description: a toy vehicle", "description: still a toy"),
        (
            "kind: action\n    replies: [done]\n    duration_s: 1.0",
            "kind: task\n    replies: [ack]",
        ),
    ],
    ids=["command description", "param description", "reply meanings", "vehicle", "unused"],
)
def test_what_does_not_change_behaviour_keeps_the_content(old: str, new: str) -> None:
    assert old in TOY_PROFILE
    net = toy_mission(toy()).net
    before = profile_content(net, toy())
    after = profile_content(net, toy(TOY_PROFILE.replace(old, new)))
    assert after == before and profile_digest(after) == profile_digest(before)


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("duration_s: 30.0", "duration_s: 90.0"),
        ("unit: m, min: 0.0, max: 50.0, description", "unit: m, min: 0.0, max: 40.0, description"),
        ("{done: reached, timeout: too slow}", "{timeout: too slow, done: reached}"),
        ("eps: [0.2]", "eps: [0.3]"),
        ("resources: [depth]\n    duration_s: 2.0", "duration_s: 2.0"),
    ],
    ids=["duration", "param range", "reply order", "space trap", "resources"],
)
def test_what_changes_behaviour_changes_the_content_and_its_digest(old: str, new: str) -> None:
    assert old in TOY_PROFILE
    net = toy_mission(toy()).net
    before = profile_content(net, toy())
    after = profile_content(net, toy(TOY_PROFILE.replace(old, new)))
    assert after != before and profile_digest(after) != profile_digest(before)


def test_the_profile_files_path_is_recorded_but_not_digested() -> None:
    mission = toy_mission(toy())
    moved = toy_mission(toy(file="elsewhere/toy.yaml"))
    assert moved.profile_content()["file"] == "elsewhere/toy.yaml"
    assert moved.profile_digest() == mission.profile_digest()
    assert mission.profile_digest().startswith("sha256:") and len(mission.profile_digest()) == 71


def test_a_command_the_profile_lost_is_absent_from_the_content() -> None:
    net = toy_mission(toy()).net
    without = TOY_PROFILE.replace(TOY_PROFILE[TOY_PROFILE.index("  DEPTH?:") :], "")
    commands = profile_content(net, toy(without))["commands"]
    assert isinstance(commands, dict) and list(commands) == ["DIVE"]


def test_a_net_without_a_profile_has_empty_content(tmp_path: Path) -> None:
    net = toy_mission(toy()).net
    assert profile_content(net, None) == {"vehicle": "TOY", "file": None, "commands": {}}
    bare = Mission(path=tmp_path / "x.coral", net=net)
    assert bare.profile is None and bare.sources == {} and bare.profiles == ()
