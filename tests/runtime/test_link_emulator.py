"""runtime.emulator: the fate of each chunk, datagram and connection, from a seed.

Rates are checked over many samples with fixed seeds; the tolerances are several standard
deviations wide, so they hold for any seed, not only the one used.
"""

from __future__ import annotations

import itertools
import math
import statistics
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.emulator import DatagramFate, Direction, LinkEmulator, Outage
from runtime.linkprofile import BUILTIN_PROFILES, LinkProfile

GENOA = BUILTIN_PROFILES["genoa-lisbon"]
HOSTILE = BUILTIN_PROFILES["hostile"]
# The Internet part of the paper's link without the rare connection-level events.
STEADY = replace(GENOA, reset_rate_per_s=0.0, outage_rate_per_s=0.0)


@given(
    seed=st.integers(0, 2**32),
    writes=st.lists(
        st.tuples(st.floats(0.0, 2.0), st.integers(0, 300), st.sampled_from(list(Direction))),
        max_size=60,
    ),
    profile=st.sampled_from([GENOA, HOSTILE, BUILTIN_PROFILES["lan"], BUILTIN_PROFILES["ideal"]]),
)
def test_stream_arrivals_keep_the_order_of_writes_in_each_direction(
    seed: int, writes: list[tuple[float, int, Direction]], profile: LinkProfile
) -> None:
    emulator = LinkEmulator(profile, seed)
    attempt = emulator.connect(0.0)
    if attempt.path is None:  # hostile: an outage at the start
        return
    now = attempt.latency
    last = {d: -math.inf for d in Direction}
    for gap, size, direction in writes:
        now += gap
        arrival = attempt.path.chunk(direction, size, now)
        assert arrival >= now + profile.delay_s
        assert arrival >= last[direction]
        last[direction] = arrival


@given(sizes=st.lists(st.integers(1, 1024), min_size=1, max_size=20), seed=st.integers(0, 99))
def test_bytes_of_one_direction_queue_on_the_9600_bps_line(sizes: list[int], seed: int) -> None:
    path = LinkEmulator(STEADY, seed).connect(0.0).path
    assert path is not None
    arrivals = [path.chunk(Direction.UP, size, 10.0) for size in sizes]
    line_bytes = sum(sizes) + len(sizes) * STEADY.stream_overhead_bytes
    # Everything written at t=10 leaves the line no sooner than N*10/9600 seconds later.
    assert arrivals[-1] >= 10.0 + line_bytes * 10 / 9600 + STEADY.delay_s
    assert arrivals[0] >= 10.0 + (sizes[0] + 40) * 10 / 9600
    # The other direction has a line of its own: no waiting behind those bytes.
    worst = 41 * 10 / 9600 + STEADY.delay_s + STEADY.jitter_cap_s + STEADY.stall_max_s
    assert path.chunk(Direction.DOWN, 1, 10.0) <= 10.0 + worst


def test_a_datagram_waits_behind_the_stream_on_the_same_line() -> None:
    emulator = LinkEmulator(STEADY, 1)
    path = emulator.connect(0.0).path
    assert path is not None
    path.chunk(Direction.DOWN, 960, 100.0)  # one second of line
    fate = emulator.datagram(Direction.DOWN, 55, 100.0)
    if not fate.lost:
        assert min(fate.arrivals) >= 100.0 + (1000 + 83) / 960


def test_the_delay_has_its_base_a_heavy_tail_and_no_more() -> None:
    emulator = LinkEmulator(GENOA, 7)
    samples = sorted(emulator.sample_delay() for _ in range(40_000))
    median = statistics.median(samples)
    assert samples[0] >= GENOA.delay_s
    assert GENOA.delay_s < median < GENOA.delay_s + 0.05
    # Heavy tail: more than 1 % of samples beyond ten times the median (an exponential
    # with this median would have 0.1 %), and some beyond 50 times it.
    beyond = sum(s > 10 * median for s in samples) / len(samples)
    assert beyond > 0.01, beyond
    assert samples[-1] > 50 * median
    assert samples[-1] <= GENOA.delay_s + GENOA.jitter_cap_s + GENOA.stall_max_s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stalls_are_rare_and_never_longer_than_seven_seconds(seed: int) -> None:
    profile = replace(GENOA, jitter_scale_s=0.0)  # what is above the base is a stall
    emulator = LinkEmulator(profile, seed)
    stalls = [d - profile.delay_s for d in (emulator.sample_delay() for _ in range(50_000))]
    stalls = [s for s in stalls if s > 0.0]
    assert all(2.0 <= s <= 7.0 for s in stalls)
    assert len(stalls) / 50_000 == pytest.approx(profile.stall_probability, rel=0.25)
    assert max(stalls) > 6.5


