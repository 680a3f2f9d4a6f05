"""The run log: telemetry samples (true and estimated), commands, replies and events.

A `Recorder` sits between a driver and a `Vehicle`: commands and clock advances go
through it, and it keeps what happened, with times, in memory. It exports to JSON (one
document) or CSV (one file per table) for plots and for merging with the engine's log.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from romeo_sim.vehicle import Reply, Telemetry, Vehicle, VehicleEvent

__all__ = ["CommandRecord", "Recorder"]

TELEMETRY_COLUMNS = tuple(f.name for f in dataclasses.fields(Telemetry) if f.name != "seq")
"""The exported telemetry fields: the snapshot's, without ``seq``, which only a datagram
has (the simulator's samples are not numbered)."""


@dataclass(frozen=True)
class CommandRecord:
    """A command as the vehicle received it."""

    time: float
    command_id: int
    command: str
    params: tuple[tuple[str, float | int | str], ...]

    def text(self) -> str:
        """E.g. ``GOTO(x=6, y=4, psi=0)``."""
        inner = ", ".join(
            f"{k}={v:g}" if not isinstance(v, str) else f"{k}={v}" for k, v in self.params
        )
        return f"{self.command}({inner})"


class Recorder:
    """Collects a run's telemetry, commands, replies and vehicle events.

    Args:
        sample_interval: telemetry period on the vehicle clock, s.
    """

    def __init__(self, sample_interval: float = 0.5) -> None:
        if not sample_interval > 0.0:
            raise ValueError(f"sample_interval must be > 0, got {sample_interval}")
        self.sample_interval = sample_interval
        self.telemetry: list[Telemetry] = []
        self.commands: list[CommandRecord] = []
        self.replies: list[Reply] = []
        self.events: list[VehicleEvent] = []
        self._events_seen = 0
        self._next_sample: float | None = None

    def command(
        self,
        vehicle: Vehicle,
        command_id: int,
        name: str,
        params: Mapping[str, float | int | str] | None = None,
    ) -> list[Reply]:
        """Send a command to ``vehicle``, logging it and its immediate replies."""
        params = {} if params is None else params
        self.commands.append(
            CommandRecord(vehicle.time, command_id, name, tuple(sorted(params.items())))
        )
        replies = vehicle.command(command_id, name, params)
        self.replies.extend(replies)
        self._take_events(vehicle)
        return replies

    def advance_to(self, vehicle: Vehicle, t: float) -> list[Reply]:
        """Advance ``vehicle`` to ``t``, sampling telemetry on the way; returns the replies."""
        if self._next_sample is None:
            self.sample(vehicle)
        assert self._next_sample is not None
        replies: list[Reply] = []
        while self._next_sample <= t + 1e-9:
            replies.extend(vehicle.advance_to(self._next_sample))
            self.sample(vehicle)
        replies.extend(vehicle.advance_to(t))
        self.replies.extend(replies)
        self._take_events(vehicle)
        return replies

    def sample(self, vehicle: Vehicle) -> None:
        """Record one telemetry sample now and schedule the next."""
        self.telemetry.append(vehicle.telemetry())
        step = self.sample_interval
        self._next_sample = (math.floor(vehicle.time / step + 1e-9) + 1) * step

    def _take_events(self, vehicle: Vehicle) -> None:
        events = vehicle.events
        self.events.extend(events[self._events_seen :])
        self._events_seen = len(events)

    # ------------------------------------------------------------- export

    def to_dict(self) -> dict[str, Any]:
        """Everything, as plain JSON-ready data."""
        return {
            "telemetry": [{k: getattr(t, k) for k in TELEMETRY_COLUMNS} for t in self.telemetry],
            "commands": [
                {
                    "time": c.time,
                    "command_id": c.command_id,
                    "command": c.command,
                    "params": dict(c.params),
                }
                for c in self.commands
            ],
            "replies": [dataclasses.asdict(r) for r in self.replies],
            "events": [dataclasses.asdict(e) for e in self.events],
        }

    def write_json(self, path: str | Path) -> Path:
        """Write `to_dict` as JSON; returns the path."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1), encoding="utf-8")
        return path

    def write_csv(self, folder: str | Path) -> list[Path]:
        """Write telemetry.csv, commands.csv, replies.csv and events.csv into ``folder``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        data = self.to_dict()
        written: list[Path] = []
        headers = {
            "telemetry": list(TELEMETRY_COLUMNS),
            "commands": ["time", "command_id", "command", "params"],
            "replies": [f.name for f in dataclasses.fields(Reply)],
            "events": [f.name for f in dataclasses.fields(VehicleEvent)],
        }
        for table, header in headers.items():
            path = folder / f"{table}.csv"
            with path.open("w", newline="", encoding="utf-8") as handle:
                writer = csv.DictWriter(handle, fieldnames=header)
                writer.writeheader()
                for row in data[table]:
                    if table == "commands":
                        row = {**row, "params": json.dumps(row["params"], sort_keys=True)}
                    writer.writerow(row)
            written.append(path)
        return written
