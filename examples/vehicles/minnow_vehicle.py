"""MINNOW (examples/profiles/minnow.yaml) on fake hardware, served on the coral wire.

Run: python examples/vehicles/minnow_vehicle.py KEY_FILE [--speed 20]  (or CORAL_KEY_FILE=...)
Replace FakeMinnow by your autopilot's driver; the handlers stay. See docs/vehicles.md.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from coral_lang.profile import load_profile
from runtime.keys import KeyProblem, load_psk
from runtime.vehicle import HandlerVehicle, Job, Outcome, Refused, TelemetryRecord, run_vehicle

PROFILE = Path(__file__).resolve().parents[1] / "profiles" / "minnow.yaml"


class FakeMinnow:
    """Stands in for the autopilot's driver: depth and position move towards set-points."""

    def __init__(self, warp: float = 1.0) -> None:
        self.warp, self.t, self.x, self.y, self.z, self.psi = warp, 0.0, 0.0, 0.0, 0.0, 0.0
        self.z_set, self.speed, self.fixed = 0.0, 0.0, False
        self.goal: tuple[float, float] | None = None

    def at(self, now: float) -> FakeMinnow:
        """The state at vehicle time ``now`` (warp > 1: a faster-than-life fake, for tests)."""
        dt, self.t = (now - self.t) * self.warp, now
        self.z += max(-0.5 * dt, min(0.5 * dt, self.z_set - self.z))
        if self.goal is not None and self.goal != (self.x, self.y):
            dx, dy = self.goal[0] - self.x, self.goal[1] - self.y
            step, self.psi = self.speed * dt / math.hypot(dx, dy), math.degrees(math.atan2(dy, dx))
            self.x, self.y = self.goal if step >= 1.0 else (self.x + step * dx, self.y + step * dy)
        return self

    def telemetry(self, now: float) -> TelemetryRecord:
        self.at(now)
        return TelemetryRecord(now, self.x, self.y, self.z, self.psi % 360.0)

    def set_depth(self, z: float) -> None:
        self.z_set = z

    def halt(self) -> None:
        self.goal = None

    def surface(self) -> None:
        self.z_set, self.goal = 0.0, None


def build_vehicle(warp: float = 1.0) -> HandlerVehicle:
    """MINNOW's commands, one handler each, on a `FakeMinnow`."""
    hw = FakeMinnow(warp)

    def gps_fix(job: Job) -> Outcome:
        if hw.at(job.now).z > 0.3:
            return "error", "the antenna is under water"
        hw.fixed = hw.fixed or job.elapsed >= 10.0  # a fix takes 10 s at the surface
        return "done" if job.elapsed >= 10.0 else None

    def survey_line(job: Job) -> None:
        if not hw.fixed:
            raise Refused("no position estimate: get a GPS fix first")
        hw.goal, hw.speed = (job["x1"], job["y1"]), job["speed"]

    def line_end(job: Job) -> Outcome:
        return "done" if hw.at(job.now).goal == (hw.x, hw.y) else None

    vehicle = HandlerVehicle(load_profile(PROFILE), on_watchdog=hw.surface, telemetry=hw.telemetry)
    vehicle.on("INIT", poll=lambda job: "done" if job.elapsed >= 2.0 else None)
    vehicle.on("GPS_FIX?", poll=gps_fix)
    vehicle.on("DIVE", start=lambda job: hw.set_depth(job["z"]))
    vehicle.on(
        "DEPTH?", poll=lambda job: "done" if abs(hw.at(job.now).z - job["z"]) < 0.1 else None
    )
    vehicle.on("SURVEY_LINE", start=survey_line, stop=lambda job: hw.halt())
    vehicle.on("LINE_END?", poll=line_end)
    vehicle.on("SURFACE", start=lambda job: hw.surface())
    vehicle.on("SURFACE?", poll=lambda job: "done" if hw.at(job.now).z < 0.2 else None)
    return vehicle


def main(argv: list[str] | None = None) -> int:
    """Serve MINNOW on 127.0.0.1 until Ctrl-C; the exit code of `run_vehicle`."""
    parser = argparse.ArgumentParser(description="MINNOW on fake hardware, on the coral wire")
    parser.add_argument("key_file", nargs="?", default=os.environ.get("CORAL_KEY_FILE"))
    parser.add_argument("--speed", type=float, default=1.0, help="vehicle s per wall s")
    args = parser.parse_args(argv)
    try:
        key = load_psk(Path(args.key_file) if args.key_file else None, None, who="MINNOW")
    except KeyProblem as exc:
        print(f"minnow_vehicle: {exc}", file=sys.stderr)
        return 2
    return run_vehicle(build_vehicle(), key, speed=args.speed)


if __name__ == "__main__":
    sys.exit(main())
