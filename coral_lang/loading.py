"""Load any net file coral accepts: a CORAL mission (``.coral``), a part of one, or a
PNML model.

The CLIs use this one entry point, so every tool accepts the same files and reports
the same errors in the same way.

A *part* is a file only included by a mission (the pool mission's phases): it starts
with ``# coral: part of FILE.coral`` (`coral_lang.compiler.part_header`). Loading a part
compiles the whole mission it names instead, so ``coral-check phases/*.coral`` checks
each part in the only context where it means something (``docs/language.md``,
"Missions in several files").
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from coral_lang.compiler import CompileResult, PartHeader, compile_file, part_header
from coral_lang.diagnostics import Diagnostic, PnmlError, Severity, Span
from coral_lang.profile import VehicleProfile
from coral_lang.safefile import MISSION_LIMIT, UnreadableFile, read_text_file

PNML_SUFFIXES = (".pnml", ".xml")
PART_CODE = "CORAL011"


def is_pnml(path: str | Path) -> bool:
    """Whether ``path`` is treated as PNML (by its suffix)."""
    return Path(path).suffix.lower() in PNML_SUFFIXES


def load_net_file(
    path: str | Path,
    profiles: Sequence[VehicleProfile] = (),
    *,
    include_path: Sequence[str | Path] = (),
) -> CompileResult:
    """Compile a mission or import a PNML model; problems come back as diagnostics.

    A part of a mission (a file starting with ``# coral: part of FILE.coral``) yields
    the compile of that whole mission, with ``part_of`` (the mission's path) and
    ``part_path`` (``path``) set; a header naming a missing file, the part itself,
    another part, or a mission that does not include the part is an error (CORAL011)
    at the header.

    ``include_path``: folders a mission's includes may also come from
    (`coral_lang.compiler.compile_file`); a PNML model includes nothing.
    """
    path = Path(path)
    if not is_pnml(path):
        found = _read_header(path)
        if found is None:
            return compile_file(path, profiles, include_path=include_path)
        text, header = found
        return _load_part(path, text, header, profiles, include_path)
    from coral_lang.pnml import read_pnml

    try:
        net = read_pnml(path)
    except PnmlError as exc:
        where = Span(str(path), 1, 1, 1, 2)
        return CompileResult(None, [Diagnostic(Severity.ERROR, "CORAL001", str(exc), where)], {})
    return CompileResult(net, [], {})


def _read_header(path: Path) -> tuple[str, PartHeader] | None:
    """The text and part header of ``path`` when it is a part with a well-placed header.

    None for anything else, an unreadable file included: `compile_file` then reads it
    and reports whatever is wrong with it (a misplaced header among the rest).
    """
    try:
        text = read_text_file(path, MISSION_LIMIT)
    except UnreadableFile:
        return None
    header, misplaced = part_header(text, str(path))
    if header is None or misplaced:
        return None
    return text, header


def _load_part(
    path: Path,
    text: str,
    header: PartHeader,
    profiles: Sequence[VehicleProfile],
    include_path: Sequence[str | Path],
) -> CompileResult:
    """The compile of the mission ``header`` names, or an error at the header.

    The mission's own diagnostics (which quote its text) are returned only once it is
    known to include the part: a header naming some unrelated file must not get that
    file's lines shown.
    """
    sources = {str(path): text}

    def refuse(message: str, *notes: str) -> CompileResult:
        diagnostic = Diagnostic(Severity.ERROR, PART_CODE, message, header.span, notes)
        return CompileResult(None, [diagnostic], sources, part_path=path)

    mission = Path(os.path.normpath(path.parent / header.mission))
    part = path.resolve()
    try:
        whole = mission.resolve()
    except (OSError, RuntimeError):  # RuntimeError: a symlink loop
        whole = mission
    if whole == part:
        return refuse(
            "a part names itself as its mission",
            "name the mission file that includes this one, relative to this file's folder",
        )
    try:
        mission_text = read_text_file(mission, MISSION_LIMIT)
    except UnreadableFile as exc:
        reason = "no such file" if exc.kind == "missing" else exc.reason
        return refuse(
            f"this file is a part of {mission}, which cannot be read: {reason}",
            "the header names the mission's file relative to this file's folder",
        )
    upper, _ = part_header(mission_text, str(mission))
    if upper is not None:
        top = os.path.relpath(os.path.normpath(mission.parent / upper.mission), path.parent)
        return refuse(
            f"{mission} is itself a part (of {upper.mission}): a part names the whole "
            "mission, not another part",
            f"write '# coral: part of {Path(top).as_posix()}'",
        )
    result = compile_file(mission, profiles, include_path=include_path)
    included = {_resolved(name) for name in result.sources}
    if part not in included:
        notes = [f"add 'include \"{path.name}\"' to {mission}, or name the right mission"]
        if result.errors:
            notes.append(f"{mission} has errors of its own: check it directly")
        return refuse(
            f"{mission} does not include this file, directly or through its includes",
            *notes,
        )
    return replace(result, part_of=mission, part_path=path)


def _resolved(name: str) -> Path | None:
    """The file a compile's source name stands for (None when it cannot be resolved)."""
    try:
        return Path(name).resolve()
    except (OSError, RuntimeError):
        return None
