"""Signed certificates: keys, the trust store, and every reason a run refuses one.

The forgery of issue 17 is here end to end: a mission that deadlocks is verified (and
fails), its certificate is edited to say ``proven``, and ``coral-run`` refuses it.
"""

from __future__ import annotations

import base64
import datetime as dt
import hashlib
import json
import os
import stat
from pathlib import Path

import pytest

from analysis import cli as check_cli
from analysis import signing
from analysis.certificate import (
    CertificateError,
    check_certificate,
    make_certificate,
    overall_verdict,
    parse_expires,
    write_certificate,
)
from analysis.report import Report
from analysis.signing import (
    KeyFileError,
    SigningKey,
    TrustStore,
    canonical_bytes,
    generate_key_files,
    load_signing_key,
    load_trust_store,
    resolve_trust_store,
    sign_certificate,
    signing_key_from_env,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import Mission, load_mission
from runtime.cli import main as coral_run
from tests.conftest import EXAMPLES, TestKey

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
DEADLOCK = EXAMPLES / "faulty" / "deadlock.coral"
FIXED = dt.datetime(2026, 11, 21, 7, 0, 0, tzinfo=dt.UTC)
FAST = VerifyOptions(structural=False)


@pytest.fixture(scope="module")
def pool() -> tuple[Mission, Report]:
    mission = load_mission(POOL)
    return mission, verify(mission.net, FAST)


def _certificate(pool: tuple[Mission, Report], **changes: object) -> dict[str, object]:
    mission, report = pool
    certificate = make_certificate(
        report, FAST, clock=lambda: FIXED, profile_content=mission.profile_content()
    )
    certificate.update(changes)
    return certificate


def _check(
    mission: Mission, path: Path, trusted: TrustStore, now: dt.datetime = FIXED
) -> str | None:
    return check_certificate(
        mission.net,
        path,
        profile_content=mission.profile_content(),
        trusted=trusted,
        clock=lambda: now,
    ).signer


def _refusal(mission: Mission, path: Path, trusted: TrustStore, now: dt.datetime = FIXED) -> str:
    with pytest.raises(CertificateError) as refused:
        _check(mission, path, trusted, now)
    return str(refused.value)


# -- keys --------------------------------------------------------------------------------


def test_keygen_writes_a_private_key_only_its_owner_reads_and_a_one_line_public_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "verifier.key"
    assert check_cli.main(["keygen", "--out", str(key), "--comment", "lab verifier"]) == 0
    out = capsys.readouterr().out
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    assert key.read_text().startswith("-----BEGIN PRIVATE KEY-----")
    line = (tmp_path / "verifier.key.pub").read_text()
    kind, encoded, comment = line.rstrip("\n").split(" ", 2)
    assert (kind, comment) == ("coral-ed25519", "lab verifier") and line.count("\n") == 1
    raw = base64.b64decode(encoded)
    assert len(raw) == 32
    key_id = hashlib.sha256(raw).hexdigest()[:16]
    assert f"key id: {key_id}" in out
    assert load_signing_key(key).public.key_id == key_id
    assert set(load_trust_store(tmp_path / "verifier.key.pub").keys) == {key_id}


def test_keygen_never_overwrites_a_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    key = tmp_path / "k"
    assert check_cli.main(["keygen", "--out", str(key)]) == 0
    before = key.read_bytes()
    assert check_cli.main(["keygen", "--out", str(key)]) == 2
    assert f"{key}: exists already" in capsys.readouterr().err
    assert key.read_bytes() == before
    key.unlink()  # the .pub alone still blocks: it would pair with a key it does not match
    assert check_cli.main(["keygen", "--out", str(key)]) == 2
    assert "k.pub: exists already" in capsys.readouterr().err
    assert check_cli.main(["keygen", "--out", str(tmp_path / "no" / "k")]) == 2
    assert "no such folder" in capsys.readouterr().err


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o644])
def test_a_private_key_others_can_read_is_refused_with_the_fix(tmp_path: Path, mode: int) -> None:
    key = tmp_path / "k"
    generate_key_files(key, "t")
    key.chmod(mode)
    with pytest.raises(KeyFileError) as refused:
        load_signing_key(key)
    message = str(refused.value)
    assert "accessible by group or others" in message and f"chmod 600 {key}" in message
    key.chmod(0o600)
    assert (
        load_signing_key(key).public.raw
        == next(iter(load_trust_store(f"{key}.pub").keys.values())).raw
    )


