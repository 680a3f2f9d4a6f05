"""How the controller reaches the vehicle: the `Link` and `Connection` it codes against.

The controller (``runtime.controller``) sees a link as two things, after the paper's
section IV: a stream connection for the handshake, commands, replies and heartbeats, and
a telemetry callback fed by datagrams. Two links implement them:

* `MemoryLink` (``runtime.memorylink``): the vehicle server in the same process, no
  sockets; meant for `runtime.vclock.VirtualTimeLoop`, where a long mission runs in
  seconds and the same seeds give the same run.
* `SocketLink` (``runtime.socketlink``): real TCP and UDP sockets, real time.

Both put a `LinkEmulator` (``runtime.emulator``) between the two ends when given one:
the paper's 9600 bps line and Internet delays, stalls, losses, resets and outages, as a
`LinkProfile` (``coral_lang.linkprofile``) describes them. ``docs/link.md`` has the model
and every profile field. This module re-exports all of those names.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from coral_lang.linkprofile import (
    BUILTIN_PROFILES,
    LinkProfile,
    LinkProfileError,
    load_link_profile,
)
from runtime.emulator import DatagramFate, Direction, LinkEmulator, Outage, StreamPath
from runtime.linkpipe import LinkStats
from runtime.memorylink import MemoryLink
from runtime.socketlink import SocketLink

__all__ = [
    "BUILTIN_PROFILES",
    "Connection",
    "DatagramFate",
    "Direction",
    "Link",
    "LinkEmulator",
    "LinkProfile",
    "LinkProfileError",
    "LinkStats",
    "MemoryLink",
    "Outage",
    "SocketLink",
    "StreamPath",
    "load_link_profile",
]


class Connection(Protocol):
    """One stream connection to the vehicle, as the controller uses it."""

    async def read(self) -> bytes:
        """The next chunk; b"" when the connection is closed or reset."""
        ...

    def write(self, data: bytes) -> None:
        """Send ``data``; never blocks. Bytes go through the emulator."""
        ...

    def close(self) -> None:
        """Close the connection (idempotent)."""
        ...

    @property
    def closed(self) -> bool:
        """True once the connection is closed by either end or reset."""
        ...


class Link(Protocol):
    """The way to the vehicle: stream connections and telemetry datagrams."""

    async def connect(self) -> Connection:
        """A new connection; raises ConnectionError when the vehicle cannot be reached."""
        ...

    async def open_telemetry(self, receive: Callable[[bytes], None]) -> int:
        """Start receiving datagrams; returns the port to announce in Hello (0 = none)."""
        ...

    async def aclose(self) -> None:
        """Close every connection and stop receiving datagrams."""
        ...
