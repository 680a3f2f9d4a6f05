"""Timed analysis under the command's budget: its time and memory limits stop it with
`analysis.budget`'s reason (which limit, after how many symbolic states), inconclusive,
and a failed allocation inside it is an inconclusive report too, never a crash."""

from __future__ import annotations

import pytest

from analysis.timed import TimedOptions, analyse_timed, explore
from coral_lang.compiler import compile_file
from coral_lang.timing import LinkBounds
from tests.conftest import EXAMPLES

LINK = LinkBounds("genoa-lisbon", 0.045, 9.5)
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"


@pytest.mark.parametrize(
    ("options", "reason"),
    [
        (TimedOptions(LINK, time_limit_s=0.0), "time limit of 0 s reached after"),
        (TimedOptions(LINK, memory_limit=1), "memory limit of 1 B reached after"),
    ],
)
def test_a_limit_stops_timed_analysis_and_says_which(options: TimedOptions, reason: str) -> None:
    result = compile_file(POOL)
    assert result.net is not None and result.profile is not None
    report = analyse_timed(result.net, [result.profile], options)
    assert not report.complete
    assert report.reason.startswith(reason), report.reason
    assert "symbolic state" in report.reason
    limit = "--memory-limit" if "memory" in reason else "--time-limit"
    assert report.reason.endswith(f"(raise it with {limit})")


def test_a_failed_allocation_is_an_inconclusive_report(monkeypatch: pytest.MonkeyPatch) -> None:
    result = compile_file(POOL)
    assert result.net is not None and result.profile is not None

    def failing(self: object, *args: object) -> object:
        raise MemoryError

    monkeypatch.setattr(explore._Search, "_add", failing)
    report = analyse_timed(result.net, [result.profile], TimedOptions(LINK, memory_limit=1 << 30))
    assert not report.complete
    assert report.reason == "memory limit of 1 GiB reached"
