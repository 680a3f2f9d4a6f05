"""``--memory-limit``: running out of memory ends as an honest inconclusive verdict
(exit 3, JSON saying which limit and after how many states), never a crash (exit 1 or
a traceback). Run as a subprocess: the limit is on the whole process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.budget import (
    Budget,
    BudgetExceeded,
    bytes_text,
    default_memory_limit,
    memory_limit_reason,
    parse_bytes,
    resident_bytes,
)

ROOT = Path(__file__).resolve().parents[2]


def _toggles_pnml(n: int) -> str:
    """``n`` independent on/off switches: 2^n markings, no deadlock, bounded; and a
    transition per switch that would move its token to a sink ``s``, if the never-marked
    catalyst ``k`` were marked. Its firing counts solve the state equation (and its
    traps) for a dead marking, so only the search can show the net deadlock-free:
    stopped, the verdict stays open."""
    places = '<place id="k"/>' + "".join(
        f'<place id="a{i}"><initialMarking><text>1</text></initialMarking></place>'
        f'<place id="b{i}"/><place id="s{i}"/>'
        for i in range(n)
    )
    transitions = "".join(
        f'<transition id="on{i}"/><transition id="off{i}"/><transition id="kill{i}"/>'
        for i in range(n)
    )
    arcs = "".join(
        f'<arc id="x{i}" source="a{i}" target="on{i}"/><arc id="y{i}" source="on{i}" target="b{i}"/>'
        f'<arc id="z{i}" source="b{i}" target="off{i}"/><arc id="w{i}" source="off{i}" target="a{i}"/>'
        f'<arc id="u{i}" source="a{i}" target="kill{i}"/><arc id="v{i}" source="k" target="kill{i}"/>'
        f'<arc id="t{i}" source="kill{i}" target="k"/><arc id="r{i}" source="kill{i}" target="s{i}"/>'
        for i in range(n)
    )
    return (
        '<?xml version="1.0"?><pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">'
        '<net id="toggles" type="http://www.pnml.org/version-2009/grammar/ptnet"><page id="p">'
        f"{places}{transitions}{arcs}</page></net></pnml>"
    )


def test_a_search_past_the_memory_limit_stops_honestly_not_with_a_crash(tmp_path: Path) -> None:
    """The search stops at the limit and says so; the verdicts it left open are
    decided by the methods that need no state space (here the state equation with
    traps proves deadlock freedom), never a crash: exit 0 or 3, never 1."""
    model = tmp_path / "toggles.pnml"
    model.write_text(_toggles_pnml(24))  # 16.8M markings: over 1 GB to store
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "analysis.cli", "verify", str(model), "--format", "json"]
    limits = ["--memory-limit", "200M", "--max-states", "100000000", "--time-limit", "60"]
    limits += ["--method", "explicit"]  # its subject: the explicit search's stop
    done = subprocess.run(
        [*command, *limits], capture_output=True, text=True, env=env, timeout=120, check=False
    )
    assert done.returncode in (0, 3), done.stderr
    assert "Traceback" not in done.stderr
    document = json.loads(done.stdout)
    text = json.dumps(document)
    assert "memory limit of 200 MiB reached after" in text
    assert '"verdict": "violated"' not in text
    space = document["files"][0]["report"]["statespace"]
    assert not space["complete"]
    assert space["stopped_reason"].startswith("memory limit of 200 MiB reached after")
    assert space["bytes_per_state"] >= space["stored_bytes_per_state"] > 0


def test_an_allocation_failing_in_a_stage_is_an_inconclusive_verdict(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A MemoryError (numpy's _ArrayMemoryError is one) in any stage ends that stage
    with an inconclusive verdict naming the limit (exit 3), keeping what came before."""
    from analysis import verify as verify_module
    from analysis.report import Verdict
    from tests.analysis.nets import mutex

    def fails(self: object) -> object:
        raise MemoryError

    monkeypatch.setattr(verify_module._Checker, "deadlock", fails)
    # above what this (possibly long-lived test worker) process already holds
    limit = resident_bytes() + (200 << 20)
    options = verify_module.VerifyOptions(memory_limit=limit, structural=False)
    report = verify_module.verify(mutex(), options)
    keys = [p.key for p in report.properties]
    assert keys == ["bounded", "analysis"]
    stopped = report.properties[-1]
    assert stopped.verdict is Verdict.INCONCLUSIVE
    assert (
        f"memory limit of {bytes_text(limit)} reached after 3 states, in deadlock" in stopped.detail
    )


@pytest.mark.parametrize(
    ("text", "amount"),
    [
        ("200M", 200 << 20),
        ("1.5G", 3 << 29),
        ("512k", 512 << 10),
        ("4096", 4096),
        ("2GiB", 2 << 30),
    ],
)
def test_memory_amounts_parse(text: str, amount: int) -> None:
    assert parse_bytes(text) == amount


@pytest.mark.parametrize("text", ["", "M", "-1G", "lots", "1X", "nan"])
def test_bad_memory_amounts_are_refused_with_the_text(text: str) -> None:
    with pytest.raises(ValueError, match="not an amount of memory"):
        parse_bytes(text)


def test_the_budget_is_spent_once_the_process_is_over_its_memory_limit() -> None:
    now = resident_bytes()
    assert not Budget(memory=now * 4).expired()
    over = Budget(memory=now // 2)
    assert over.expired()
    assert over.time_reason(7) == memory_limit_reason(now // 2, 7)
    assert over.child(seconds=5.0).expired()  # a stage inherits the limit
    with pytest.raises(BudgetExceeded, match="memory limit of"):
        Budget(memory=now * 4).check_memory(extra_bytes=now * 8)


def test_the_default_limit_is_a_share_of_the_machine() -> None:
    limit = default_memory_limit()
    assert limit is None or 0 < limit < 1 << 50
    assert bytes_text(200 << 20) == "200 MiB"
