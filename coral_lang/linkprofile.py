"""Link profiles: how good or bad the link between controller and vehicle is.

A `LinkProfile` is the numbers the link emulator (`runtime.emulator`) draws from: the
serial line's speed, the Internet's delay and its heavy tail, rare multi-second stalls,
datagram loss, duplication and reordering, connection resets and outages. Four come
built in (`BUILTIN_PROFILES`); ``load_link_profile`` also reads one from a YAML file,
and names the file, line and field of any mistake. ``docs/link.md`` documents every
field and where the built-in numbers come from.

It lives in ``coral_lang``, not beside the emulator in ``runtime``, because it is plain
data and timed analysis (``coral-check verify --timed --link NAME|FILE``, in
``analysis``, which may import ``coral_lang`` only) reads the same profiles: a profile
says what delays the emulator draws, and `LinkProfile.analysis_bounds` what analysis
assumes of them. ``runtime.linkprofile`` re-exports every name here.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from coral_lang.diagnostics import CoralError, ProfileError, did_you_mean
from coral_lang.safefile import PROFILE_LIMIT, UnreadableFile, read_text_file
from coral_lang.timing import LinkBounds
from coral_lang.yamlsource import Plain, YamlDocument, load_yaml

__all__ = [
    "ANALYSIS_FRAME_BYTES",
    "BUILTIN_PROFILES",
    "LinkProfile",
    "LinkProfileError",
    "load_link_profile",
    "parse_link_profile",
]


class LinkProfileError(CoralError, ValueError):
    """A link profile that cannot be used; ``source`` and ``field`` say where.

    Usually a misspelt profile name or field, a probability outside 0..1, or a negative
    time. Fix the field named in the message, or start the file with ``base: <built-in
    name>`` and set only the fields that differ.
    """

    def __init__(self, source: str, field: str, message: str) -> None:
        self.source = source
        self.field = field
        self.detail = message
        super().__init__(f"{source}: {field}: {message}" if field else f"{source}: {message}")


# Field kinds, checked in __post_init__ and when reading YAML.
_PROBABILITIES = ("stall_probability", "datagram_loss", "datagram_duplicate", "datagram_reorder")
_DURATIONS = (
    "delay_s",
    "jitter_scale_s",
    "jitter_cap_s",
    "stall_min_s",
    "stall_max_s",
    "reorder_delay_s",
    "outage_min_s",
    "outage_max_s",
)
_RATES = ("reset_rate_per_s", "outage_rate_per_s")
_POSITIVE = ("bits_per_byte", "jitter_shape")
_COUNTS = ("stream_overhead_bytes", "datagram_overhead_bytes")
_RANGES = (("stall_min_s", "stall_max_s"), ("outage_min_s", "outage_max_s"))
_OPTIONAL_DURATIONS = ("analysis_min_delay_s", "analysis_max_delay_s")

ANALYSIS_FRAME_BYTES = 4096
"""The frame size the derived analysis bound allows serialisation time for: four times
the protocol's largest frame (1 KiB), so that a command or reply queued behind up to
three other frames on a slow line is still within the bound."""


@dataclass(frozen=True)
class LinkProfile:
    """The impairments of one link, both directions alike. All times in seconds.

    Attributes:
        name: what logs and reports call it.
        bandwidth_bps: line speed of each direction in bits per second; None: unlimited
            (no serialisation time). Bytes of one direction, stream and datagrams alike,
            queue behind each other.
        bits_per_byte: line bits per data byte: 10 for an 8N1 serial line (start and stop
            bits), 8 for a synchronous link.
        stream_overhead_bytes: extra bytes on the line per stream chunk (TCP/IP headers).
        datagram_overhead_bytes: extra bytes on the line per datagram (UDP/IP headers).
        delay_s: base one-way delay, added to everything after serialisation.
        jitter_scale_s: scale of the heavy-tailed extra delay (Lomax, i.e. Pareto type II:
            ``scale * (U ** (-1 / shape) - 1)``); 0: no jitter.
        jitter_shape: tail index of that distribution; smaller is heavier (below 2 the
            variance is infinite, as measured on Internet paths).
        jitter_cap_s: largest jitter sample; longer delays come only from stalls.
        stall_probability: chance that a stream chunk or a datagram is caught in a stall
            (a route change, a mobile link retraining); on the stream it holds up every
            later byte of its direction too.
        stall_min_s: shortest stall.
        stall_max_s: longest stall (the paper saw about 7 s).
        datagram_loss: chance that a datagram is lost.
        datagram_duplicate: chance that a delivered datagram arrives twice.
        datagram_reorder: chance that a datagram is held back so that later ones overtake it.
        reorder_delay_s: a held-back datagram waits an extra time drawn uniformly from
            0..reorder_delay_s.
        reset_rate_per_s: mean connection resets per second of connected time (Poisson).
        outage_rate_per_s: mean outages per second (Poisson). During an outage connecting
            fails, the current connection dies with the bytes in flight, and datagrams
            are lost.
        outage_min_s: shortest outage.
        outage_max_s: longest outage.
        analysis_min_delay_s: shortest one-way delay timed analysis assumes; None:
            derived (`analysis_bounds`).
        analysis_max_delay_s: longest one-way delay timed analysis assumes; None:
            derived (`analysis_bounds`).

    Raises:
        LinkProfileError: a value out of its range (probabilities 0..1, times and rates
            finite and not negative, shape and bits per byte positive, min <= max).
    """

    name: str = "custom"
    bandwidth_bps: float | None = None
    bits_per_byte: float = 10.0
    stream_overhead_bytes: int = 0
    datagram_overhead_bytes: int = 0
    delay_s: float = 0.0
    jitter_scale_s: float = 0.0
    jitter_shape: float = 2.0
    jitter_cap_s: float = 2.0
    stall_probability: float = 0.0
    stall_min_s: float = 0.0
    stall_max_s: float = 0.0
    datagram_loss: float = 0.0
    datagram_duplicate: float = 0.0
    datagram_reorder: float = 0.0
    reorder_delay_s: float = 0.0
    reset_rate_per_s: float = 0.0
    outage_rate_per_s: float = 0.0
    outage_min_s: float = 0.0
    outage_max_s: float = 0.0
    analysis_min_delay_s: float | None = None
    analysis_max_delay_s: float | None = None

    def __post_init__(self) -> None:
        problem = _check(self)
        if problem is not None:
            raise LinkProfileError(f"link profile '{self.name}'", *problem)

    def serialisation_time(self, size: int) -> float:
        """Seconds the line takes to carry ``size`` bytes (0 when unlimited)."""
        if self.bandwidth_bps is None:
            return 0.0
        return size * self.bits_per_byte / self.bandwidth_bps

    @property
    def jitter_median_s(self) -> float:
        """Median of the jitter distribution (before the cap)."""
        return self.jitter_scale_s * (math.pow(2.0, 1.0 / self.jitter_shape) - 1.0)

    def analysis_bounds(self) -> LinkBounds:
        """The one-way delay bounds timed analysis assumes on this link.

        The profile's own ``analysis_min_delay_s`` / ``analysis_max_delay_s`` when it
        gives them, else the derived ones (`derived_min_delay_s`, `derived_max_delay_s`).
        Named after the profile, so reports say which link they assumed.
        """
        low = self.analysis_min_delay_s
        high = self.analysis_max_delay_s
        return LinkBounds(
            name=self.name,
            min_delay_s=self.derived_min_delay_s if low is None else low,
            max_delay_s=self.derived_max_delay_s if high is None else high,
        )

    @property
    def derived_min_delay_s(self) -> float:
        """The shortest delay the emulator gives a message: the base ``delay_s`` (jitter,
        stalls and serialisation only add to it)."""
        return self.delay_s

    @property
    def derived_max_delay_s(self) -> float:
        """The longest delay the emulator gives a message that is not lost, when no
        outage or reset happens and the line is not queued beyond one
        `ANALYSIS_FRAME_BYTES` frame.

        The sum of every delay the emulator can add that this profile turns on: the
        base ``delay_s``; the jitter, never more than ``jitter_cap_s`` (the emulator caps
        every sample); a stall of at most ``stall_max_s``; a held-back datagram's
        ``reorder_delay_s``; and the line's serialisation of a 4 KiB frame with its
        stream header. A stream chunk held up behind an earlier one (head of line) is
        within it too: the earlier one was sent first, with the same bound.
        """
        total = self.delay_s
        if self.jitter_scale_s > 0.0:
            total += self.jitter_cap_s
        if self.stall_probability > 0.0:
            total += self.stall_max_s
        if self.datagram_reorder > 0.0:
            total += self.reorder_delay_s
        frame = ANALYSIS_FRAME_BYTES + max(self.stream_overhead_bytes, self.datagram_overhead_bytes)
        return total + self.serialisation_time(frame)


def _check(profile: LinkProfile) -> tuple[str, str] | None:
    """The first (field, problem) of ``profile``, or None if it is usable."""
    if not isinstance(profile.name, str) or not profile.name:
        return "name", "must be a non-empty string"
    bandwidth = profile.bandwidth_bps
    if bandwidth is not None and not (_is_number(bandwidth) and 0 < bandwidth < math.inf):
        return "bandwidth_bps", f"must be a positive number or null (unlimited), got {bandwidth!r}"
    for name in _COUNTS:
        value = getattr(profile, name)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            return name, f"must be a whole number of bytes >= 0, got {value!r}"
    for name in (*_PROBABILITIES, *_DURATIONS, *_RATES, *_POSITIVE):
        value = getattr(profile, name)
        if not _is_number(value) or not math.isfinite(value):
            return name, f"must be a finite number, got {value!r}"
    for name in _PROBABILITIES:
        if not 0.0 <= getattr(profile, name) <= 1.0:
            return name, f"is a probability: between 0 and 1, got {getattr(profile, name)!r}"
    for name in (*_DURATIONS, *_RATES):
        if getattr(profile, name) < 0.0:
            return name, f"must not be negative, got {getattr(profile, name)!r}"
    for name in _POSITIVE:
        if getattr(profile, name) <= 0.0:
            return name, f"must be positive, got {getattr(profile, name)!r}"
    for low, high in _RANGES:
        if getattr(profile, low) > getattr(profile, high):
            return (
                low,
                f"must not exceed {high} ({getattr(profile, low)} > {getattr(profile, high)})",
            )
    return _check_analysis_bounds(profile)


def _check_analysis_bounds(profile: LinkProfile) -> tuple[str, str] | None:
    """The first problem of the analysis bounds, given or derived, or None.

    A given bound is a finite number >= 0 or null; the pair in effect (a given one with
    the other derived) must have min <= max, so a profile that sets only
    ``analysis_min_delay_s`` above the derived maximum is refused when it loads, not
    when analysis first asks for its bounds.
    """
    for name in _OPTIONAL_DURATIONS:
        value = getattr(profile, name)
        if value is None:
            continue
        if not _is_number(value) or not math.isfinite(value):
            return name, f"must be a finite number or null (derived), got {value!r}"
        if value < 0.0:
            return name, f"must not be negative, got {value!r}"
    low, high = profile.analysis_min_delay_s, profile.analysis_max_delay_s
    if low is not None and low > profile.derived_min_delay_s:
        # The emulator delivers as fast as delay_s: assuming slower would hide the runs
        # in which a fast link makes a query time out.
        return (
            "analysis_min_delay_s",
            f"must not exceed delay_s, the fastest the link delivers "
            f"({low:g} > {profile.derived_min_delay_s:g})",
        )
    effective_low = profile.derived_min_delay_s if low is None else low
    effective_high = profile.derived_max_delay_s if high is None else high
    if effective_low > effective_high:
        field = "analysis_min_delay_s" if low is not None else "analysis_max_delay_s"
        low_text = f"{effective_low:g}" + (" (derived)" if low is None else "")
        high_text = f"{effective_high:g}" + (" (derived)" if high is None else "")
        return (
            field,
            f"analysis_min_delay_s must not exceed analysis_max_delay_s ({low_text} > {high_text})",
        )
    return None


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


BUILTIN_PROFILES: dict[str, LinkProfile] = {
    # Everything delivered at once, nothing lost: for tests of the logic alone.
    "ideal": LinkProfile(name="ideal"),
    # A local network: fast, sub-millisecond, never loses anything.
    "lan": LinkProfile(
        name="lan",
        bandwidth_bps=100e6,
        bits_per_byte=8.0,
        stream_overhead_bytes=40,
        datagram_overhead_bytes=28,
        delay_s=0.0002,
        jitter_scale_s=0.0001,
        jitter_shape=3.0,
        jitter_cap_s=0.002,
    ),
    # The paper's experiment (section IV): Lisbon to Genoa over the Internet, and the last
    # stretch to the pool over a 9600 bps mobile phone serial data link; delays of about
    # 7 s seen on two commands. See docs/link.md for each number.
    "genoa-lisbon": LinkProfile(
        name="genoa-lisbon",
        bandwidth_bps=9600.0,
        bits_per_byte=10.0,
        stream_overhead_bytes=40,
        datagram_overhead_bytes=28,
        delay_s=0.045,
        jitter_scale_s=0.03,
        jitter_shape=1.5,
        jitter_cap_s=2.0,
        stall_probability=0.004,
        stall_min_s=2.0,
        stall_max_s=7.0,
        datagram_loss=0.01,
        datagram_duplicate=0.002,
        datagram_reorder=0.01,
        reorder_delay_s=0.6,
        reset_rate_per_s=0.0005,
        outage_rate_per_s=0.0002,
        outage_min_s=10.0,
        outage_max_s=60.0,
    ),
    # Everything bad and often: for tests of the controller's recovery.
    "hostile": LinkProfile(
        name="hostile",
        bandwidth_bps=9600.0,
        bits_per_byte=10.0,
        stream_overhead_bytes=40,
        datagram_overhead_bytes=28,
        delay_s=0.1,
        jitter_scale_s=0.1,
        jitter_shape=1.2,
        jitter_cap_s=3.0,
        stall_probability=0.05,
        stall_min_s=1.0,
        stall_max_s=7.0,
        datagram_loss=0.2,
        datagram_duplicate=0.05,
        datagram_reorder=0.1,
        reorder_delay_s=1.0,
        reset_rate_per_s=0.03,
        outage_rate_per_s=0.02,
        outage_min_s=1.0,
        outage_max_s=10.0,
    ),
}


def load_link_profile(spec: str | os.PathLike[str]) -> LinkProfile:
    """A built-in profile by name, or one read from a YAML file.

    The file is a mapping of `LinkProfile` fields. ``base: <built-in name>`` starts from
    that profile, so a file need only list what differs; without it every field not
    given is the ``ideal`` profile's. ``name`` defaults to the file's stem.

    Raises:
        LinkProfileError: an unknown name, an unreadable file, YAML that is not a mapping
            of known fields, or a value of the wrong type or out of range. The message
            names the file, the line and column when known, and the field.
    """
    if isinstance(spec, str) and spec in BUILTIN_PROFILES:
        return BUILTIN_PROFILES[spec]
    path = Path(spec)
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        known = ", ".join(BUILTIN_PROFILES)
        raise LinkProfileError(
            "link profile",
            "",
            f"'{spec}' is neither a built-in profile{did_you_mean(str(spec), BUILTIN_PROFILES)}"
            f" nor a YAML file; built-in: {known}",
        )
    try:  # a regular file of at most PROFILE_LIMIT bytes: never a FIFO or /dev/zero
        text = read_text_file(path, PROFILE_LIMIT)
    except UnreadableFile as exc:
        raise LinkProfileError(
            str(path), "", f"cannot read the link profile: {exc.reason}"
        ) from None
    return parse_link_profile(text, str(path))


def parse_link_profile(text: str, file: str) -> LinkProfile:
    """A profile from YAML text (see `load_link_profile`); ``file`` names it in errors."""
    try:
        document = load_yaml(text, file)
    except ProfileError as exc:  # not valid YAML
        raise LinkProfileError(exc.file, "", exc.detail) from None
    data = document.data
    if not isinstance(data, dict):
        raise _error(document, "", "expected a mapping of link profile fields")
    base = BUILTIN_PROFILES["ideal"]
    if "base" in data:
        name = data["base"]
        if not isinstance(name, str) or name not in BUILTIN_PROFILES:
            known = ", ".join(BUILTIN_PROFILES)
            hint = did_you_mean(name, BUILTIN_PROFILES) if isinstance(name, str) else ""
            raise _error(
                document, "base", f"unknown built-in profile {name!r}{hint}; one of {known}"
            )
        base = BUILTIN_PROFILES[name]
    known_fields = {f.name: f for f in fields(LinkProfile)}
    values: dict[str, Any] = {"name": Path(file).stem}
    for key, value in data.items():
        if key == "base":
            continue
        if key not in known_fields:
            hint = did_you_mean(key, [*known_fields, "base"])
            raise _error(document, key, f"unknown field{hint}")
        values[key] = _convert(document, key, value)
    candidate = _unchecked(base, values)
    problem = _check(candidate)
    if problem is not None:
        raise _error(document, *problem)
    return replace(base, **values)


def _convert(document: YamlDocument, key: str, value: Plain) -> object:
    if key == "name":
        if not isinstance(value, str) or not value:
            raise _error(document, key, "expected a non-empty string")
        return value
    if key in ("bandwidth_bps", *_OPTIONAL_DURATIONS) and value is None:
        return None
    if key in _COUNTS:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _error(document, key, f"expected a whole number of bytes, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _error(document, key, f"expected a number, got {value!r}")
    return float(value)


def _unchecked(base: LinkProfile, values: dict[str, Any]) -> LinkProfile:
    """``base`` with ``values`` applied, without validation (so YAML errors get positions)."""
    candidate = object.__new__(LinkProfile)
    for f in fields(LinkProfile):
        object.__setattr__(candidate, f.name, values.get(f.name, getattr(base, f.name)))
    return candidate


def _error(document: YamlDocument, key: str, message: str) -> LinkProfileError:
    position = document.positions.get(key)
    where = f"{document.file}:{position[0]}:{position[1]}" if position else document.file
    return LinkProfileError(where, key, message)