def test_bad_key_files_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(
        KeyFileError, match="no such signing key; create one with 'coral-check keygen"
    ):
        load_signing_key(tmp_path / "absent")
    junk = tmp_path / "junk"
    fd = os.open(junk, os.O_WRONLY | os.O_CREAT, 0o600)
    os.write(fd, b"not a key")
    os.close(fd)
    with pytest.raises(KeyFileError, match="junk: not a usable signing key"):
        load_signing_key(junk)


def test_verify_refuses_an_open_key_before_verifying(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "k"
    generate_key_files(key, "t")
    key.chmod(0o644)
    cert = tmp_path / "c.json"
    argv = ["verify", str(POOL), "--certificate", str(cert), "--signing-key", str(key)]
    assert check_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "chmod 600" in err and "Traceback" not in err and not cert.exists()


def test_the_key_can_come_from_the_environment(tmp_path: Path, signing_key: TestKey) -> None:
    assert signing_key_from_env({}) is None
    by_path = signing_key_from_env({"CORAL_SIGNING_KEY": str(signing_key.private)})
    by_text = signing_key_from_env({"CORAL_SIGNING_KEY": signing_key.private.read_text()})
    assert by_path is not None and by_text is not None
    assert by_path.public.raw == by_text.public.raw == signing_key.key.public.raw
    assert check_cli.SIGNING_KEY_ENV == signing.SIGNING_KEY_ENV


def test_trust_store_file_or_folder_and_bad_lines_named(tmp_path: Path) -> None:
    first, second = SigningKey.generate("a"), SigningKey.generate("b")
    folder = tmp_path / "trusted"
    folder.mkdir()
    (folder / "a.pub").write_text(f"# the lab\n\n{first.public.line()}\n")
    (folder / "b.pub").write_text(second.public.line() + "\n")
    (folder / "notes.txt").write_text("not read: only .pub files are\n")
    store = load_trust_store(folder)
    assert set(store.keys) == {first.public.key_id, second.public.key_id}
    bad = tmp_path / "bad"
    bad.write_text(f"{first.public.line()}\nssh-ed25519 AAAA x\n")
    with pytest.raises(KeyFileError, match=f"{bad}:2: not a public key line"):
        load_trust_store(bad)
    bad.write_text("coral-ed25519 AAAA x\n")
    with pytest.raises(KeyFileError, match="32 bytes, not 3"):
        load_trust_store(bad)
    with pytest.raises(KeyFileError, match="no such trusted keys file"):
        load_trust_store(tmp_path / "absent")


def test_the_default_trust_store_is_used_only_if_it_exists(tmp_path: Path) -> None:
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    assert resolve_trust_store(None, env).keys == {}
    key = SigningKey.generate("x")
    (tmp_path / "coral").mkdir()
    (tmp_path / "coral" / "trusted_keys").write_text(key.public.line() + "\n")
    assert set(resolve_trust_store(None, env).keys) == {key.public.key_id}


# -- signing and checking -----------------------------------------------------------------


def test_sign_and_check_roundtrip_whatever_the_layout(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    signed = sign_certificate(_certificate(pool), signing_key.key)
    assert signed["signature"] == {
        "algorithm": "ed25519",
        "key_id": signing_key.key.public.key_id,
        "value": signed["signature"]["value"],  # type: ignore[index]
    }
    path = tmp_path / "c.json"
    write_certificate(signed, path)
    assert _check(mission, path, signing_key.trusted) == signing_key.key.public.key_id
    # Indentation and key order are not content: the canonical JSON is what is signed.
    path.write_text(json.dumps(dict(reversed(list(signed.items())))))
    assert _check(mission, path, signing_key.trusted) == signing_key.key.public.key_id
    assert b" " not in canonical_bytes({"a": [1, 2], "b": {"c": "d"}})
    assert canonical_bytes(signed) == canonical_bytes(_certificate(pool))


def test_cli_signs_and_says_when_it_does_not(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    signing_key: TestKey,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("CORAL_SIGNING_KEY", raising=False)
    mission = load_mission(POOL)
    cert = tmp_path / "c.json"
    base = ["verify", str(POOL), "--no-structure", "--certificate", str(cert), "-o", os.devnull]
    assert check_cli.main(base) == 0
    assert "UNSIGNED" in capsys.readouterr().err
    assert "is not signed" in _refusal(mission, cert, signing_key.trusted, dt.datetime.now(dt.UTC))
    assert check_cli.main([*base, "--signing-key", str(signing_key.private), "--expires", "3"]) == 0
    assert f"signed by key {signing_key.key.public.key_id}" in capsys.readouterr().err
    now = dt.datetime.now(dt.UTC)
    assert _check(mission, cert, signing_key.trusted, now) == signing_key.key.public.key_id
    assert "expired" in _refusal(mission, cert, signing_key.trusted, now + dt.timedelta(days=4))


def test_unsigned_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    path = tmp_path / "c.json"
    write_certificate(_certificate(pool), path)
    message = _refusal(mission, path, signing_key.trusted)
    assert "is not signed" in message and "--signing-key" in message and "--verify" in message
    # Without a trust store (coral-check reading what it claims) the content still passes.
    assert check_certificate(mission.net, path).signer is None


def test_an_unknown_signer_is_named_by_key_id(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    stranger = SigningKey.generate("someone else")
    path = tmp_path / "c.json"
    write_certificate(sign_certificate(_certificate(pool), stranger), path)
    message = _refusal(mission, path, signing_key.trusted)
    assert f"signed by key {stranger.public.key_id}, which is not trusted" in message
    assert "1 trusted key(s)" in message


@pytest.mark.parametrize(
    "edit",
    [
        lambda c: c.update(issued="2020-01-01T00:00:00Z"),
        lambda c: c["options"].update(max_states=1),
        lambda c: c.update(expires="2099-01-01T00:00:00Z"),
        lambda c: c["signature"].update(value=base64.b64encode(b"x" * 64).decode()),
        lambda c: c["signature"].update(value="not base64!"),
    ],
    ids=["issued", "options", "expiry-added", "other-signature", "garbage-signature"],
)
def test_content_edited_after_signing_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey, edit: object
) -> None:
    mission, _ = pool
    signed = sign_certificate(_certificate(pool), signing_key.key)
    edit(signed)  # type: ignore[operator]
    path = tmp_path / "c.json"
    write_certificate(signed, path)
    message = _refusal(mission, path, signing_key.trusted)
    assert "edited after it was signed" in message


def test_a_field_added_to_the_signature_block_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    """The block is outside the signed content, so the signature still verifies; an
    extra field in it is an edit no signer made (found by bench/redteam.py)."""
    mission, _ = pool
    signed = sign_certificate(_certificate(pool), signing_key.key)
    block = signed["signature"]
    assert isinstance(block, dict)
    block["key_id_extra"] = "x"
    path = tmp_path / "c.json"
    write_certificate(signed, path)
    message = _refusal(mission, path, signing_key.trusted)
    assert "'signature' has fields no signer writes ('key_id_extra')" in message


def test_an_expired_certificate_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, report = pool
    certificate = make_certificate(
        report,
        FAST,
        clock=lambda: FIXED,
        profile_content=mission.profile_content(),
        expires=FIXED + dt.timedelta(days=30),
    )
    assert certificate["expires"] == "2026-12-21T07:00:00Z"
    path = tmp_path / "c.json"
    write_certificate(sign_certificate(certificate, signing_key.key), path)
    assert _check(mission, path, signing_key.trusted, FIXED + dt.timedelta(days=29)) is not None
    message = _refusal(mission, path, signing_key.trusted, FIXED + dt.timedelta(days=30))
    assert "expired at 2026-12-21T07:00:00Z" in message


def test_parse_expires() -> None:
    assert parse_expires("30", FIXED) == FIXED + dt.timedelta(days=30)
    assert parse_expires("2026-12-31", FIXED) == dt.datetime(
        2026, 12, 31, 23, 59, 59, tzinfo=dt.UTC
    )
    assert parse_expires("2027-01-01T12:00:00Z", FIXED).hour == 12
    for bad, why in [
        ("2020-01-01", "not in the future"),
        ("0", "not in the future"),
        ("soon", "number of days"),
    ]:
        with pytest.raises(ValueError, match=why):
            parse_expires(bad, FIXED)


def test_bad_expires_and_orphan_options_are_usage_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = str(tmp_path / "c.json")
    assert check_cli.main(["verify", str(POOL), "--certificate", cert, "--expires", "soon"]) == 2
    assert "--expires: expected a number of days" in capsys.readouterr().err
    assert check_cli.main(["verify", str(POOL), "--expires", "3"]) == 2
    assert "--expires applies to --certificate FILE" in capsys.readouterr().err
    assert not Path(cert).exists()


def test_a_certificate_for_another_net_does_not_show_the_expected_digest(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    other = "sha256:" + "ab" * 32
    path = tmp_path / "c.json"
    write_certificate(sign_certificate(_certificate(pool, net_digest=other), signing_key.key), path)
    message = _refusal(mission, path, signing_key.trusted)
    assert "is for another net (its digest begins sha256:abababababab)" in message
    assert mission.net.digest() not in message and mission.net.digest()[7:19] not in message
    assert other not in message  # not even its own in full


def test_a_certificate_for_another_profile_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    certificate = _certificate(pool)
    profile = json.loads(json.dumps(certificate["profile"]))
    command = next(iter(profile["commands"].values()))
    command["duration_s"] = 12345.0
    certificate["profile"] = profile
    path = tmp_path / "c.json"
    write_certificate(sign_certificate(certificate, signing_key.key), path)
    assert "changed since certification" in _refusal(mission, path, signing_key.trusted)


def test_every_property_verdict_is_read_not_only_the_summary(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    """Signed by a trusted key yet inconsistent (a buggy or old signer): the summary
    says proven, a required property does not, or one is missing: refused."""
    mission, _ = pool
    path = tmp_path / "c.json"

    def signed_with(properties: list[dict[str, object]], verdict: str = "proven") -> str:
        certificate = _certificate(pool, properties=properties, verdict=verdict)
        write_certificate(sign_certificate(certificate, signing_key.key), path)
        return _refusal(mission, path, signing_key.trusted)

    listed = _certificate(pool)["properties"]
    assert isinstance(listed, list)
    violated = [dict(p, verdict="violated") if p["key"] == "deadlock" else p for p in listed]
    assert "deadlock violated" in signed_with(violated)
    # Marking it not required does not help: a deadlock-free run is always required.
    unrequired = [dict(p, required=False) if p["key"] == "deadlock" else p for p in violated]
    assert "deadlock violated" in signed_with(unrequired)
    assert "deadlock missing" in signed_with([p for p in listed if p["key"] != "deadlock"])
    assert "inconclusive" in signed_with(listed, verdict="inconclusive")


@pytest.mark.slow
def test_the_summary_verdict_is_derived_from_the_properties(tmp_path: Path) -> None:
    """A search cut short by its budget leaves properties inconclusive, so the
    certificate cannot say proven, whatever else is true."""
    mission = load_mission(POOL)
    report = verify(mission.net, VerifyOptions(structural=False, max_states=5))
    certificate = make_certificate(report, VerifyOptions(structural=False, max_states=5))
    assert certificate["search"] == {
        "states": report.statespace.states,
        "complete": False,
        "stopped_reason": report.statespace.stopped_reason,
    }
    assert certificate["verdict"] != "proven"
    assert certificate["options"]["max_states"] == 5  # type: ignore[index]
    assert (
        overall_verdict([{"verdict": "proven"}, {"verdict": "violated", "required": False}])
        == "proven"
    )
    assert overall_verdict([{"verdict": "proven"}, {"verdict": "inconclusive"}]) == "inconclusive"
    assert overall_verdict([{"verdict": "PROVEN"}]) == "violated"


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"format": True}, "format must be the integer 1, found true"),
        ({"format": 1.0}, "format must be the integer 1, found 1.0"),
        ({"format": "1"}, 'format must be the integer 1, found "1"'),
        ({"properties": 5}, "'properties' must be a list (found int)"),
        ({"properties": [5]}, "properties[1] is not an object"),
        (
            {"properties": [{"key": "deadlock", "verdict": 1}]},
            "properties[1].verdict must be a string",
        ),
        (
            {"properties": [{"key": "deadlock", "verdict": "proven", "required": "yes"}]},
            "required must be true or false",
        ),
        ({"net_digest": None}, "'net_digest' must be a string (found NoneType)"),
        ({"signature": "abc"}, "'signature' must be an object"),
        ({"signature": {"algorithm": "rsa", "key_id": "x", "value": "y"}}, 'algorithm "ed25519"'),
        ({"expires": "next week"}, "'expires' must be a UTC time"),
        ({"profile": [1]}, "'profile' must be an object"),
    ],
)
def test_malformed_certificates_name_the_field(
    tmp_path: Path,
    pool: tuple[Mission, Report],
    signing_key: TestKey,
    changes: dict[str, object],
    message: str,
) -> None:
    mission, _ = pool
    certificate = sign_certificate(_certificate(pool), signing_key.key)
    certificate.update(changes)
    path = tmp_path / "c.json"
    write_certificate(certificate, path)
    assert message in _refusal(mission, path, signing_key.trusted)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
        ('{"format": 1, "format": 1}', "duplicate key 'format'"),
        ('{"format": NaN}', "NaN is not JSON"),
        ("[1]", "not a JSON object"),
        ("\xff", "not a readable certificate"),
    ],
    ids=["deep", "duplicate", "nan", "list", "bytes"],
)
def test_unreadable_certificates_are_clear_errors(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey, text: str, message: str
) -> None:
    mission, _ = pool
    path = tmp_path / "c.json"
    path.write_bytes(text.encode("latin-1"))
    assert message in _refusal(mission, path, signing_key.trusted)


