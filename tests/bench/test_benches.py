"""Smoke tests of the trust benches (``bench/redteam.py``, ``bench/kill9.py``), so they
do not rot: each runs the real command at its smallest size and checks its table.

They run the benches as a user does, in a subprocess, because both start processes of
their own (workers, a served vehicle, ``coral-run``) and install signal handling.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

CLASSES = ("mission", "profile", "pnml", "query", "certificate", "frames", "server", "log")


def _bench(*argv: str, timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *argv], capture_output=True, text=True, cwd=REPO, timeout=timeout
    )


@pytest.mark.slow
def test_redteam_tiny_campaign_has_every_class_and_no_failure(tmp_path: Path) -> None:
    done = _bench(
        "bench/redteam.py", "--per-class", "2", "--seed", "7", "--out", str(tmp_path), timeout=120
    )
    rows = {
        m.group(1): [int(n) for n in m.group(2).split()]
        for m in re.finditer(r"(?m)^(\w+)\s+((?:\d+\s+){5})[\d.]+$", done.stdout)
    }
    assert set(rows) == set(CLASSES), done.stdout + done.stderr
    for cls, (inputs, clean, _exit1, accepted, failures) in rows.items():
        assert inputs == 2 == clean + accepted + failures, cls
    assert "FAILURE" not in done.stdout, done.stdout
    assert done.returncode == 0, done.stdout + done.stderr
    assert not (tmp_path / "failures").exists() or not any((tmp_path / "failures").iterdir())


@pytest.mark.slow
def test_kill9_one_short_trial_loses_and_repeats_nothing(tmp_path: Path) -> None:
    done = _bench(
        "bench/kill9.py",
        "--trials",
        "1",
        "--missions",
        "survey",
        "--kills",
        "1",
        "--speed-factor",
        "3",
        "--kill-mode",
        "commands",
        "--seed",
        "2",
        "--out",
        str(tmp_path),
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    total = re.search(
        r"total: 1 trials, (\d+) kills, (\d+) commands sent, executed twice (\d+), lost (\d+), "
        r"completed after --resume (\d+)/1",
        done.stdout,
    )
    assert total, done.stdout
    kills, sent, twice, lost, completed = (int(g) for g in total.groups())
    assert kills == 1 and sent == 11  # the survey mission sends 11 commands
    assert (twice, lost, completed) == (0, 0, 1)
