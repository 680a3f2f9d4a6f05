"""Key revocation and rotation: revoked keys in a trust store, the refusal of what they
signed, and ``coral-check resign`` moving certificates to a new key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis import cli as check_cli
from analysis.certificate import (
    CertificateError,
    check_certificate,
    make_certificate,
    resign_certificate,
    write_certificate,
)
from analysis.signing import (
    KeyFileError,
    Revocation,
    SigningKey,
    TrustStore,
    generate_key_files,
    load_signing_key,
    load_trust_store,
    sign_certificate,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import Mission, load_mission
from runtime.gate import check_mission_certificate
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAST = VerifyOptions(structural=False)


@pytest.fixture(scope="module")
def pool() -> tuple[Mission, dict[str, object]]:
    mission = load_mission(POOL)
    report = verify(mission.net, FAST)
    return mission, make_certificate(report, FAST, profile_content=mission.profile_content())


def _keys(folder: Path, *names: str) -> list[SigningKey]:
    """Key pairs ``folder/NAME`` (+ ``.pub``), as 'coral-check keygen' makes them."""
    keys = []
    for name in names:
        generate_key_files(folder / name, name)
        keys.append(load_signing_key(folder / name))
    return keys


def _write(path: Path, certificate: dict[str, object], key: SigningKey) -> Path:
    write_certificate(sign_certificate(certificate, key), path)
    return path


def _check(mission: Mission, path: Path, trusted: TrustStore) -> str | None:
    return check_certificate(
        mission.net, path, profile_content=mission.profile_content(), trusted=trusted
    ).signer


# -- the trust store -----------------------------------------------------------------------


def test_a_folder_store_reads_revocations_from_its_revoked_file(tmp_path: Path) -> None:
    old, new = _keys(tmp_path, "old.key", "new.key")
    store = tmp_path / "trusted"
    store.mkdir()
    for name in ("old.key.pub", "new.key.pub"):
        (store / name).write_text((tmp_path / name).read_text())
    kid = old.public.key_id
    (store / "revoked").write_text(f"# lost keys\n\nrevoked {kid} 2026-11-24 laptop stolen\n")
    trusted = load_trust_store(store)
    assert set(trusted.keys) == {kid, new.public.key_id}  # still listed...
    revocation = trusted.revocation(kid)
    assert revocation is not None and revocation.reason == "laptop stolen"
    assert revocation.date == "2026-11-24" and revocation.source == f"{store / 'revoked'}:3"
    assert trusted.revocation(new.public.key_id) is None
    assert "2 trusted key(s), 1 revoked" in trusted.describe()


def test_a_file_store_holds_key_and_revocation_lines_together(tmp_path: Path) -> None:
    (old,) = _keys(tmp_path, "old.key")
    kid = old.public.key_id
    store = tmp_path / "trusted_keys"
    store.write_text(old.public.line() + f"\nrevoked {kid} 2026-01-02 rotated out\n")
    assert load_trust_store(store).revocation(kid) == Revocation(
        kid, "2026-01-02", "rotated out", f"{store}:2"
    )


@pytest.mark.parametrize(
    ("line", "complaint"),
    [
        ("revoked 0123456789abcdef 2026-11-24", "not a revocation line"),
        ("revoked 0123456789ABCDEF 2026-11-24 why", "is not a key id"),
        ("revoked 0123 2026-11-24 why", "is not a key id"),
        ("revoked 0123456789abcdef 24/11/2026 why", "is not a date"),
        ("revoked 0123456789abcdef 2026-02-30 why", "is not a date"),
    ],
)
def test_a_bad_revocation_line_is_refused_with_file_and_line(
    tmp_path: Path, line: str, complaint: str
) -> None:
    store = tmp_path / "trusted"
    store.mkdir()
    (store / "revoked").write_text(f"\n{line}\n")
    with pytest.raises(KeyFileError, match=complaint) as refused:
        load_trust_store(store)
    assert f"{store / 'revoked'}:2" in str(refused.value)


def test_a_key_line_in_the_revoked_file_is_refused(tmp_path: Path) -> None:
    (key,) = _keys(tmp_path, "k")
    store = tmp_path / "trusted"
    store.mkdir()
    (store / "revoked").write_text(key.public.line() + "\n")
    with pytest.raises(KeyFileError, match="holds only revocation lines"):
        load_trust_store(store)


# -- refusals ------------------------------------------------------------------------------


def test_a_certificate_signed_by_a_revoked_key_is_refused_even_if_trusted(
    tmp_path: Path, pool: tuple[Mission, dict[str, object]]
) -> None:
    mission, certificate = pool
    (key,) = _keys(tmp_path, "k")
    path = _write(tmp_path / "pool.cert.json", certificate, key)
    kid = key.public.key_id
    revocation = Revocation(kid, "2026-11-24", "key leaked in a log", "trusted/revoked:1")
    assert _check(mission, path, TrustStore.of([key.public])) == kid
    for trusted in (
        TrustStore.of([key.public], "trusted", [revocation]),  # listed and revoked
        TrustStore.of([], "trusted", [revocation]),  # revoked only
    ):
        with pytest.raises(CertificateError) as refused:
            check_mission_certificate(mission, path, trusted=trusted)
        message = str(refused.value)
        assert f"signed by key {kid}, which was revoked on 2026-11-24" in message
        assert "key leaked in a log" in message and "trusted/revoked:1" in message
        assert "not trusted here" not in message  # its own refusal, not "unknown key"


# -- rotation ------------------------------------------------------------------------------


def test_rotation_resign_then_revoke(
    tmp_path: Path, pool: tuple[Mission, dict[str, object]], capsys: pytest.CaptureFixture[str]
) -> None:
    mission, certificate = pool
    old, new = _keys(tmp_path, "old.key", "new.key")
    store = tmp_path / "trusted"
    store.mkdir()
    (store / "old.key.pub").write_text((tmp_path / "old.key.pub").read_text())
    cert = _write(tmp_path / "pool.cert.json", certificate, old)
    before = json.loads(cert.read_text())
    # 1. The new key joins the store; 2. the certificate is re-signed with it.
    (store / "new.key.pub").write_text((tmp_path / "new.key.pub").read_text())
    argv = ["resign", str(cert), "--signing-key", str(tmp_path / "new.key")]
    assert check_cli.main([*argv, "--trusted-keys", str(store)]) == 0
    assert f"re-signed by key {new.public.key_id} (was {old.public.key_id})" in (
        capsys.readouterr().err
    )
    after = json.loads(cert.read_text())
    assert after["signature"]["key_id"] == new.public.key_id
    assert {k: v for k, v in after.items() if k != "signature"} == {
        k: v for k, v in before.items() if k != "signature"
    }  # only the signature changed
    assert not list(tmp_path.glob(".*.tmp"))  # written by rename, nothing left behind
    # 3. The old key is revoked: the re-signed certificate passes, the old one does not.
    (store / "revoked").write_text(f"revoked {old.public.key_id} 2026-11-24 rotation\n")
    trusted = load_trust_store(store)
    assert _check(mission, cert, trusted) == new.public.key_id
    stale = _write(tmp_path / "stale.cert.json", certificate, old)
    with pytest.raises(CertificateError, match="was revoked on 2026-11-24 \\(rotation"):
        _check(mission, stale, trusted)
    # ...and can no longer be re-signed: it must be verified again.
    resign_stale = ["resign", str(stale), "--signing-key", str(tmp_path / "new.key")]
    assert check_cli.main([*resign_stale, "--trusted-keys", str(store)]) == 2
    assert "not re-signed" in capsys.readouterr().err


def test_resign_checks_the_present_signature_first(
    tmp_path: Path, pool: tuple[Mission, dict[str, object]]
) -> None:
    _, certificate = pool
    old, new, stranger = _keys(tmp_path, "old", "new", "stranger")
    trusted = TrustStore.of([old.public, new.public], "store")
    unsigned = tmp_path / "unsigned.json"
    write_certificate(certificate, unsigned)
    with pytest.raises(CertificateError, match="is not signed"):
        resign_certificate(unsigned, new, trusted)
    foreign = _write(tmp_path / "foreign.json", certificate, stranger)
    with pytest.raises(CertificateError, match="not trusted here"):
        resign_certificate(foreign, new, trusted)
    edited = _write(tmp_path / "edited.json", certificate, old)
    data = json.loads(edited.read_text())
    data["expires"] = "2099-01-01T00:00:00Z"
    edited.write_text(json.dumps(data))
    with pytest.raises(CertificateError, match="does not match the content"):
        resign_certificate(edited, new, trusted)
    good = _write(tmp_path / "good.json", certificate, old)
    revoked_new = TrustStore.of(
        [old.public], "store", [Revocation(new.public.key_id, "2026-11-24", "lost")]
    )
    with pytest.raises(CertificateError, match=r"the new signing key .* is revoked"):
        resign_certificate(good, new, revoked_new)
    assert resign_certificate(good, new, trusted)["signature"]["key_id"] == (  # type: ignore[index]
        new.public.key_id
    )


def test_resign_usage_errors_exit_2(
    tmp_path: Path,
    pool: tuple[Mission, dict[str, object]],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _, certificate = pool
    (old,) = _keys(tmp_path, "old")
    cert = _write(tmp_path / "c.json", certificate, old)
    monkeypatch.delenv("CORAL_SIGNING_KEY", raising=False)
    store = str(tmp_path / "old.pub")
    assert check_cli.main(["resign", str(cert), "--trusted-keys", store]) == 2
    assert "no signing key" in capsys.readouterr().err
    key = str(tmp_path / "old")
    for argv in (
        ["resign"],
        ["resign", str(tmp_path / "missing.json"), "--signing-key", key, "--trusted-keys", store],
        ["resign", str(cert), "--signing-key", key, "--trusted-keys", str(tmp_path / "none")],
        ["resign", str(cert), "--signing-key", str(tmp_path / "nokey"), "--trusted-keys", store],
        ["resign", str(cert), "--signing-key", key, "--trusted-keys", store, "-o", str(tmp_path)],
    ):
        assert check_cli.main(argv) == 2, argv
    err = capsys.readouterr().err
    assert "no certificate" in err and "no such trusted keys file" in err
    assert "no such signing key" in err and "it is a directory" in err
    assert "Traceback" not in err
    out = tmp_path / "copy.json"
    argv = ["resign", str(cert), "--signing-key", key, "--trusted-keys", store, "-o", str(out)]
    assert check_cli.main(argv) == 0
    assert json.loads(out.read_text()) == json.loads(cert.read_text())  # same key: same bytes
