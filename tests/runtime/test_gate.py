"""The pre-run gate with vehicle profiles: a mission for a vehicle whose profile is not
bundled compiles, is certified and approved; a profile edited since is refused; and the
schedule's work times come from the profile the mission compiled against."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis.certificate import CertificateError, make_certificate, write_certificate
from analysis.outcome import FileOutcome
from analysis.signing import TrustStore, sign_certificate
from analysis.verify import VerifyOptions, verify
from coral_lang import CompileError, load_mission, load_profile
from coral_lang.net import Command
from runtime.gate import approve_mission, check_mission_certificate, default_certificate_path
from runtime.schedule import DEFAULT_WORK_S, Timing
from tests.conftest import EXAMPLES, TestKey

SURVEY = EXAMPLES / "survey_auv" / "survey.coral"
MINNOW = EXAMPLES / "profiles" / "minnow.yaml"
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"


def _edited_minnow(tmp_path: Path, old: str, new: str) -> Path:
    text = MINNOW.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "minnow.yaml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def _sign_file(path: Path, key: TestKey) -> None:
    """Sign the certificate at ``path`` in place, as a verifier holding ``key`` would."""
    write_certificate(sign_certificate(json.loads(path.read_text()), key.key), path)


NOBODY = TrustStore()


def test_a_mission_for_a_vehicle_given_by_profile_is_certified_and_approved(
    tmp_path: Path, signing_key: TestKey
) -> None:
    cert = tmp_path / "survey.cert.json"
    minnow = load_profile(MINNOW)
    issued = approve_mission(SURVEY, cert, issue=True, profiles=[minnow], trusted=NOBODY)
    assert issued.issued_now and issued.path == SURVEY
    assert issued.mission.profile is minnow and issued.net is issued.mission.net
    assert issued.approval.net_digest == issued.net.digest()
    assert issued.approval.profile_digest == issued.mission.profile_digest()
    # Approved on its own verification, by a key that never left the process.
    assert issued.approval.signer is not None
    assert issued.approval.signer not in signing_key.trusted.keys
    written = json.loads(cert.read_text())
    assert "signature" not in written  # the file records; it does not approve
    section = written["profile"]
    assert section["vehicle"] == "MINNOW" and section["digest"] == issued.mission.profile_digest()
    with pytest.raises(CertificateError, match="is not signed"):
        approve_mission(SURVEY, cert, profiles=[load_profile(MINNOW)], trusted=NOBODY)
    _sign_file(cert, signing_key)
    with pytest.raises(CertificateError, match="not trusted here"):
        approve_mission(SURVEY, cert, profiles=[load_profile(MINNOW)], trusted=NOBODY)
    again = approve_mission(
        SURVEY, cert, profiles=[load_profile(MINNOW)], trusted=signing_key.trusted
    )
    assert not again.issued_now and again.approval.profile_digest == section["digest"]
    assert again.approval.signer == signing_key.key.public.key_id


def test_without_its_profile_the_mission_does_not_compile(tmp_path: Path) -> None:
    with pytest.raises(CompileError, match="no vehicle profile for 'MINNOW'"):
        approve_mission(SURVEY, tmp_path / "cert.json", issue=True)


def test_a_profile_edited_since_certification_is_refused_and_reissued_on_request(
    tmp_path: Path, signing_key: TestKey
) -> None:
    cert = tmp_path / "survey.cert.json"
    approve_mission(SURVEY, cert, issue=True, profiles=[load_profile(MINNOW)])
    _sign_file(cert, signing_key)
    slower = load_profile(_edited_minnow(tmp_path, "duration_s: 60.0 ", "duration_s: 90.0 "))
    with pytest.raises(CertificateError) as refused:
        approve_mission(SURVEY, cert, profiles=[slower], trusted=signing_key.trusted)
    message = str(refused.value)
    assert "profile MINNOW changed since certification: DEPTH?.duration_s 60 -> 90;" in message
    assert f"--profile {tmp_path / 'minnow.yaml'}" in message
    reissued = approve_mission(SURVEY, cert, issue=True, profiles=[slower])
    assert reissued.issued_now
    assert json.loads(cert.read_text())["profile"]["commands"]["DEPTH?"]["duration_s"] == 90.0


def test_a_certificate_from_before_profile_coverage_does_not_run(
    tmp_path: Path, signing_key: TestKey
) -> None:
    mission = load_mission(POOL)
    cert = tmp_path / "pool.cert.json"
    write_certificate(make_certificate(verify(mission.net, VerifyOptions(structural=False))), cert)
    _sign_file(cert, signing_key)
    with pytest.raises(CertificateError, match="predates profile coverage"):
        approve_mission(POOL, cert, trusted=signing_key.trusted)
    with pytest.raises(CertificateError, match="predates profile coverage"):
        check_mission_certificate(mission, cert, trusted=signing_key.trusted)


def test_check_mission_certificate_defaults_to_the_file_beside_the_mission(
    tmp_path: Path, signing_key: TestKey, monkeypatch: pytest.MonkeyPatch
) -> None:
    mission_file = tmp_path / "dive.coral"
    mission_file.write_text(
        "mission dive\nvehicle ROMEO\nplace a = 1, b, c\nfinal { b }\nfinal { c }\n"
        "transition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, error: c } }\n",
        encoding="utf-8",
    )
    approved = approve_mission(mission_file, issue=True)
    assert approved.approval.path == str(default_certificate_path(mission_file))
    _sign_file(default_certificate_path(mission_file), signing_key)
    # No store given: the default one, here a folder of .pub files under XDG_CONFIG_HOME.
    store = tmp_path / "config" / "coral" / "trusted_keys"
    store.mkdir(parents=True)
    (store / "verifier.pub").write_text(signing_key.public.read_text())
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    accepted = check_mission_certificate(approved.mission)
    assert accepted.profile_digest == approved.mission.profile_digest()
    assert accepted.signer == signing_key.key.public.key_id


# -- the schedule's work times ------------------------------------------------------------


def test_timing_takes_the_missions_profile() -> None:
    mission = load_mission(SURVEY, [load_profile(MINNOW)])
    depth = next(
        t.command
        for t in mission.net.transitions
        if t.command is not None and t.command.name == "DEPTH?"
    )
    assert Timing(mission.net, profile=mission.profile).nominal_s(depth) == 60.0
    # MINNOW is not bundled: looked up by name, every command takes the default.
    assert Timing(mission.net).nominal_s(depth) == DEFAULT_WORK_S
    assert Timing(mission.net, profile=None).nominal_s(depth) == DEFAULT_WORK_S


def test_timing_still_finds_a_bundled_profile_by_name() -> None:
    mission = load_mission(POOL)
    command = Command("ROMEO", "DEPTH?", ())
    assert mission.profile is not None
    expected = mission.profile.command("DEPTH?")
    assert expected is not None and expected.duration_s != DEFAULT_WORK_S
    assert Timing(mission.net).nominal_s(command) == expected.duration_s
    assert Timing(mission.net, profile=mission.profile).nominal_s(command) == expected.duration_s


def test_timing_refuses_the_profile_of_another_vehicle() -> None:
    mission = load_mission(POOL)
    with pytest.raises(ValueError, match="not for the net's vehicle ROMEO"):
        Timing(mission.net, profile=load_profile(MINNOW))


def test_the_gate_compiles_with_an_include_path(tmp_path: Path, signing_key: TestKey) -> None:
    (tmp_path / "lib").mkdir()
    (tmp_path / "missions").mkdir()
    (tmp_path / "lib" / "common.coral").write_text(
        "place done\ntransition finish wait { start } signal { done }\n"
    )
    mission = tmp_path / "missions" / "m.coral"
    mission.write_text(
        'mission m\nvehicle ROMEO\nplace start = 1\nfinal { done }\ninclude "common.coral"\n'
    )
    cert = tmp_path / "m.cert.json"
    with pytest.raises(CompileError, match="file not found"):
        approve_mission(mission, cert, issue=True, trusted=NOBODY)
    lib = [tmp_path / "lib"]
    issued = approve_mission(mission, cert, issue=True, trusted=NOBODY, include_path=lib)
    assert issued.issued_now and "done" in issued.net.place_names
    _sign_file(cert, signing_key)
    again = approve_mission(mission, cert, trusted=signing_key.trusted, include_path=lib)
    assert again.approval.net_digest == issued.net.digest() and not again.issued_now


def test_the_gate_refuses_a_revoked_signer_and_a_known_unsound_revision(
    tmp_path: Path, signing_key: TestKey
) -> None:
    from analysis.signing import Revocation

    cert = tmp_path / "pool.cert.json"
    approve_mission(POOL, cert, issue=True, trusted=NOBODY)
    _sign_file(cert, signing_key)
    kid = signing_key.key.public.key_id
    revoked = TrustStore.of(
        [signing_key.key.public], "store", [Revocation(kid, "2026-11-24", "rotated")]
    )
    with pytest.raises(CertificateError, match=f"key {kid}, which was revoked on 2026-11-24"):
        approve_mission(POOL, cert, trusted=revoked)
    # Signed, trusted, but resting on a method with a known bug at its revision: a net
    # whose counts pass 2**60 and a certificate of revision 1 (as written before the fix).
    pump = tmp_path / "pump.coral"
    pump.write_text(
        "mission pump\nvehicle ROMEO\nplace a = 1, b\nfinal { b }\n"
        "transition t wait { a } signal { a, b*4611686018427387904 }\n"
    )
    compiled = load_mission(pump)
    old = make_certificate(
        verify(compiled.net, VerifyOptions(structural=False)),
        profile_content=compiled.profile_content(),
    )
    old.pop("checker_revision")
    old["verdict"] = "proven"
    old["properties"] = [
        {**p, "verdict": "proven", "method": "explicit state space"}
        for p in old["properties"]  # type: ignore[attr-defined]
    ]
    pump_cert = tmp_path / "pump.cert.json"
    write_certificate(sign_certificate(old, signing_key.key), pump_cert)
    with pytest.raises(CertificateError, match=r"explorer-64-bit-wrap.*re-verify"):
        approve_mission(pump, pump_cert, trusted=signing_key.trusted)


def test_issuing_verifies_through_the_check_pipeline(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``coral-run --verify`` and ``coral-check verify`` reach their verdict through
    one path (`analysis.pipeline.check_file`), so they cannot disagree on a file."""
    import analysis.pipeline

    seen: list[tuple[Path, analysis.pipeline.CheckOptions]] = []
    real = analysis.pipeline.check_file

    def spy(file: str | Path, options: analysis.pipeline.CheckOptions) -> FileOutcome:
        seen.append((Path(file), options))
        return real(file, options)

    monkeypatch.setattr(analysis.pipeline, "check_file", spy)
    minnow = load_profile(MINNOW)
    issued = approve_mission(
        SURVEY, tmp_path / "c.json", issue=True, profiles=[minnow], trusted=NOBODY
    )
    ((file, options),) = seen
    assert file == SURVEY and list(options.profiles) == [minnow]
    assert options.verify is not None
    outcome = real(SURVEY, options)
    assert outcome.report is not None and outcome.net is not None
    assert issued.net.digest() == outcome.net.digest() == issued.approval.net_digest
    # A mission that fails verification names what failed, as before.
    faulty = EXAMPLES / "faulty" / "deadlock.coral"
    with pytest.raises(CertificateError, match=r"verification did not pass \(deadlock violated"):
        approve_mission(faulty, tmp_path / "d.json", issue=True, trusted=NOBODY)
    assert [f for f, _ in seen] == [SURVEY, faulty]
