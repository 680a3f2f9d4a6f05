"""ROMEO's `Vehicle.make_safe`: the watchdog's surfacing, at the controller's request."""

from __future__ import annotations

import pytest

from romeo_sim.vehicle import Vehicle
from runtime.vehicle import VehicleModel
from tests.romeo_sim.conftest import run


def test_make_safe_surfaces_at_once_with_the_watchdogs_replies() -> None:
    vehicle = Vehicle()
    assert isinstance(vehicle, VehicleModel)
    vehicle.command(1, "DEPTH", {"z": 2.0})
    vehicle.command(2, "DEPTH?", {"z": 2.5, "time_out": 300.0})  # never reached
    run(vehicle, 20.0)
    deep = vehicle.telemetry().z
    assert deep > 1.0
    replies = vehicle.make_safe("SIGTERM")
    assert [(r.command_id, r.kind) for r in replies] == [(2, "timeout")]
    assert replies[0].time == pytest.approx(20.0, abs=0.06)
    assert "make itself safe" in replies[0].detail
    (event,) = [e for e in vehicle.events if e.text.startswith("make-safe")]
    assert "SIGTERM" in event.text and event.time == pytest.approx(20.0, abs=0.06)
    (line,) = vehicle.status()
    assert line.startswith("SURFACE (id -1) since 20.0 s")
    # It surfaces by itself, and the watchdog does not do it again meanwhile.
    run(vehicle, 60.0, keep_alive=False)
    assert vehicle.telemetry().z < 0.1 < deep
    assert not any(e.text.startswith("watchdog") for e in vehicle.events)
    # A repeat is harmless: nothing left to stop, no reply.
    assert vehicle.make_safe("SIGTERM") == []


def test_make_safe_interrupts_a_position_fix() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "FIX_XY", {})
    vehicle.advance(0.5)
    replies = vehicle.make_safe("SIGINT")
    assert [(r.command_id, r.kind) for r in replies] == [(1, "error")]
