"""Pre-mission certificates: issued by verify, checked against the net's digest."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest

from analysis.certificate import (
    CertificateError,
    check_certificate,
    make_certificate,
    write_certificate,
)
from analysis.cli import main
from analysis.signing import TrustStore
from analysis.verify import VerifyOptions, verify
from coral_lang import Mission, compile_mission, compile_source, load_mission, load_profile
from coral_lang.mission import profile_content
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FIXED = dt.datetime(2026, 11, 21, 7, 0, 0, tzinfo=dt.UTC)


def test_certificate_records_digest_verdicts_and_date(tmp_path: Path) -> None:
    net = compile_mission(POOL)
    certificate = make_certificate(
        verify(net, VerifyOptions(structural=False)), clock=lambda: FIXED
    )
    assert certificate["net_digest"] == net.digest()
    assert certificate["verdict"] == "proven" and certificate["issued"] == "2026-11-21T07:00:00Z"
    keys = {p["key"] for p in certificate["properties"]}  # type: ignore[attr-defined]
    assert {"deadlock", "bounded", "resource_conflicts"} <= keys
    path = tmp_path / "pool.cert.json"
    write_certificate(certificate, path)
    accepted = check_certificate(net, path)
    assert accepted.net_digest == net.digest() and accepted.issued == "2026-11-21T07:00:00Z"


def test_a_changed_mission_voids_its_certificate(tmp_path: Path) -> None:
    text = (
        "mission m\nvehicle ROMEO\nplace a = 1, b, c\nfinal { b }\nfinal { c }\n"
        "transition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, error: c } }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    path = tmp_path / "m.cert.json"
    write_certificate(make_certificate(verify(net, VerifyOptions(structural=False))), path)
    check_certificate(net, path)
    reformatted = compile_source("# same mission\n" + text.replace(" { a }", "{a}"), "m.coral")
    check_certificate(reformatted.raise_for_errors(), path)  # layout is not behaviour
    changed = compile_source(text.replace("2.0", "3.0"), "m.coral").raise_for_errors()
    with pytest.raises(CertificateError, match="changed since it was verified"):
        check_certificate(changed, path)


def test_a_failing_verification_gives_no_passing_certificate(tmp_path: Path) -> None:
    net = compile_mission(EXAMPLES / "faulty" / "deadlock.coral")
    path = tmp_path / "bad.cert.json"
    write_certificate(make_certificate(verify(net, VerifyOptions(structural=False))), path)
    with pytest.raises(CertificateError, match="deadlock violated"):
        check_certificate(net, path)


def test_missing_or_garbage_certificates_are_refused_with_the_way_out(tmp_path: Path) -> None:
    net = compile_mission(POOL)
    with pytest.raises(CertificateError, match="no certificate; run 'coral-check verify"):
        check_certificate(net, tmp_path / "none.json")
    garbage = tmp_path / "garbage.json"
    garbage.write_text("{not json")
    with pytest.raises(CertificateError, match="not a readable certificate"):
        check_certificate(net, garbage)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"format": 99}))
    with pytest.raises(CertificateError, match="not a coral certificate"):
        check_certificate(net, other)
    assert issubclass(CertificateError, ValueError)


def test_cli_writes_the_certificate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "pool.cert.json"
    assert main(["verify", str(POOL), "--no-structure", "--certificate", str(path)]) == 0
    check_certificate(compile_mission(POOL), path)
    capsys.readouterr()


# -- the vehicle profile ------------------------------------------------------------------

TOY_PROFILE = """\
vehicle: TOY
resources: [depth, horizontal]
commands:
  DIVE:
    kind: task
    description: go down
    params:
      - {name: z, type: float, unit: m, min: 0.0, max: 50.0}
    replies: {ack: started, error: refused}
    resources: [depth]
    duration_s: 2.0
  DEPTH?:
    kind: query
    params:
      - {name: z, type: float, unit: m, min: 0.0, max: 50.0}
      - {name: time_out, type: float, unit: s, min: 1.0, max: 600.0}
    replies: {done: reached, timeout: too slow, error: sensor fault}
    resources: [depth]
    duration_s: 60.0
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
transition check wait { down } action {
    TOY(DEPTH?, z = 10.0, time_out = 60 s) -> { done: ok, timeout: failed, error: failed } }