def _datagram_run(profile: LinkProfile, seed: int, count: int) -> list[DatagramFate]:
    """``count`` datagrams of 55 bytes, 0.2 s apart (the line is never the bottleneck)."""
    emulator = LinkEmulator(profile, seed)
    return [emulator.datagram(Direction.DOWN, 55, 0.2 * i) for i in range(count)]


@pytest.mark.slow
@pytest.mark.parametrize(("profile", "seed"), [(STEADY, 3), (HOSTILE, 4)])
def test_datagram_loss_duplication_and_reordering_follow_the_profile(
    profile: LinkProfile, seed: int
) -> None:
    count = 40_000
    fates = _datagram_run(replace(profile, outage_rate_per_s=0.0), seed, count)
    lost = sum(f.lost for f in fates) / count
    duplicated = sum(f.duplicated for f in fates) / count
    reordered = sum(f.reordered for f in fates if not f.lost) / count
    assert lost == pytest.approx(profile.datagram_loss, rel=0.15, abs=0.001)
    kept = 1 - profile.datagram_loss
    assert duplicated == pytest.approx(profile.datagram_duplicate * kept, rel=0.3, abs=0.001)
    assert reordered == pytest.approx(profile.datagram_reorder * kept, rel=0.2, abs=0.001)
    # Held-back datagrams really are overtaken: arrival order differs from sending order.
    firsts = [(min(f.arrivals), i) for i, f in enumerate(fates) if not f.lost]
    inversions = sum(a[1] > b[1] for a, b in itertools.pairwise(sorted(firsts)))
    assert inversions > 0.5 * reordered * count
    assert all(f.lost_to == "loss" for f in fates if f.lost)


def test_outages_lose_datagrams_refuse_connections_and_cut_the_connection() -> None:
    emulator = LinkEmulator(HOSTILE, 5)
    outage = emulator.next_outage(0.0)
    assert outage is not None
    assert HOSTILE.outage_min_s <= outage.length <= HOSTILE.outage_max_s
    middle = (outage.start + outage.end) / 2
    assert emulator.outage_at(middle) == outage
    fate = emulator.datagram(Direction.DOWN, 55, middle)
    assert fate.lost and fate.lost_to == "outage" and fate.outage == outage
    attempt = emulator.connect(middle)
    assert not attempt.ok and attempt.outage == outage
    assert attempt.latency == pytest.approx(2 * HOSTILE.delay_s)
    # A connection made before the outage ends at its start at the latest.
    before = emulator.connect(max(0.0, outage.start - 1e-3 - 5.0))
    if before.path is not None:
        assert before.path.ends_at <= outage.start


def test_one_outage_serves_the_emulator_in_seconds_and_schedules_in_milliseconds() -> None:
    """runtime.schedule lists outages with the emulator's class, in integer milliseconds."""
    from runtime import schedule

    assert schedule.Outage is Outage
    in_ms = Outage(100, 29_900)
    assert in_ms.end == 30_000 and isinstance(in_ms.end, int)
    assert in_ms.covers(100) and in_ms.covers(29_999) and not in_ms.covers(30_000)
    in_s = Outage(1.5, 2.0)
    assert in_s.end == 3.5 and in_s.overlaps(0.0, 1.5) and not in_s.overlaps(3.5, 9.0)
    with pytest.raises(ValueError, match="start and length >= 0"):
        Outage(1.0, -0.5)
    run = schedule.Schedule(outages=(in_ms,))
    assert run.arrival(5_000) == 30_000 and run.arrival(30_000) == 30_000
    assert "outage from 100 ms for 29900 ms" in run.describe()


