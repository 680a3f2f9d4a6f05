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
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_mission, compile_source
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