"""


def _toy_profile(tmp_path: Path, text: str = TOY_PROFILE) -> VehicleProfile:
    """The profile as a file in ``tmp_path`` (not bundled: messages name it)."""
    path = tmp_path / "toy.yaml"
    path.write_text(text, encoding="utf-8")
    return load_profile(path)


@pytest.fixture
def toy(tmp_path: Path) -> tuple[Mission, Path]:
    """The toy mission and a passing certificate covering its profile."""
    profile = _toy_profile(tmp_path)
    mission = Mission.from_result(compile_source(TOY_MISSION, "toy.coral", [profile]), None)
    report = verify(mission.net, VerifyOptions(structural=False))
    path = tmp_path / "toy.cert.json"
    certificate = make_certificate(
        report, clock=lambda: FIXED, profile_content=mission.profile_content()
    )
    write_certificate(certificate, path)
    return mission, path


def test_the_certificate_records_the_profile_of_the_commands_used(
    toy: tuple[Mission, Path],
) -> None:
    mission, path = toy
    section = json.loads(path.read_text())["profile"]
    assert section["vehicle"] == "TOY" and section["file"].endswith("toy.yaml")
    assert sorted(section["commands"]) == ["DEPTH?", "DIVE"]  # BEEP is not used
    assert section["commands"]["DEPTH?"]["replies"] == ["done", "timeout", "error"]
    assert section["digest"] == mission.profile_digest()
    accepted = check_certificate(mission.net, path, profile_content=mission.profile_content())
    assert accepted.profile_digest == mission.profile_digest()
    assert check_certificate(mission.net, path).profile_digest is None  # not compared


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        ("duration_s: 60.0", "duration_s: 90.0", "DEPTH?.duration_s 60 -> 90"),
        (
            "{done: reached, timeout: too slow, error: sensor fault}",
            "{done: reached, timeout: too slow}",
            "DEPTH?.replies [done, timeout, error] -> [done, timeout]",
        ),
        (
            "{name: z, type: float, unit: m, min: 0.0, max: 50.0}\n    replies: {ack",
            "{name: z, type: float, unit: m, min: 0.0, max: 40.0}\n    replies: {ack",
            "DIVE.params.z.max 50 -> 40",
        ),
        (
            "{name: time_out, type: float, unit: s, min: 1.0",
            "{name: time_out, type: float, unit: s, min: 5.0",
            "DEPTH?.params.time_out.min 1 -> 5",
        ),
        ("kind: task", "kind: action", "DIVE.kind task -> action"),
        (
            "resources: [depth]\n    duration_s: 2.0",
            "resources: [depth, horizontal]\n    duration_s: 2.0",
            "DIVE.resources [depth] -> [depth, horizontal]",
        ),
        (
            "duration_s: 60.0\n",
            "duration_s: 60.0\n    space_trap: {signal: depth, order: 0, eps: [0.2], "
            "window_s: 2.0}\n",
            "DEPTH?.space_trap none -> {signal: depth, order: 0, eps: [0.2], window_s: 2}",
        ),
        (
            "      - {name: z, type: float, unit: m, min: 0.0, max: 50.0}\n"
            "      - {name: time_out, type: float, unit: s, min: 1.0, max: 600.0}\n",
            "      - {name: time_out, type: float, unit: s, min: 1.0, max: 600.0}\n"
            "      - {name: z, type: float, unit: m, min: 0.0, max: 50.0}\n",
            "DEPTH?.params order [z, time_out] -> [time_out, z]",
        ),
    ],
    ids=[
        "duration",
        "reply kinds",
        "param max",
        "param min",
        "kind",
        "resources",
        "trap",
        "param order",
    ],
)
def test_a_profile_edited_after_certification_is_refused_naming_the_change(
    toy: tuple[Mission, Path], tmp_path: Path, old: str, new: str, named: str
) -> None:
    mission, path = toy
    assert old in TOY_PROFILE
    edited = _toy_profile(tmp_path, TOY_PROFILE.replace(old, new, 1))
    # The mission as compiled before: a reply kind it maps may be gone from the profile.
    current = profile_content(mission.net, edited)
    with pytest.raises(CertificateError) as refused:
        check_certificate(mission.net, path, profile_content=current)
    message = str(refused.value)
    assert f"profile TOY changed since certification: {named};" in message
    assert f"--profile {tmp_path / 'toy.yaml'} --certificate {path}" in message


def test_a_command_removed_from_the_profile_is_named(
    toy: tuple[Mission, Path], tmp_path: Path
) -> None:
    mission, path = toy
    without = (
        TOY_PROFILE[: TOY_PROFILE.index("  DEPTH?:")] + TOY_PROFILE[TOY_PROFILE.index("  BEEP:") :]
    )
    current = profile_content(mission.net, _toy_profile(tmp_path, without))
    with pytest.raises(
        CertificateError, match=r"changed since certification: command DEPTH\? removed;"
    ):
        check_certificate(mission.net, path, profile_content=current)


def test_many_changes_are_capped(toy: tuple[Mission, Path], tmp_path: Path) -> None:
    mission, path = toy
    edited = (
        TOY_PROFILE.replace("max: 50.0", "max: 45.0")
        .replace("min: 0.0", "min: 0.5")
        .replace("duration_s: 60.0", "duration_s: 61.0")
        .replace("duration_s: 2.0", "duration_s: 3.0")
        .replace("max: 600.0", "max: 601.0")
    )  # 7 changes in all: z.max and z.min of two commands, two durations, time_out.max
    current = profile_content(mission.net, _toy_profile(tmp_path, edited))
    with pytest.raises(CertificateError) as refused:
        check_certificate(mission.net, path, profile_content=current)
    message = str(refused.value)
    assert message.count(" -> ") == 5 and "; and 2 more;" in message
    assert "DEPTH?.params.z.min 0 -> 0.5" in message  # commands by name, fields in order


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("description: go down", "description: descend"),
        ("{ack: started, error: refused}", "{ack: descending, error: declined}"),
        (
            "kind: action\n    replies: [done]\n    duration_s: 1.0",
            "kind: task\n    replies: [ack]",
        ),
    ],
    ids=["description", "reply meanings", "unused command"],
)
def test_a_profile_change_the_mission_does_not_depend_on_keeps_the_certificate(
    toy: tuple[Mission, Path], tmp_path: Path, old: str, new: str
) -> None:
    mission, path = toy
    assert old in TOY_PROFILE
    edited = _toy_profile(tmp_path, TOY_PROFILE.replace(old, new))
    recompiled = Mission.from_result(compile_source(TOY_MISSION, "toy.coral", [edited]), None)
    accepted = check_certificate(recompiled.net, path, profile_content=recompiled.profile_content())
    assert accepted.profile_digest == mission.profile_digest()


def test_a_certificate_without_a_profile_section_is_refused_when_the_profile_is_given(
    toy: tuple[Mission, Path], tmp_path: Path
) -> None:
    mission, _ = toy
    old = tmp_path / "old.cert.json"
    write_certificate(make_certificate(verify(mission.net, VerifyOptions(structural=False))), old)
    assert "profile" not in json.loads(old.read_text())
    check_certificate(mission.net, old)  # a bare net check (coral-check, PNML) still passes
    with pytest.raises(CertificateError) as refused:
        check_certificate(mission.net, old, profile_content=mission.profile_content())
    message = str(refused.value)
    assert "predates profile coverage" in message
    assert f"coral-check verify MISSION --profile {tmp_path / 'toy.yaml'} --certificate" in message


def test_a_bundled_profile_needs_no_profile_option_in_the_way_out(tmp_path: Path) -> None:
    mission = load_mission(POOL)
    old = tmp_path / "pool.cert.json"
    write_certificate(make_certificate(verify(mission.net, VerifyOptions(structural=False))), old)
    with pytest.raises(CertificateError, match="run 'coral-check verify MISSION --certificate"):
        check_certificate(mission.net, old, profile_content=mission.profile_content())


def test_cli_certificate_covers_the_given_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    survey = EXAMPLES / "survey_auv" / "survey.coral"
    minnow = EXAMPLES / "profiles" / "minnow.yaml"
    path = tmp_path / "survey.cert.json"
    argv = ["verify", str(survey), "--profile", str(minnow), "--no-structure"]
    assert main([*argv, "--certificate", str(path)]) == 0
    capsys.readouterr()
    section = json.loads(path.read_text())["profile"]
    assert section["vehicle"] == "MINNOW" and section["file"] == str(minnow)
    assert "SURVEY_LINE" in section["commands"]
    mission = load_mission(survey, [load_profile(minnow)])
    accepted = check_certificate(mission.net, path, profile_content=mission.profile_content())
    assert accepted.profile_digest == section["digest"]


# -- the way out names the files -------------------------------------------------------------

SMALL = (
    "mission m\nvehicle ROMEO\nplace a = 1, b, c\nfinal { b }\nfinal { c }\n"
    "transition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, error: c } }\n"
)


def _unsigned(tmp_path: Path) -> tuple[Net, Path]:
    """A passing, unsigned certificate for `SMALL`, in a folder whose name needs quoting."""
    net = compile_source(SMALL, "m.coral").raise_for_errors()
    folder = tmp_path / "my certs"
    folder.mkdir()
    path = folder / "m.cert.json"
    write_certificate(make_certificate(verify(net, VerifyOptions(structural=False))), path)
    return net, path


def test_an_unsigned_certificate_names_the_mission_and_certificate_to_verify(
    tmp_path: Path,
) -> None:
    net, path = _unsigned(tmp_path)
    nobody = TrustStore.of([], "test")
    with pytest.raises(CertificateError, match="is not signed") as refused:
        check_certificate(net, path, trusted=nobody, mission="missions/dive 1.coral")
    message = str(refused.value)
    assert (
        f"'coral-check verify 'missions/dive 1.coral' --certificate '{path}' --signing-key KEY'"
        in message
    )
    assert "'coral-run 'missions/dive 1.coral' --verify'" in message
    with pytest.raises(CertificateError) as generic:  # a caller that does not know it
        check_certificate(net, path, trusted=nobody)
    assert f"'coral-check verify MISSION --certificate '{path}' --signing-key KEY'" in str(
        generic.value
    )
    assert "'coral-run MISSION --verify'" in str(generic.value)


def test_every_refusal_names_the_mission_when_the_caller_knows_it(tmp_path: Path) -> None:
    net, path = _unsigned(tmp_path)
    changed = compile_source(SMALL.replace("2.0", "3.0"), "m.coral").raise_for_errors()
    with pytest.raises(CertificateError, match="changed since it was verified") as refused:
        check_certificate(changed, path, mission=Path("m.coral"))
    assert f"run 'coral-check verify m.coral --certificate '{path}' --signing-key KEY'" in str(
        refused.value
    )
    accepted = check_certificate(net, path, mission=Path("m.coral"))
    assert accepted.mission == "m.coral"  # the engine's refusals name it too
    assert check_certificate(net, path).mission is None
