"""coral_lang.linkprofile: the move from runtime, and the delay bounds timed analysis
assumes (given in the profile or derived from its impairments)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

import coral_lang.linkprofile as moved
import runtime.linkprofile as old
from coral_lang.linkprofile import (
    ANALYSIS_FRAME_BYTES,
    BUILTIN_PROFILES,
    LinkProfile,
    LinkProfileError,
    load_link_profile,
    parse_link_profile,
)
from coral_lang.timing import LinkBounds


def test_the_old_import_path_gives_the_same_objects() -> None:
    assert set(old.__all__) <= set(moved.__all__)
    for name in old.__all__:
        assert getattr(old, name) is getattr(moved, name), name
    assert old.load_link_profile("hostile") is BUILTIN_PROFILES["hostile"]


def test_runtime_modules_use_the_coral_lang_profile() -> None:
    import runtime.emulator
    import runtime.link

    assert vars(runtime.emulator)["LinkProfile"] is LinkProfile
    assert runtime.link.LinkProfile is LinkProfile
    assert runtime.link.load_link_profile is load_link_profile


# Derived by hand from docs/link.md's model: base + jitter cap + longest stall + reorder
# hold-back + a 4 KiB frame with its 40-byte TCP/IP header at the line speed.
EXPECTED_BOUNDS = {
    "ideal": (0.0, 0.0),
    "lan": (0.0002, 0.0002 + 0.002 + (4096 + 40) * 8 / 100e6),
    "genoa-lisbon": (0.045, 0.045 + 2.0 + 7.0 + 0.6 + (4096 + 40) * 10 / 9600),
    "hostile": (0.1, 0.1 + 3.0 + 7.0 + 1.0 + (4096 + 40) * 10 / 9600),
}


@pytest.mark.parametrize("name", sorted(BUILTIN_PROFILES))
def test_every_built_in_profile_has_derived_analysis_bounds(name: str) -> None:
    profile = BUILTIN_PROFILES[name]
    assert profile.analysis_min_delay_s is None and profile.analysis_max_delay_s is None
    bounds = profile.analysis_bounds()
    low, high = EXPECTED_BOUNDS[name]
    assert bounds.name == name
    assert bounds.min_delay_s == pytest.approx(low, abs=1e-12)
    assert bounds.max_delay_s == pytest.approx(high, abs=1e-12)


def test_only_the_impairments_a_profile_turns_on_count() -> None:
    # A jitter cap, stall length or reorder delay whose mechanism is off adds nothing.
    quiet = LinkProfile(delay_s=0.5, jitter_cap_s=3.0, stall_max_s=7.0, reorder_delay_s=1.0)
    assert quiet.analysis_bounds() == LinkBounds("custom", 0.5, 0.5)
    jitter = dataclasses.replace(quiet, jitter_scale_s=0.01)
    assert jitter.analysis_bounds().max_delay_s == pytest.approx(3.5)
    stalls = dataclasses.replace(jitter, stall_probability=0.01)
    assert stalls.analysis_bounds().max_delay_s == pytest.approx(10.5)
    reorder = dataclasses.replace(stalls, datagram_reorder=0.01)
    assert reorder.analysis_bounds().max_delay_s == pytest.approx(11.5)
    serial = dataclasses.replace(reorder, bandwidth_bps=8000.0, bits_per_byte=8.0)
    assert serial.analysis_bounds().max_delay_s == pytest.approx(11.5 + ANALYSIS_FRAME_BYTES / 1000)


def test_given_bounds_override_the_derived_ones() -> None:
    genoa = BUILTIN_PROFILES["genoa-lisbon"]
    both = dataclasses.replace(genoa, analysis_min_delay_s=0.04, analysis_max_delay_s=8.0)
    assert both.analysis_bounds() == LinkBounds("genoa-lisbon", 0.04, 8.0)
    only_max = dataclasses.replace(genoa, analysis_max_delay_s=8.0)
    assert only_max.analysis_bounds() == LinkBounds("genoa-lisbon", 0.045, 8.0)
    assert only_max.analysis_bounds().to_json() == {
        "name": "genoa-lisbon",
        "min_delay_s": 0.045,
        "max_delay_s": 8.0,
    }


def test_bounds_from_a_yaml_file(tmp_path: Path) -> None:
    path = tmp_path / "assumed.yaml"
    path.write_text("base: genoa-lisbon\nanalysis_max_delay_s: 8\nanalysis_min_delay_s: null\n")
    profile = load_link_profile(path)
    assert profile.analysis_max_delay_s == 8.0 and profile.analysis_min_delay_s is None
    assert profile.analysis_bounds() == LinkBounds("assumed", 0.045, 8.0)


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        ("analysis_max_delay_s: -1\n", ":1:23: analysis_max_delay_s:", "must not be negative"),
        ("analysis_min_delay_s: .inf\n", ":1:23: analysis_min_delay_s:", "finite"),
        ("analysis_min_delay_s: soon\n", ":1:23: analysis_min_delay_s:", "expected a number"),
        (
            "delay_s: 5\nanalysis_min_delay_s: 3\nanalysis_max_delay_s: 2\n",
            ":2:23: analysis_min_delay_s:",
            "must not exceed analysis_max_delay_s (3 > 2)",
        ),
        (
            "base: hostile\nanalysis_max_delay_s: 0.05\n",
            ":2:23: analysis_max_delay_s:",
            "(0.1 (derived) > 0.05)",
        ),
        (
            "delay_s: 1\nanalysis_min_delay_s: 2\n",
            ":2:23: analysis_min_delay_s:",
            "must not exceed delay_s, the fastest the link delivers (2 > 1)",
        ),
        (
            "analysis_max_delay: 2\n",
            ":1:21: analysis_max_delay:",
            "did you mean 'analysis_max_delay_s'",
        ),
    ],
)
def test_bad_bounds_name_file_line_and_field(text: str, where: str, message: str) -> None:
    with pytest.raises(LinkProfileError) as info:
        parse_link_profile(text, "bad.yaml")
    assert str(info.value).startswith("bad.yaml" + where), str(info.value)
    assert message in str(info.value)


def test_bounds_given_in_code_are_checked_too() -> None:
    with pytest.raises(LinkProfileError, match="link profile 'x': analysis_min_delay_s"):
        LinkProfile(name="x", analysis_min_delay_s=2.0, analysis_max_delay_s=1.0)
    with pytest.raises(LinkProfileError, match="analysis_max_delay_s: must be a finite number"):
        LinkProfile(analysis_max_delay_s=float("nan"))
