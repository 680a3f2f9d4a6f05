"""Load any net file coral accepts: a CORAL mission (``.coral``) or a PNML model.

The CLIs use this one entry point, so every tool accepts the same files and reports
the same errors in the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from coral_lang.compiler import CompileResult, compile_file
from coral_lang.diagnostics import Diagnostic, PnmlError, Severity, Span
from coral_lang.profile import VehicleProfile

PNML_SUFFIXES = (".pnml", ".xml")


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

    ``include_path``: folders a mission's includes may also come from
    (`coral_lang.compiler.compile_file`); a PNML model includes nothing.
    """
    path = Path(path)
    if not is_pnml(path):
        return compile_file(path, profiles, include_path=include_path)
    from coral_lang.pnml import read_pnml

    try:
        net = read_pnml(path)
    except PnmlError as exc:
        where = Span(str(path), 1, 1, 1, 2)
        return CompileResult(None, [Diagnostic(Severity.ERROR, "CORAL001", str(exc), where)], {})
    return CompileResult(net, [], {})
