"""Timed analysis: how long a mission takes, and whether its time-outs are adequate.

Untimed analysis lets every reply come at any time, which is sound for deadlock but
says nothing about time. Here the vehicle works within its profile's bounds
(`coral_lang.profile.CommandSpec.work_interval`) and every message crosses the link
within `coral_lang.timing.LinkBounds`; the engine fires immediately. The exact model
and what it abstracts: ``docs/analysis-methods.md`` (timed analysis).

`analyse_timed` answers, on a symbolic (zone) state space:

* best and worst mission time to each declared final marking, with runs attaining them;
* per query, whether it can time out although the vehicle did its work in time;
* per ``assert within T s { places }``, whether every run marks them by T.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from analysis.timed.options import TimedOptions
from analysis.timed.results import DeadlineResult, FinalTiming, QueryAdequacy, TimedReport
from analysis.timed.schedule import (
    ScheduledCommand,
    ScheduledFiring,
    ScheduleError,
    TimedSchedule,
    read_schedule,
)

if TYPE_CHECKING:
    from coral_lang.net import Net
    from coral_lang.profile import VehicleProfile

__all__ = [
    "DeadlineResult",
    "FinalTiming",
    "QueryAdequacy",
    "ScheduleError",
    "ScheduledCommand",
    "ScheduledFiring",
    "TimedOptions",
    "TimedReport",
    "TimedSchedule",
    "analyse_timed",
    "read_schedule",
]


def analyse_timed(
    net: Net, profiles: Sequence[VehicleProfile], options: TimedOptions
) -> TimedReport:
    """Timed analysis of ``net`` (`analysis.timed.explore.analyse_timed`).

    The explorers are imported on the first call: every ``coral-check`` run loads this
    package (for its options and results), and only ``--timed`` needs them.
    """
    from analysis.timed.explore import analyse_timed as explore

    return explore(net, profiles, options)
