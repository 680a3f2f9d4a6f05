"""The scripted pool mission, the run log, the figures and the romeo-sim program."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from romeo_sim.cli import build_parser, main
from romeo_sim.plots import plot_run
from romeo_sim.scenario import PHASES, MissionResult, mission_targets, pool_mission_stages


def test_pool_mission_completes_with_every_query_done(mission: MissionResult) -> None:
    assert mission.completed, mission.reason
    stages = pool_mission_stages(mission.mission)
    sent = [name for stage in stages for name, _ in stage.commands]
    assert [c.command for c in mission.recorder.commands] == sent
    finals = {cid: r.kind for cid, r in mission.final_replies.items()}
    assert set(finals.values()) == {"done", "ack"}
    queries = [r for r in mission.recorder.replies if r.command.endswith("?")]
    assert len(queries) == 9 and all(r.kind == "done" for r in queries)
    assert [p.name for p in mission.phases] == list(PHASES)
    assert 100.0 < mission.vehicle.time < 400.0


def test_pool_mission_ends_docked_at_the_surface(mission: MissionResult) -> None:
    final = mission.recorder.telemetry[-1]
    assert final.z < 0.05
    assert mission.dock is not None
    assert math.hypot(final.x - mission.dock[0], final.y - mission.dock[1]) < 0.4
    assert final.horizontal_task.startswith("DOCKING")


def test_estimate_tracks_truth_through_the_mission(mission: MissionResult) -> None:
    errors = [
        math.hypot(t.x - t.est_x, t.y - t.est_y)
        for t in mission.recorder.telemetry
        if t.est_x is not None and t.est_y is not None
    ]
    assert len(errors) > 100
    assert max(errors) < 0.3


def test_run_log_exports(mission: MissionResult, tmp_path: Path) -> None:
    path = mission.recorder.write_json(tmp_path / "run.json")
    data = json.loads(path.read_text())
    assert len(data["telemetry"]) == len(mission.recorder.telemetry)
    assert data["commands"][0] == {"time": 0.0, "command_id": 1, "command": "INIT", "params": {}}
    assert {"x", "est_x", "z", "psi"} <= set(data["telemetry"][0])
    files = mission.recorder.write_csv(tmp_path / "csv")
    assert sorted(p.name for p in files) == [
        "commands.csv",
        "events.csv",
        "replies.csv",
        "telemetry.csv",
    ]
    with (tmp_path / "csv" / "replies.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert rows[0]["command"] == "INIT" and rows[0]["kind"] == "done"


@pytest.mark.slow
def test_plots_are_written(mission: MissionResult, tmp_path: Path) -> None:
    pool = mission.vehicle.config.pool
    files = plot_run(
        mission.recorder,
        tmp_path,
        targets=mission_targets(mission.mission),
        dock=mission.dock,
        pool=(pool.length_m, pool.width_m),
        phases=[(p.name, p.start, p.end) for p in mission.phases],
    )
    assert [p.name for p in files] == [
        "mission.png",
        "mission.svg",
        "phase1_go_to_operating_site.png",
        "phase1_go_to_operating_site.svg",
        "phase2_way_point_navigation.png",
        "phase2_way_point_navigation.svg",
        "phase3_docking.png",
        "phase3_docking.svg",
    ]
    for path in files:
        assert path.stat().st_size > 10_000
    assert files[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert files[1].read_text().lstrip().startswith("<?xml")


def test_cli_help_names_the_mission_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    assert "usage: romeo-sim" in text and "mission" in text
    assert build_parser().prog == "romeo-sim"


def test_cli_runs_the_mission(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mission", "--out", str(tmp_path), "--no-plots", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "pool mission completed" in out
    assert (tmp_path / "run.json").is_file()


def test_cli_refuses_a_bad_vehicle_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("dynamics:\n  mass: {surge: -650}\n")
    assert main(["mission", "--out", str(tmp_path), "--vehicle", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml:2: dynamics.mass.surge: must be > 0, got -650" in err
