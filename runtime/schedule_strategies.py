"""Hypothesis strategies for `runtime.schedule` schedules, for property tests of missions.

Needs hypothesis (the ``dev`` extra); nothing else in ``runtime`` imports this module.

The strategies draw what the network and the vehicle may do to a mission: per command,
its reply (when the vehicle can give several), the delay each way, how long the vehicle
works, the order among replies due together; and a few outages. Every field shrinks
towards "nominal": the expected reply, no delay, the profile's nominal work time, no
outage. A failing schedule therefore shrinks to the few delays or replies the failure
needs, which is what a person wants to read. See ``docs/fuzz.md``.

Typical use in a user's own tests::

    @given(schedules())
    def test_my_mission_always_ends_properly(schedule: Schedule) -> None:
        timing = Timing(mission.net, profile=mission.profile)  # a coral_lang.Mission
        run = run_schedule(Engine(mission.net, approval), schedule, timing)
        assert run.outcome is Outcome.FINAL
"""

from __future__ import annotations

from hypothesis import strategies as st

from runtime.schedule import MessageFate, Outage, Schedule

__all__ = ["message_fates", "outages", "schedules"]

DEFAULT_MAX_DELAY_MS = 10_000
"""Longest one-way delay drawn: the paper saw link stalls of about 7 s; a little more."""


def message_fates(
    *,
    max_delay_ms: int = DEFAULT_MAX_DELAY_MS,
    failure_weight: int = 1,
    success_weight: int = 3,
    work_permille: tuple[int, int] = (500, 1500),
    max_rank: int = 3,
) -> st.SearchStrategy[MessageFate]:
    """The fate of one command.

    Args:
        max_delay_ms: longest delay of each leg (up, down).
        failure_weight: relative weight of the vehicle giving another reply than the
            first (an ``error``, a ``timeout``)...
        success_weight: ... against giving the first one. The default (1 in 4 replies a
            failure) lets long missions reach their later phases as well as fail early.
        work_permille: range of the vehicle's work time, in thousandths of nominal; it
            shrinks towards 1000 (nominal) when the range holds it.
        max_rank: ranks among replies due at the same millisecond.
    """
    low, high = work_permille
    if not 0 <= low <= high:
        raise ValueError(f"work_permille must be a range 0 <= low <= high, got {work_permille}")
    centre = min(max(1000, low), high)
    replies = st.sampled_from((0,) * success_weight + tuple(range(1, failure_weight + 1)))
    delay = st.integers(0, max_delay_ms)
    return st.builds(
        MessageFate,
        reply=replies,
        up_ms=delay,
        # An offset from nominal: integers shrink towards 0, so work shrinks to nominal.
        work_permille=st.integers(low - centre, high - centre).map(lambda d: centre + d),
        down_ms=delay,
        rank=st.integers(0, max_rank),
    )


def outages(
    *, horizon_ms: int = 600_000, max_length_ms: int = 20_000
) -> st.SearchStrategy[Outage[int]]:
    """One outage starting within ``horizon_ms`` of the mission's start."""
    return st.builds(Outage, start=st.integers(0, horizon_ms), length=st.integers(0, max_length_ms))


def schedules(
    *,
    max_messages: int = 48,
    max_outages: int = 2,
    max_delay_ms: int = DEFAULT_MAX_DELAY_MS,
    failure_weight: int = 1,
    success_weight: int = 3,
    horizon_ms: int = 600_000,
) -> st.SearchStrategy[Schedule]:
    """Whole schedules: up to ``max_messages`` command fates and ``max_outages`` outages.

    Commands beyond the drawn list are nominal (`MessageFate()`), so short lists, which
    hypothesis prefers when shrinking, still run a whole mission.
    """
    fates = message_fates(
        max_delay_ms=max_delay_ms, failure_weight=failure_weight, success_weight=success_weight
    )
    return st.builds(
        Schedule,
        messages=st.lists(fates, max_size=max_messages).map(tuple),
        outages=st.lists(outages(horizon_ms=horizon_ms), max_size=max_outages).map(tuple),
    )
