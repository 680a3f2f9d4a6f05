"""The public surface of romeo_sim, pinned: changing it is a decision, not an accident."""

from __future__ import annotations

import romeo_sim


def test_public_names() -> None:
    assert sorted(romeo_sim.__all__) == sorted(
        [
            "SUPPORTED_COMMANDS",
            "CommandRecord",
            "MissionResult",
            "Phase",
            "PoolMission",
            "Recorder",
            "Reply",
            "Telemetry",
            "Vehicle",
            "VehicleConfig",
            "VehicleConfigError",
            "VehicleEvent",
            "default_config",
            "load_vehicle_config",
            "parse_vehicle_config",
            "run_pool_mission",
        ]
    )
    for name in romeo_sim.__all__:
        assert getattr(romeo_sim, name) is not None


def test_romeo_sim_imports_only_the_allowed_parts_of_coral() -> None:
    """Design rule: the vehicle side shares with the controller only what both ends of the
    link must agree on: the profile, the wire protocol, the key format and the event log
    format, and the vehicle-side library (runtime.vehicle) built on them. Never the engine,
    analysis or the compiler (tests/test_layering.py pins the rule for every package)."""
    import ast
    from pathlib import Path

    package = Path(romeo_sim.__file__).parent
    for source in package.glob("*.py"):
        tree = ast.parse(source.read_text())
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                top = name.split(".")[0]
                if top in ("coral_lang", "analysis", "runtime"):
                    assert name.startswith("runtime.vehicle.") or name in (
                        "coral_lang.profile",
                        "coral_lang.cliframe",
                        "runtime.protocol",
                        "runtime.telemetry",
                        "runtime.keys",
                        "runtime.eventlog",
                    ), (source, name)


def test_no_wall_clock_inside_the_vehicle() -> None:
    from pathlib import Path

    package = Path(romeo_sim.__file__).parent
    for source in package.glob("*.py"):
        text = source.read_text()
        for call in ("time.time(", "time.monotonic(", "perf_counter(", "datetime.now("):
            assert call not in text, (source.name, call)
