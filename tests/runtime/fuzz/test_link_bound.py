"""How often a fuzz campaign's link exceeded the delay bound timed analysis assumes.

The count must be exact (a message over the bound is counted, one within it is not) and
must change nothing: same fates, same events, whatever the bound.
"""

from __future__ import annotations

import dataclasses
import json

from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.emulator import Direction, LinkEmulator
from runtime.engine import Policy
from runtime.fuzz import FuzzOptions, format_report, fuzz, run_one
from runtime.fuzz.one_run import CountingEmulator
from runtime.link import BUILTIN_PROFILES, LinkProfile
from tests.runtime.test_properties import mission

HOSTILE = BUILTIN_PROFILES["hostile"]


def _bounded(profile: LinkProfile, bound: float) -> LinkProfile:
    return dataclasses.replace(profile, analysis_min_delay_s=0.0, analysis_max_delay_s=bound)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32),
    bound=st.floats(0.0, 3.0),
    gaps=st.lists(st.tuples(st.floats(0.0, 2.0), st.booleans(), st.integers(0, 600)), max_size=40),
)
def test_counting_changes_no_fate_and_counts_exactly(
    seed: int, bound: float, gaps: list[tuple[float, bool, int]]
) -> None:
    plain = LinkEmulator(HOSTILE, seed)
    counting = CountingEmulator(HOSTILE, seed, bound)
    first, second = plain.connect(0.0), counting.connect(0.0)
    assert first.latency == second.latency
    if first.path is None or second.path is None:
        assert first.path is second.path is None
        return
    now, delays = first.latency, []
    for gap, up, size in gaps:
        now += gap
        direction = Direction.UP if up else Direction.DOWN
        arrival = first.path.chunk(direction, size, now)
        assert second.path.chunk(direction, size, now) == arrival
        if size > 0 and arrival < first.path.ends_at:
            delays.append(arrival - now)
    assert counting.messages == len(delays)
    assert counting.over_bound == sum(d > bound + 1e-9 for d in delays)
    assert counting.longest_delay == max(delays, default=0.0)


def test_a_run_counts_the_messages_over_the_bound_and_keeps_its_events() -> None:
    racy = mission("racy")
    tight = FuzzOptions(runs=1, seed=3, link=_bounded(HOSTILE, 0.01), policy=Policy.PRIORITY)
    loose = dataclasses.replace(tight, link=_bounded(HOSTILE, 1e6))
    over = run_one(racy.net, racy.approval, 3, tight)
    within = run_one(racy.net, racy.approval, 3, loose)
    assert over.events_digest == within.events_digest  # counting changes nothing
    assert over.messages == within.messages > 0
    assert over.over_bound == over.messages  # hostile: every message takes > 10 ms
    assert within.over_bound == 0
    assert over.longest_delay == within.longest_delay > 0.01
    assert over.to_json()["messages_over_link_bound"] == over.messages


def test_the_report_says_how_many_messages_and_runs_exceeded_the_bound() -> None:
    racy = mission("racy")
    link = _bounded(HOSTILE, 0.3)
    report = fuzz(racy.net, racy.approval, FuzzOptions(runs=3, seed=11, link=link))
    count = report.link_bound()
    assert count.max_delay_s == 0.3 and count.link == HOSTILE.name
    assert count.messages == sum(r.messages for r in report.runs)
    assert count.messages_over == sum(r.over_bound for r in report.runs)
    assert count.runs_over == sum(r.over_bound > 0 for r in report.runs)
    assert 0 < count.messages_over < count.messages  # the bound splits hostile's delays
    text = format_report(report, "coral-run fuzz racy.coral")
    assert (
        f"link: {count.messages_over} of {count.messages} messages, in {count.runs_over}/3 "
        f"run(s), took longer than the analysis bound 0.3 s of link '{HOSTILE.name}'"
    ) in text
    data = json.loads(json.dumps(report.to_json()))
    assert data["link_bound"]["messages_over"] == count.messages_over
    assert data["link_bound"]["runs_over"] == count.runs_over
    calm = fuzz(racy.net, racy.approval, FuzzOptions(runs=1, seed=11, link=_bounded(HOSTILE, 1e6)))
    assert "link: no message took longer than the analysis bound" in format_report(calm, "x")
