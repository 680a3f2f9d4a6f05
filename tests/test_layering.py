"""The import layering of coral's four packages (docs/architecture.md).

Every ``import`` in every module is read from the source (lazy imports inside functions
included), so a forbidden dependency fails here even when no test happens to execute it.

* ``coral_lang`` imports nothing of ours;
* ``analysis`` imports ``coral_lang`` only;
* ``runtime`` (the controller's side) imports ``coral_lang``, ``analysis`` and itself, and
  never a vehicle implementation (``romeo_sim``, ``runtime.vehicle.generic``): it reaches
  simulated vehicles through ``runtime.vehicle.registry``, by name;
* the vehicle side (``runtime.vehicle``, and the modules both sides share:
  ``runtime.protocol`` (a package: every ``runtime.protocol.*`` module, by prefix),
  ``runtime.eventlog``, ``runtime.telemetry``, ``runtime.faultplan``, ``runtime.keys``)
  imports ``coral_lang`` and itself only, so a vehicle can be built on it without the engine;
* ``romeo_sim`` imports ``coral_lang`` and the vehicle side only.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("coral_lang", "analysis", "runtime", "romeo_sim")
SHARED = (
    "runtime.protocol",
    "runtime.eventlog",
    "runtime.telemetry",
    "runtime.faultplan",
    "runtime.keys",
)
VEHICLE_IMPLEMENTATIONS = ("romeo_sim", "runtime.vehicle.generic")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in ``path`` that names one of our packages."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found: list[tuple[int, str]] = []
    package = _module_name(path).rpartition(".")[0] if path.name != "__init__.py" else None
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package if package is not None else _module_name(path)
                for _ in range(node.level - 1):
                    anchor = anchor.rpartition(".")[0]
                base = f"{anchor}.{base}" if base else anchor
            found.append((node.lineno, base))
    return [(line, name) for line, name in found if name.split(".")[0] in PACKAGES]


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _is_vehicle_side(module: str) -> bool:
    return _within(module, ("runtime.vehicle", *SHARED))


def _allowed(module: str) -> tuple[str, ...]:
    """The modules ``module`` may import from (by prefix)."""
    top = module.split(".")[0]
    if top == "coral_lang":
        return ("coral_lang",)
    if top == "analysis":
        return ("coral_lang", "analysis")
    if top == "romeo_sim":
        return ("coral_lang", "romeo_sim", "runtime.vehicle", *SHARED)
    if _is_vehicle_side(module):
        return ("coral_lang", "runtime.vehicle", *SHARED)
    return ("coral_lang", "analysis", "runtime")


def _violations() -> list[str]:
    problems: list[str] = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            module = _module_name(path)
            allowed = _allowed(module)
            for line, name in _imports(path):
                where = f"{path.relative_to(ROOT)}:{line}"
                if not _within(name, allowed):
                    problems.append(f"{where}: {module} imports {name}")
                elif (
                    module.startswith("runtime")
                    and not _within(module, VEHICLE_IMPLEMENTATIONS)
                    and _within(name, VEHICLE_IMPLEMENTATIONS)
                ):
                    problems.append(
                        f"{where}: {module} imports the vehicle implementation {name} "
                        "(use runtime.vehicle.registry)"
                    )
    return problems


@pytest.mark.slow
def test_every_package_keeps_its_layer() -> None:
    assert _violations() == []


@pytest.mark.parametrize(
    ("module", "imported", "ok"),
    [
        ("coral_lang.net", "analysis.report", False),
        ("analysis.verify", "runtime.engine", False),
        ("runtime.run", "romeo_sim.vehicle", False),
        ("runtime.run", "runtime.vehicle.generic", False),
        ("runtime.run", "runtime.vehicle.registry", True),
        ("runtime.simvehicle", "romeo_sim.vehicle", False),
        ("runtime.simvehicle", "runtime.vehicle.registry", True),
        ("coral_lang.cliframe", "analysis.cli", False),
        ("romeo_sim.cli", "coral_lang.cliframe", True),
        ("runtime.vehicle.server", "runtime.controller", False),
        ("runtime.protocol", "runtime.engine", False),
        ("runtime.protocol.codec", "runtime.engine", False),
        ("runtime.protocol.codec", "runtime.protocol.wire", True),
        ("runtime.protocol.messages", "runtime.telemetry", True),
        ("runtime.telemetry", "runtime.controller", False),
        ("runtime.vehicle.model", "runtime.telemetry", True),
        ("romeo_sim.vehicle", "runtime.telemetry", True),
        ("romeo_sim.server", "runtime.vehicle.server", True),
        ("romeo_sim.server", "runtime.controller", False),
        ("romeo_sim.scenario", "analysis.verify", False),
    ],
)
def test_the_rules_themselves(module: str, imported: str, ok: bool) -> None:
    """The checker is not vacuous: each rule refuses what it should."""
    allowed = _within(imported, _allowed(module))
    implementation = (
        module.startswith("runtime")
        and not _within(module, VEHICLE_IMPLEMENTATIONS)
        and _within(imported, VEHICLE_IMPLEMENTATIONS)
    )
    assert (allowed and not implementation) is ok


def test_relative_imports_are_resolved(tmp_path: Path) -> None:
    """``from ..engine import X`` inside runtime/vehicle counts as runtime.engine."""
    del tmp_path
    source = ROOT / "runtime" / "vehicle" / "model.py"
    assert all(not name.startswith(".") for _, name in _imports(source))
