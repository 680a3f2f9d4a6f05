"""coral-check as a function: help text, exit codes, diagnostics on stderr."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.cli import build_parser, main
from tests.conftest import EXAMPLES

POOL = str(EXAMPLES / "pool_mission" / "pool_mission.coral")


def test_help_names_the_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "usage: coral-check" in out and "exit codes: 0 clean" in out
    assert build_parser().prog == "coral-check"


def test_clean_mission_exits_0_and_prints_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([POOL]) == 0
    out = capsys.readouterr().out
    assert "ok, net 'pool_mission'" in out and "digest sha256:" in out


def test_mission_with_errors_exits_1_and_prints_diagnostics(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([str(EXAMPLES / "faulty" / "unhandled_reply.coral")]) == 1
    err = capsys.readouterr().err
    assert "unhandled_reply.coral:20:20: error:" in err and "[CORAL106]" in err and "^~~~~~" in err


def test_missing_file_and_bad_usage_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main([str(tmp_path / "nope.coral")]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert main([]) == 2
    assert main(["--no-such-flag", POOL]) == 2


def test_bad_profile_exits_2_naming_the_field(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicle: ROMEO\ncommands: {DEPTH: {kind: taks, replies: [ack]}}\n")
    assert main(["--profile", str(bad), POOL]) == 2
    assert "commands.DEPTH.kind" in capsys.readouterr().err


def test_worst_exit_code_wins_over_several_files(tmp_path: Path) -> None:
    assert main([POOL, str(EXAMPLES / "faulty" / "unhandled_reply.coral")]) == 1
    assert main([POOL, str(tmp_path / "missing.coral")]) == 2
