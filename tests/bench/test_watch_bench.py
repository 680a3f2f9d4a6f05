"""Smoke test of ``bench/watch.py`` at its smallest size, so it does not rot: the three
configurations run (the viewers' process connects, the run completes) and the table and
the ratios are printed."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow
def test_watch_bench_tiny_run_prints_three_rates_and_the_ratio() -> None:
    argv = ["bench/watch.py", "--chains", "2", "--length", "6", "--rounds", "1"]
    done = subprocess.run(
        [sys.executable, *argv, "--viewers", "3"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    rows = re.findall(
        r"(?m)^(no server|live server, .+?)\s+(\d+)\s+([\d,]+)\s+[\d,]+\s+[\d.]+\s+[\d.]+$",
        done.stdout,
    )
    assert [label for label, _, _ in rows] == [
        "no server",
        "live server, 0 viewers",
        "live server, 3 viewers (1 stalled)",
    ], done.stdout
    assert {int(messages) for _, messages, _ in rows} == {12}  # 6 queries: sent + replied
    assert re.search(r"3 viewers \(1 stalled\) / no server: [\d.]+", done.stdout), done.stdout
    assert "target (at most 5 % slower with viewers than with 0 viewers, wall):" in done.stdout
