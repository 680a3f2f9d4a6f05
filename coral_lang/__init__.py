"""The CORAL language: mission text to a Petri net, checked against a vehicle profile.

Typical use::

    from coral_lang import compile_file
    result = compile_file("examples/pool_mission/pool_mission.coral")
    if not result.ok:
        print(render_all(result.diagnostics, result.sources))
    net = result.net

or, raising `CompileError` instead, a `Mission` that keeps the net with the profile
it was compiled against (what the runtime and certificates need)::

    mission = load_mission("survey.coral", [load_profile("minnow.yaml")])
    mission.net, mission.profile

The PNML functions (`read_pnml`, `parse_pnml`, `to_pnml`, `write_pnml`) load their XML
machinery on first use, so tools that never touch PNML start faster.
"""

from typing import TYPE_CHECKING

from coral_lang.compiler import CompileResult, compile_file, compile_mission, compile_source
from coral_lang.diagnostics import (
    CompileError,
    CoralError,
    Diagnostic,
    PnmlError,
    ProfileError,
    Severity,
    Span,
    render_all,
)
from coral_lang.dot import to_dot
from coral_lang.loading import load_net_file
from coral_lang.mission import Mission, load_mission
from coral_lang.net import (
    Assertion,
    AssertKind,
    Command,
    FinalMarking,
    Net,
    NetError,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
)
from coral_lang.parser import parse
from coral_lang.printer import format_mission
from coral_lang.profile import (
    CommandSpec,
    ParamSpec,
    SpaceTrap,
    VehicleProfile,
    load_bundled_profile,
    load_profile,
    parse_profile,
)

if TYPE_CHECKING:
    from coral_lang.pnml import parse_pnml, read_pnml, to_pnml, write_pnml

_LAZY = {"parse_pnml", "read_pnml", "to_pnml", "write_pnml"}


def __getattr__(name: str) -> object:
    """The PNML names, imported from `coral_lang.pnml` when first asked for: its XML
    parser and writer take about 50 ms to load."""
    if name in _LAZY:
        from coral_lang import pnml

        value: object = getattr(pnml, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'coral_lang' has no attribute {name!r}")


__all__ = [
    "AssertKind",
    "Assertion",
    "Command",
    "CommandSpec",
    "CompileError",
    "CompileResult",
    "CoralError",
    "Diagnostic",
    "FinalMarking",
    "Mission",
    "Net",
    "NetError",
    "ParamSpec",
    "Place",
    "PlaceKind",
    "PnmlError",
    "ProfileError",
    "Severity",
    "SpaceTrap",
    "Span",
    "Transition",
    "TransitionKind",
    "VehicleProfile",
    "compile_file",
    "compile_mission",
    "compile_source",
    "format_mission",
    "load_bundled_profile",
    "load_mission",
    "load_net_file",
    "load_profile",
    "parse",
    "parse_pnml",
    "parse_profile",
    "read_pnml",
    "render_all",
    "to_dot",
    "to_pnml",
    "write_pnml",
]
