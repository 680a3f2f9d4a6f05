"""The fixed facts of the wire: version magics, sizes and limits, roles, frame types.

Every other module of `runtime.protocol` builds on these; ``docs/protocol.md`` gives the
byte layout they describe and ``tests/runtime/test_protocol.py`` pins the sizes. The one
exception the protocol raises, `ProtocolError`, is here too: it is about our own code
asking for something these limits forbid.
"""

from __future__ import annotations

import enum
import struct
from typing import Final

from coral_lang.diagnostics import CoralError

__all__ = [
    "DATAGRAM_MAGIC",
    "HEADER_SIZE",
    "MAX_COUNTER",
    "MAX_DETAIL_BYTES",
    "MAX_FRAME",
    "MAX_KIND_BYTES",
    "MAX_NAME_BYTES",
    "MAX_PARAMS",
    "MAX_PAYLOAD",
    "MAX_TEXT_BYTES",
    "MIN_KEY_SIZE",
    "NONCE_SIZE",
    "STREAM_MAGIC",
    "TAG_SIZE",
    "FrameType",
    "ProtocolError",
    "Role",
]


class ProtocolError(CoralError, ValueError):
    """Our own code asked the protocol to do something it cannot (a programming error).

    Usually a name or text too long for its length prefix, a number out of its field's
    range, a non-finite float, a message sent in the wrong direction, or a session message
    sent before the handshake finished. Fix the caller: shorten the name, check the value,
    wait for `StreamCodec.can_send`. Bytes received from the network never raise this;
    bad input comes back as a `Rejected` value instead.
    """


STREAM_MAGIC: Final = b"\xc5\x01"
"""First two bytes of every stream frame: 0xC5 ("coral"), then protocol version 1."""
DATAGRAM_MAGIC: Final = b"\xc5\x81"
"""First two bytes of every datagram: version 1 with the datagram bit (0x80) set."""

HEADER: Final = struct.Struct(">2sBHIH")  # magic, type, payload length, counter, header CRC
HEADER_SIZE: Final = HEADER.size  # 11
TAG_SIZE: Final = 16
"""HMAC-SHA256 truncated to 128 bits (as RFC 4868 does for IPsec); see docs/protocol.md."""
MAX_FRAME: Final = 1024
"""Largest stream frame in bytes, header and tag included (about 1.07 s at 9600 bps)."""
MAX_PAYLOAD: Final = MAX_FRAME - HEADER_SIZE - TAG_SIZE  # 997
NONCE_SIZE: Final = 16
MIN_KEY_SIZE: Final = 16
MAX_COUNTER: Final = 2**32 - 1

MAX_NAME_BYTES: Final = 32
"""Command names and parameter names: at most this many bytes of UTF-8."""
MAX_KIND_BYTES: Final = 16
MAX_TEXT_BYTES: Final = 64
"""String parameter values."""
MAX_DETAIL_BYTES: Final = 200
MAX_PARAMS: Final = 16

U16: Final = 2**16 - 1
U32: Final = 2**32 - 1
U64: Final = 2**64 - 1


class Role(enum.IntEnum):
    """Who sends a frame. The value is mixed into every tag so a frame cannot be reflected."""

    CONTROLLER = 1
    VEHICLE = 2

    @property
    def peer(self) -> Role:
        """The other end of the link."""
        return Role.VEHICLE if self is Role.CONTROLLER else Role.CONTROLLER


class FrameType(enum.IntEnum):
    """The type byte of a frame or datagram."""

    HELLO = 0x01
    HELLO_REPLY = 0x02
    COMMAND = 0x10
    REPLY = 0x11
    REPLY_ACK = 0x12
    MAKE_SAFE = 0x13
    MAKE_SAFE_ACK = 0x14
    HEARTBEAT = 0x20
    TELEMETRY = 0x40


HANDSHAKE_TYPES: Final = frozenset({FrameType.HELLO, FrameType.HELLO_REPLY})
KNOWN_TYPES: Final = frozenset(int(t) for t in FrameType)