def test_deep_nesting_inside_a_valid_certificate_is_refused(
    tmp_path: Path, pool: tuple[Mission, Report], signing_key: TestKey
) -> None:
    mission, _ = pool
    text = json.dumps(sign_certificate(_certificate(pool), signing_key.key))
    deep = "[" * 100_000 + "]" * 100_000
    path = tmp_path / "c.json"
    path.write_text(text[:-1] + f', "extra": {deep}}}')
    assert "nested too deeply" in _refusal(mission, path, signing_key.trusted)


# -- coral-run ------------------------------------------------------------------------------


def test_the_forgery_of_issue_17_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], signing_key: TestKey
) -> None:
    """Verify a mission that deadlocks (it fails), edit every verdict to proven, run."""
    cert = tmp_path / "deadlock.certificate.json"
    argv = ["verify", str(DEADLOCK), "--no-structure", "--certificate", str(cert)]
    assert check_cli.main([*argv, "--signing-key", str(signing_key.private), "-o", os.devnull]) == 1
    data = json.loads(cert.read_text())
    assert data["verdict"] == "violated"
    text = cert.read_text().replace('"verdict": "violated"', '"verdict": "proven"')
    text = text.replace('"verdict": "inconclusive"', '"verdict": "proven"')
    assert '"violated"' not in text
    cert.write_text(text)
    run = [str(DEADLOCK), "--certificate", str(cert), "--no-plots", "-q"]
    trusted = ["--trusted-keys", str(signing_key.public)]
    assert coral_run([*run, *trusted, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "edited after it was signed" in err and "Traceback" not in err
    assert not (tmp_path / "a" / "controller.sqlite").exists()
    # The same forgery with the signature removed: unsigned, refused too.
    del data["signature"]
    data["verdict"] = "proven"
    for p in data["properties"]:
        p["verdict"] = "proven"
    write_certificate(data, cert)
    assert coral_run([*run, *trusted, "--out", str(tmp_path / "b")]) == 2
    assert "is not signed" in capsys.readouterr().err
    assert not (tmp_path / "b" / "controller.sqlite").exists()


def test_coral_run_trusted_keys_errors_are_input_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "keys"
    bad.write_text("hello\n")
    base = [str(POOL), "--out", str(tmp_path / "run"), "--no-plots", "-q"]
    assert coral_run([*base, "--trusted-keys", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:1: not a public key line" in err and "Traceback" not in err
    assert coral_run([*base, "--trusted-keys", str(tmp_path / "absent")]) == 2
    assert "no such trusted keys file" in capsys.readouterr().err


@pytest.mark.slow
def test_verify_runs_without_a_key_and_its_certificate_needs_verify_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "no-config"))
    cert = tmp_path / "pool.json"
    base = [str(POOL), "--certificate", str(cert), "--no-plots", "-q", "--time-limit", "5"]
    # Exit 1: the short time limit ends the run, but it ran (the gate approved it).
    assert coral_run([*base, "--verify", "--out", str(tmp_path / "a")]) == 1
    assert "certificate written" in capsys.readouterr().out
    assert "signature" not in json.loads(cert.read_text())
    assert coral_run([*base, "--out", str(tmp_path / "b")]) == 2
    assert "is not signed" in capsys.readouterr().err
    assert coral_run([*base, "--verify", "--out", str(tmp_path / "c")]) == 1


def test_an_oversized_certificate_is_refused_unread(
    tmp_path: Path,
    pool: tuple[Mission, Report],
    signing_key: TestKey,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from analysis import certificate as certificate_module

    mission, _ = pool
    path = tmp_path / "c.json"
    write_certificate(sign_certificate(_certificate(pool), signing_key.key), path)
    monkeypatch.setattr(certificate_module, "MAX_CERTIFICATE_BYTES", 100)
    assert "too large for a certificate" in _refusal(mission, path, signing_key.trusted)