def test_outage_durations_and_rate_follow_the_profile() -> None:
    emulator = LinkEmulator(HOSTILE, 6)
    starts, lengths = [], []
    t = 0.0
    while (outage := emulator.next_outage(t)) is not None and outage.start < 50_000:
        starts.append(outage.start)
        lengths.append(outage.length)
        t = outage.end
    assert all(HOSTILE.outage_min_s <= length <= HOSTILE.outage_max_s for length in lengths)
    up_time = 50_000 - sum(lengths)
    assert len(starts) / up_time == pytest.approx(HOSTILE.outage_rate_per_s, rel=0.1)


def test_connections_reset_at_the_profiles_rate() -> None:
    profile = LinkProfile(name="resets", delay_s=0.01, reset_rate_per_s=0.1)
    emulator = LinkEmulator(profile, 8)
    lifetimes = []
    for i in range(4000):
        path = emulator.connect(1000.0 * i).path
        assert path is not None and path.end_cause == "reset"
        lifetimes.append(path.ends_at - path.established_at)
    assert statistics.fmean(lifetimes) == pytest.approx(10.0, rel=0.06)


def test_a_connect_takes_one_round_trip() -> None:
    emulator = LinkEmulator(STEADY, 9)
    latencies = [emulator.connect(10.0 * i).latency for i in range(200)]
    line = 2 * 40 * 10 / 9600
    assert min(latencies) >= 2 * STEADY.delay_s + line
    assert statistics.median(latencies) < 2 * (STEADY.delay_s + 0.05) + line


def test_the_ideal_link_is_instant_and_perfect() -> None:
    emulator = LinkEmulator(BUILTIN_PROFILES["ideal"], 0)
    attempt = emulator.connect(5.0)
    assert attempt.latency == 0.0 and attempt.path is not None
    assert attempt.path.ends_at == math.inf and attempt.path.end_cause is None
    assert attempt.path.chunk(Direction.UP, 1000, 5.0) == 5.0
    assert emulator.datagram(Direction.DOWN, 55, 6.0) == DatagramFate(6.0, (6.0,))
    assert emulator.next_outage(0.0) is None


def _script(emulator: LinkEmulator) -> list[object]:
    """A fixed sequence of calls; what the emulator answers."""
    answers: list[object] = []
    for i in range(300):
        now = 0.5 * i
        attempt = emulator.connect(now)
        answers.append((attempt.latency, attempt.outage))
        if attempt.path is not None:
            answers.append((attempt.path.ends_at, attempt.path.end_cause))
            answers.append(attempt.path.chunk(Direction.UP, 57 + i % 13, now))
            answers.append(attempt.path.chunk(Direction.DOWN, 48, now))
        answers.append(emulator.datagram(Direction.DOWN, 55, now))
    return answers


@settings(max_examples=20)
@given(seed=st.integers(0, 2**63))
def test_same_seed_same_fates_other_seed_other_fates(seed: int) -> None:
    first = _script(LinkEmulator(HOSTILE, seed))
    assert _script(LinkEmulator(HOSTILE, seed)) == first
    assert _script(LinkEmulator(HOSTILE, seed + 1)) != first


def test_outages_do_not_depend_on_the_traffic() -> None:
    busy, idle = LinkEmulator(HOSTILE, 11), LinkEmulator(HOSTILE, 11)
    _script(busy)
    assert [busy.next_outage(t) for t in (0.0, 100.0, 1000.0)] == [
        idle.next_outage(t) for t in (0.0, 100.0, 1000.0)
    ]


@given(
    seed=st.integers(0, 2**32),
    queries=st.lists(st.tuples(st.floats(0.0, 5000.0), st.floats(0.0, 100.0)), max_size=30),
)
def test_outage_lookups_agree_with_a_plain_scan(
    seed: int, queries: list[tuple[float, float]]
) -> None:
    emulator = LinkEmulator(HOSTILE, seed)
    for t0, length in queries:
        found = emulator.outage_between(t0, t0 + length)
        timeline = emulator._outages
        expected = next((o for o in timeline if o.overlaps(t0, t0 + length)), None)
        assert found == expected
        at = emulator.outage_at(t0)
        assert at == next((o for o in timeline if o.covers(t0)), None)
        nxt = emulator.next_outage(t0)
        assert nxt == next(o for o in emulator._outages if o.start >= t0)
    assert all(a.end <= b.start for a, b in itertools.pairwise(emulator._outages))
