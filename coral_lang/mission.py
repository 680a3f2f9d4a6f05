"""A compiled mission as one object: its net, its sources, and the profiles behind it.

Every stage after the compiler needs the same few things: the `Net`, the file it came
from, and the vehicle profile it was checked against (the runtime takes nominal
durations from it, a certificate records it). Passing them separately let each stage
look the profile up again by vehicle name, which only finds bundled profiles and so
could not run a mission for a vehicle given with ``--profile``. A `Mission` keeps the
profile that the compiler actually used.

It also defines what a certificate records of that profile (`Mission.profile_content`):
for each command the net sends, the fields of its `CommandSpec.canonical` form. The
decision (``docs/verify.md``): a change to a command the mission does not use, to a
description or reply meaning, or to the profile file's name or place keeps a
certificate valid; any other change to a used command (kind, a parameter's type, unit
or range, the reply kinds or their order, resources, nominal duration, tracking
criterion) voids it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from coral_lang.compiler import CompileResult, compile_file
from coral_lang.diagnostics import Diagnostic
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile

__all__ = ["Mission", "load_mission", "profile_content", "profile_digest"]

DIGEST_FIELDS = ("vehicle", "commands")
"""The fields of the profile content that its digest covers: ``file`` is where the
profile was read from, which says nothing about the vehicle (the bundled profile's
path differs between installations, a copied profile behaves the same)."""


@dataclass(frozen=True)
class Mission:
    """A mission that compiled, with everything later stages need to know about it.

    Attributes:
        path: the mission file, or None for a mission compiled from text.
        net: the compiled net.
        sources: the text of every file read (the mission and its includes), by name,
            for rendering diagnostics and reports.
        profiles: the vehicle profiles it was compiled against: those given by the
            caller, in order, then the bundled one the compiler fell back to, if any.
        diagnostics: the compiler's warnings (a `Mission` exists only without errors).
        include_path: the folders its includes could come from besides its own, as
            given (a run records them, so ``coral-run --resume`` compiles it the same way).
    """

    path: Path | None
    net: Net
    sources: Mapping[str, str] = field(default_factory=dict, hash=False)
    profiles: tuple[VehicleProfile, ...] = ()
    diagnostics: tuple[Diagnostic, ...] = ()
    include_path: tuple[Path, ...] = ()

    def __post_init__(self) -> None:
        # Read-only, so that a frozen Mission cannot have its sources edited behind it.
        object.__setattr__(self, "sources", MappingProxyType(dict(self.sources)))
        object.__setattr__(self, "profiles", tuple(self.profiles))
        object.__setattr__(self, "diagnostics", tuple(self.diagnostics))
        object.__setattr__(self, "include_path", tuple(Path(p) for p in self.include_path))

    @classmethod
    def from_result(
        cls,
        result: CompileResult,
        path: str | Path | None,
        profiles: Sequence[VehicleProfile] = (),
        include_path: Sequence[str | Path] = (),
    ) -> Mission:
        """The mission ``result`` describes, compiled from ``path`` with ``profiles``
        (and its includes looked for in ``include_path`` too).

        Raises:
            CompileError: the compile had errors (every one is listed).
        """
        net = result.raise_for_errors()
        used = tuple(profiles)
        if result.profile is not None and result.profile not in used:
            used += (result.profile,)  # the bundled profile the compiler fell back to
        return cls(
            path=None if path is None else Path(path),
            net=net,
            sources=result.sources,
            profiles=used,
            diagnostics=tuple(result.diagnostics),
            include_path=tuple(Path(p) for p in include_path),
        )

    @property
    def profile(self) -> VehicleProfile | None:
        """The profile of the net's vehicle, or None for a net without one (a PNML model).

        The first of `profiles` with that name, the one the compiler used.
        """
        if self.net.vehicle is None:
            return None
        return next((p for p in self.profiles if p.name == self.net.vehicle), None)

    def profile_content(self) -> dict[str, object]:
        """What a certificate records of the vehicle profile: see `profile_content`."""
        return profile_content(self.net, self.profile)

    def profile_digest(self) -> str:
        """``sha256:...`` of `profile_content` (its ``vehicle`` and ``commands``)."""
        return profile_digest(self.profile_content())


def load_mission(
    path: str | Path,
    profiles: Sequence[VehicleProfile] = (),
    *,
    include_path: Sequence[str | Path] = (),
) -> Mission:
    """Compile the mission in ``path`` against ``profiles`` (then the bundled ones);
    its includes may also come from the ``include_path`` folders.

    Raises:
        CompileError: the mission does not compile; every error is listed, with its
            file, line and column.
    """
    path = Path(path)
    result = compile_file(path, profiles, include_path=include_path)
    return Mission.from_result(result, path, profiles, include_path)


def profile_content(net: Net, profile: VehicleProfile | None) -> dict[str, object]:
    """The part of ``profile`` that ``net``'s behaviour depends on, as plain JSON data.

    ``{"vehicle": NAME, "file": PATH, "commands": {NAME: CommandSpec.canonical()}}``,
    with only the commands some transition of ``net`` sends, sorted by name. A command
    the net sends that ``profile`` lacks is left out, so comparing with the content
    recorded earlier reports it as removed. Without a profile (a net of no vehicle, or
    a PNML model) ``file`` is None and ``commands`` empty.
    """
    used = sorted({t.command.name for t in net.transitions if t.command is not None})
    commands: dict[str, object] = {}
    if profile is not None:
        for name in used:
            spec = profile.command(name)
            if spec is not None:
                commands[name] = spec.canonical()
    content: dict[str, object] = {
        "vehicle": profile.name if profile is not None else net.vehicle,
        "file": profile.file if profile is not None else None,
        "commands": commands,
    }
    # The timing block only when the profile declares one: timed analysis assumed it,
    # and every certificate issued before it existed keeps its digest.
    timing = profile.canonical_timing() if profile is not None else None
    if timing is not None:
        content["timing"] = timing
    return content


def profile_digest(content: Mapping[str, object]) -> str:
    """``sha256:<hex>`` of the `DIGEST_FIELDS` of ``content``, as canonical JSON.

    Stable across runs and platforms (sorted keys, no whitespace), and the same for
    content read back from a certificate's JSON as for content just computed.
    """
    covered = {key: content.get(key) for key in DIGEST_FIELDS}
    if content.get("timing") is not None:
        covered["timing"] = content["timing"]
    blob = json.dumps(covered, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(blob.encode()).hexdigest()
