"""``coral-check verify --timed`` and ``check --timed``: options, exit codes, schedules.

The analyser is the stub of `tests.analysis.test_timed_report` (a hand-made report), so
these tests are about the command line: which link and budget reach the analyser, what
each verdict does to the exit code, the schedule files written, and every usage error.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis.cli import main
from analysis.report import Verdict
from analysis.timed import read_schedule
from coral_lang.linkprofile import BUILTIN_PROFILES
from tests.analysis.test_timed_report import (
    LINK,
    POOL,
    install_stub,
    pool_with_deadline,
    timed_report,
    validate_document,
)

DEFAULT_BOUNDS = BUILTIN_PROFILES["genoa-lisbon"].analysis_bounds()
QUICK = ["--no-config", "--no-structure"]


def test_verify_timed_uses_the_default_link_and_a_warning_exits_0(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    stub = install_stub(monkeypatch, timed_report(query=Verdict.VIOLATED))
    mission = pool_with_deadline(tmp_path)
    assert main(["verify", str(mission), "--timed", *QUICK]) == 0
    (call,) = stub.calls
    assert call[2].link == DEFAULT_BOUNDS and call[2].max_states == 200_000
    out = capsys.readouterr().out
    assert "Timing (timed analysis):" in out
    assert "WARNING       Time-out of check_depth (DEPTH?, 30 s) is adequate" in out


def test_a_missed_deadline_exits_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    install_stub(monkeypatch, timed_report(deadline=Verdict.VIOLATED))
    assert main(["verify", str(pool_with_deadline(tmp_path)), "--timed", *QUICK]) == 1
    assert "assert:4 within 600 s { mission_complete }: missed" in capsys.readouterr().out


def test_untimed_a_deadline_is_inconclusive_and_exits_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["verify", str(pool_with_deadline(tmp_path)), *QUICK]) == 3
    out = capsys.readouterr().out
    assert "decided by timed analysis: run coral-check verify --timed" in out
    assert "Timing" not in out


@pytest.mark.parametrize("command", [["check"], []])
def test_check_and_the_shorthand_take_timed_options(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    argv = [*command, str(POOL / "pool_mission.coral"), "--timed", "--link", "lan"]
    assert main([*argv, "--timed-states", "77", "--format", "json", *QUICK]) == 0
    (call,) = stub.calls
    assert call[2].link == BUILTIN_PROFILES["lan"].analysis_bounds()
    assert call[2].max_states == 77
    report = json.loads(capsys.readouterr().out)["files"][0]["report"]
    assert report["timed"]["link"] == LINK.to_json()  # the stub's answer, unchanged


def test_a_link_profile_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    link = tmp_path / "slow.yaml"
    link.write_text("base: lan\nanalysis_max_delay_s: 4.5\n", encoding="utf-8")
    argv = ["verify", str(POOL / "pool_mission.coral"), "--timed", "--link", str(link)]
    assert main([*argv, *QUICK]) == 0
    (call,) = stub.calls
    assert call[2].link.name == "slow" and call[2].link.max_delay_s == 4.5
    # The link profile was read: no output may replace it.
    capsys.readouterr()
    assert main([*argv, *QUICK, "-o", str(link)]) == 2
    assert "is the link profile" in capsys.readouterr().err
    assert "analysis_max_delay_s: 4.5" in link.read_text(encoding="utf-8")


def test_the_config_file_may_turn_timed_analysis_on(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    config = tmp_path / "coral.toml"
    config.write_text('timed = true\nlink = "ideal"\ntimed-states = 9\n', encoding="utf-8")
    mission = str(POOL / "pool_mission.coral")
    assert main(["verify", mission, "--config", str(config), "--no-structure"]) == 0
    (call,) = stub.calls
    assert call[2].link.name == "ideal" and call[2].max_states == 9
    # --no-timed wins over the file; lint never times anything.
    assert main(["verify", mission, "--config", str(config), "--no-timed", "--no-structure"]) == 0
    assert main(["lint", mission, "--config", str(config)]) == 0
    assert len(stub.calls) == 1


def test_export_schedules_writes_stable_names_that_read_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    report = timed_report(deadline=Verdict.VIOLATED)
    install_stub(monkeypatch, report)
    folder = tmp_path / "out" / "schedules"  # made, parents too
    argv = ["verify", str(pool_with_deadline(tmp_path)), "--timed", *QUICK]
    assert main([*argv, "--export-schedules", str(folder)]) == 1
    names = sorted(p.name for p in folder.iterdir())
    assert names == [
        "best-mission_complete.json",
        "deadline-assert-4.json",
        "timeout-check_depth.json",
        "worst-mission_complete.json",
    ]
    assert read_schedule(folder / "worst-mission_complete.json") == report.finals[0].worst
    assert read_schedule(folder / "best-mission_complete.json") == report.finals[0].best
    assert read_schedule(folder / "timeout-check_depth.json") == report.queries[1].counterexample
    assert read_schedule(folder / "deadline-assert-4.json") == report.deadlines[0].counterexample
    assert "4 schedule(s) written to" in capsys.readouterr().err


def test_export_schedules_refuses_to_overwrite_another_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    install_stub(monkeypatch, timed_report())
    folder = tmp_path / "schedules"
    argv = ["verify", str(POOL / "pool_mission.coral"), "--timed", *QUICK]
    output = folder / "worst-mission_complete.json"
    folder.mkdir()
    assert main([*argv, "--export-schedules", str(folder), "-o", str(output)]) == 2
    assert "are the same file" in capsys.readouterr().err
    assert not output.exists()


def test_a_timed_certificate_from_the_command_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    install_stub(monkeypatch, timed_report())
    certificate = tmp_path / "c.json"
    argv = ["verify", str(POOL / "pool_mission.coral"), "--timed", *QUICK]
    assert main([*argv, "--certificate", str(certificate)]) == 0
    data = json.loads(certificate.read_text(encoding="utf-8"))
    assert data["timed"]["worst_s"] == 402.7
    assert data["timed"]["profiles"][0]["vehicle"] == "ROMEO"
    assert data["options"]["timed"]["link"] == DEFAULT_BOUNDS.to_json()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--timed", "--link", "genoa-lisbn"], "did you mean 'genoa-lisbon'?"),
        (["--timed", "--timed-states", "0"], "--timed-states: must be at least 1"),
        (["--timed", "--export-schedules", "{file}"], "it is a file"),
        (["--link", "lan"], "--link applies to --timed; add it"),
        (["--timed-states", "5"], "--timed-states applies to --timed; add it"),
        (["--export-schedules", "{dir}"], "--export-schedules applies to --timed; add it"),
    ],
)
def test_option_errors_exit_2(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    options: list[str],
    message: str,
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    a_file = tmp_path / "file.txt"
    a_file.write_text("x", encoding="utf-8")
    options = [o.format(file=a_file, dir=tmp_path / "d") for o in options]
    assert main(["verify", str(POOL / "pool_mission.coral"), *options, *QUICK]) == 2
    assert message in capsys.readouterr().err
    assert not stub.calls  # refused before any analysis


# -- end to end, with the real analyser ------------------------------------------------


def test_the_pool_mission_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "schedules"
    argv = ["verify", str(POOL / "pool_mission.coral"), "--timed", "--format", "json", *QUICK]
    assert main([*argv, "--export-schedules", str(folder)]) == 0
    document = validate_document(json.loads(capsys.readouterr().out))
    report = document["files"][0]["report"]
    verdicts = {p["key"]: p["verdict"] for p in report["properties"]}
    assert verdicts["timed:bounds"] == "proven"
    assert verdicts["timed:timeout:check_depth"] == "proven"
    timed = report["timed"]
    assert timed["complete"] and timed["link"] == DEFAULT_BOUNDS.to_json()
    (complete,) = [f for f in timed["finals"] if f["final"] == {"mission_complete": 1}]
    assert 0 < complete["best_s"] < complete["worst_s"]
    worst = read_schedule(folder / "worst-mission_complete.json")
    assert worst.kind == "worst-case" and worst.duration_s == pytest.approx(complete["worst_s"])
    assert worst.final == {"mission_complete": 1}


def test_a_deadline_end_to_end_and_a_pnml_net_without_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission = pool_with_deadline(tmp_path)  # an INIT error ends the mission unfinished
    assert main(["verify", str(mission), "--timed", *QUICK]) == 1
    assert "assert:4 within 600 s { mission_complete }: missed" in capsys.readouterr().out
    pnml = tmp_path / "pool.pnml"
    assert (
        main(["export", str(POOL / "pool_mission.coral"), "--pnml", str(pnml), "--no-config"]) == 0
    )
    assert main(["verify", str(pnml), "--timed", *QUICK]) == 3
    assert "no vehicle profile: timed analysis needs the mission's profile" in (
        capsys.readouterr().out
    )
