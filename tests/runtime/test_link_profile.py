"""Link profiles (``coral_lang.linkprofile``, also imported as ``runtime.linkprofile``):
built-in profiles, YAML files, errors that say where, and the emulator's delays against
the bounds timed analysis assumes."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.diagnostics import CoralError
from runtime.emulator import Direction, LinkEmulator
from runtime.linkprofile import (
    ANALYSIS_FRAME_BYTES,
    BUILTIN_PROFILES,
    LinkProfile,
    LinkProfileError,
    load_link_profile,
)
from tests.conftest import REPO

DOC = (REPO / "docs" / "link.md").read_text()


def test_the_built_in_profiles_are_there_by_name() -> None:
    assert set(BUILTIN_PROFILES) == {"ideal", "lan", "genoa-lisbon", "hostile"}
    for name, profile in BUILTIN_PROFILES.items():
        assert load_link_profile(name) is profile
        assert profile.name == name


def test_the_ideal_link_does_nothing() -> None:
    ideal = load_link_profile("ideal")
    assert ideal.bandwidth_bps is None and ideal.serialisation_time(1000) == 0.0
    assert ideal.delay_s == ideal.jitter_scale_s == ideal.stall_probability == 0.0
    assert ideal.datagram_loss == ideal.reset_rate_per_s == ideal.outage_rate_per_s == 0.0


def test_genoa_lisbon_is_the_papers_link() -> None:
    p = load_link_profile("genoa-lisbon")
    assert p.bandwidth_bps == 9600 and p.bits_per_byte == 10  # 960 bytes a second
    assert p.serialisation_time(96) == pytest.approx(0.1)
    assert 0.03 <= p.delay_s <= 0.06
    assert p.stall_max_s == 7.0  # "remarkable network delays, i.e. of about 7 seconds"
    assert 0.0 < p.datagram_loss <= 0.02
    assert p.jitter_shape < 2.0  # heavy tail: infinite variance


def test_every_field_and_every_built_in_value_is_documented() -> None:
    for field in dataclasses.fields(LinkProfile):
        assert re.search(rf"^\| `{field.name}` \|", DOC, re.M), field.name
    for name, profile in BUILTIN_PROFILES.items():
        assert f"`{name}`" in DOC
        for field in dataclasses.fields(LinkProfile):
            row = re.search(rf"^\| `{field.name}` \|(.*)$", DOC, re.M)
            assert row is not None
            assert _shown(getattr(profile, field.name)) in row.group(1), (name, field.name)


def _shown(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def test_a_yaml_file_starts_from_a_base_and_overrides_fields(tmp_path: Path) -> None:
    path = tmp_path / "slow-sat.yaml"
    path.write_text("base: genoa-lisbon\ndelay_s: 0.3\ndatagram_loss: 0.05\n")
    profile = load_link_profile(path)
    genoa = BUILTIN_PROFILES["genoa-lisbon"]
    assert profile == dataclasses.replace(genoa, name="slow-sat", delay_s=0.3, datagram_loss=0.05)
    assert load_link_profile(str(path)) == profile


def test_a_yaml_file_without_base_starts_from_ideal(tmp_path: Path) -> None:
    path = tmp_path / "mine.yml"
    path.write_text("name: mine\nbandwidth_bps: null\ndelay_s: 1\nstream_overhead_bytes: 5\n")
    profile = load_link_profile(path)
    assert profile == LinkProfile(name="mine", delay_s=1.0, stream_overhead_bytes=5)


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        ("delay_s: -1\n", ":1:10: delay_s:", "must not be negative"),
        (
            "base: ideal\ndatagram_los: 0.1\n",
            ":2:15: datagram_los:",
            "did you mean 'datagram_loss'",
        ),
        ("datagram_loss: 1.5\n", ":1:16: datagram_loss:", "between 0 and 1"),
        ("delay_s: fast\n", ":1:10: delay_s:", "expected a number"),
        ("stall_probability: true\n", ":1:20: stall_probability:", "expected a number"),
        ("stream_overhead_bytes: 2.5\n", ":1:24: stream_overhead_bytes:", "whole number"),
        (
            "outage_min_s: 9\noutage_max_s: 3\n",
            ":1:15: outage_min_s:",
            "must not exceed outage_max_s",
        ),
        ("base: genoa-lisbn\n", ":1:7: base:", "did you mean 'genoa-lisbon'"),
        ("bandwidth_bps: 0\n", ":1:16: bandwidth_bps:", "positive number or null"),
        ("jitter_shape: 0\n", ":1:15: jitter_shape:", "must be positive"),
        ("delay_s: .inf\n", ":1:10: delay_s:", "finite"),
        ("- delay_s\n", "", "expected a mapping"),
        ("delay_s: [1\n", ":2:1", "not valid YAML"),
    ],
)
def test_a_bad_file_names_file_line_and_field(
    tmp_path: Path, text: str, where: str, message: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(LinkProfileError) as info:
        load_link_profile(path)
    assert isinstance(info.value, CoralError)
    assert str(info.value).startswith(str(path) + where), str(info.value)
    assert message in str(info.value)


def test_an_unknown_name_lists_the_built_in_profiles() -> None:
    with pytest.raises(LinkProfileError, match=r"did you mean 'hostile'.*ideal, lan"):
        load_link_profile("hostle")


def test_a_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(LinkProfileError, match=r"nowhere\.yaml: cannot read the link profile"):
        load_link_profile(tmp_path / "nowhere.yaml")


def test_a_profile_built_in_code_is_checked_too() -> None:
    with pytest.raises(LinkProfileError, match="link profile 'x': stall_min_s: must not exceed"):
        LinkProfile(name="x", stall_min_s=8.0, stall_max_s=7.0)
    with pytest.raises(LinkProfileError, match="bandwidth_bps"):
        LinkProfile(bandwidth_bps=-5.0)


def test_the_jitter_median_follows_the_lomax_formula() -> None:
    p = LinkProfile(jitter_scale_s=0.02, jitter_shape=1.0)
    assert p.jitter_median_s == pytest.approx(0.02)


def _capped_profiles() -> st.SearchStrategy[LinkProfile]:
    """Profiles whose every delay is bounded, without loss, resets or outages (what the
    derived analysis bound speaks about), stalls and reordering often, so the longest
    delays are drawn."""
    times = st.floats(0.0, 5.0)
    return st.builds(
        lambda delay, scale, shape, cap, stall_p, stall_a, stall_b, reorder_p, reorder, bw: (
            LinkProfile(
                name="capped",
                bandwidth_bps=bw,
                stream_overhead_bytes=40,
                datagram_overhead_bytes=28,
                delay_s=delay,
                jitter_scale_s=scale,
                jitter_shape=shape,
                jitter_cap_s=cap,
                stall_probability=stall_p,
                stall_min_s=min(stall_a, stall_b),
                stall_max_s=max(stall_a, stall_b),
                datagram_duplicate=0.3,
                datagram_reorder=reorder_p,
                reorder_delay_s=reorder,
            )
        ),
        times,
        st.sampled_from([0.0, 0.001, 0.1, 1.0]),
        st.floats(0.5, 4.0),
        times,
        st.sampled_from([0.0, 0.1, 0.9]),
        times,
        times,
        st.sampled_from([0.0, 0.5]),
        times,
        st.sampled_from([None, 1200.0, 9600.0, 1e8]),
    )


@settings(max_examples=60, deadline=None)
@given(
    profile=st.one_of(
        _capped_profiles(),
        st.sampled_from(
            [
                dataclasses.replace(p, reset_rate_per_s=0.0, outage_rate_per_s=0.0)
                for p in BUILTIN_PROFILES.values()
            ]
        ),
    ),
    seed=st.integers(0, 2**32),
    messages=st.lists(
        st.tuples(
            st.floats(0.0, 3.0),
            st.integers(0, ANALYSIS_FRAME_BYTES),
            st.booleans(),
            st.sampled_from(list(Direction)),
        ),
        min_size=1,
        max_size=40,
    ),
)
def test_emulated_delays_stay_within_the_derived_analysis_bounds(
    profile: LinkProfile, seed: int, messages: list[tuple[float, int, bool, Direction]]
) -> None:
    """Any chunk or datagram of at most 4 KiB, sent when the line has carried what went
    before, arrives within [analysis min, analysis max] of its sending, on virtual time."""
    bounds = profile.analysis_bounds()
    emulator = LinkEmulator(profile, seed)
    attempt = emulator.connect(0.0)
    assert attempt.path is not None  # no outages in these profiles
    # One frame's line time between sends: the line is free when each message starts.
    spacing = profile.serialisation_time(ANALYSIS_FRAME_BYTES + 40)
    now = attempt.latency
    for gap, size, on_stream, direction in messages:
        now += spacing + gap
        if on_stream:
            arrivals: tuple[float, ...] = (attempt.path.chunk(direction, size, now),)
        else:
            arrivals = emulator.datagram(direction, size, now).arrivals
            assert arrivals  # nothing is lost in these profiles
        for arrival in arrivals:
            assert bounds.min_delay_s - 1e-9 <= arrival - now <= bounds.max_delay_s + 1e-9


def test_the_derived_bound_is_reached_when_every_impairment_is_at_its_worst() -> None:
    """Not a loose bound: with stalls every time, a jitter always at its cap and every
    datagram held back, some delays come within a few percent of it."""
    worst = LinkProfile(
        name="worst",
        delay_s=0.1,
        jitter_scale_s=10.0,
        jitter_cap_s=0.5,
        stall_probability=1.0,
        stall_min_s=2.0,
        stall_max_s=3.0,
        datagram_reorder=1.0,
        reorder_delay_s=1.0,
    )
    bound = worst.analysis_bounds().max_delay_s
    assert bound == pytest.approx(4.6)
    emulator = LinkEmulator(worst, seed=7)
    delays = [
        max(emulator.datagram(Direction.DOWN, 100, float(t)).arrivals) - t for t in range(500)
    ]
    assert max(delays) <= bound
    assert max(delays) >= 0.97 * bound
