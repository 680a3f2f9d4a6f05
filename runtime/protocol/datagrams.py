"""Telemetry datagrams (UDP, vehicle to controller): one fixed-size, tagged datagram each.

A datagram carries one `TelemetryRecord` as float32 (55 bytes, see ``docs/protocol.md``),
tagged with the connection's session key. `DatagramReceiver` authenticates, decodes and
drops late or duplicate datagrams, so the controller only ever sees newer samples.
"""

from __future__ import annotations

import hmac
import math
import struct
from typing import Final

from runtime.protocol.auth import check_key, frame_tag
from runtime.protocol.messages import Rejected, RejectReason, TelemetryRecord
from runtime.protocol.payload import finite, uint
from runtime.protocol.wire import DATAGRAM_MAGIC, TAG_SIZE, U32, FrameType, ProtocolError, Role

__all__ = ["TELEMETRY_SIZE", "DatagramReceiver", "encode_datagram"]


_TELEMETRY = struct.Struct(">2sBId6f")
_TELEMETRY_TYPE = FrameType.TELEMETRY
_VEHICLE = Role.VEHICLE
_NAN = math.nan
TELEMETRY_SIZE: Final = _TELEMETRY.size + TAG_SIZE  # 55


def encode_datagram(key: bytes, msg: TelemetryRecord) -> bytes:
    """One telemetry datagram, tagged with the connection's `StreamCodec.session_key`.

    Raises:
        ProtocolError: a short key, a sequence number outside 1..2**32-1, a non-finite
            time or pose, or a value beyond float32 range.
    """
    key = check_key(key, "the session key")
    if not isinstance(msg, TelemetryRecord):
        raise ProtocolError(f"only TelemetryRecord goes by datagram, not {type(msg).__name__}")
    seq = uint(msg.seq, U32, "TelemetryRecord.seq")
    if seq == 0:
        raise ProtocolError("TelemetryRecord.seq starts at 1")
    x = finite(msg.x, "TelemetryRecord.x")
    y = finite(msg.y, "TelemetryRecord.y")
    z = finite(msg.z, "TelemetryRecord.z")
    psi = finite(msg.psi, "TelemetryRecord.psi")
    est_x = _NAN if msg.est_x is None else finite(msg.est_x, "TelemetryRecord.est_x")
    est_y = _NAN if msg.est_y is None else finite(msg.est_y, "TelemetryRecord.est_y")
    try:
        body = _TELEMETRY.pack(
            DATAGRAM_MAGIC,
            _TELEMETRY_TYPE,
            seq,
            finite(msg.vehicle_time, "TelemetryRecord.vehicle_time"),
            x,
            y,
            z,
            psi,
            est_x,
            est_y,
        )
    except (OverflowError, struct.error) as exc:
        raise ProtocolError(f"telemetry value out of float32 range: {exc}") from None
    return body + frame_tag(key, _VEHICLE, body)


class DatagramReceiver:
    """The controller's side of telemetry: authenticate, decode, drop late datagrams.

    One per connection (keyed with that connection's `StreamCodec.session_key`); a new
    connection restarts the sequence numbers, so make a new receiver with the new key.

    Args:
        key: the session key of the current connection.

    Raises:
        ProtocolError: a key shorter than `MIN_KEY_SIZE`.
    """

    def __init__(self, key: bytes) -> None:
        self._key = check_key(key, "the session key")
        self.last_seq = 0
        """Sequence number of the newest accepted datagram (0: none yet)."""
        self.accepted = 0
        self.rejected = 0

    def accept(self, data: bytes) -> TelemetryRecord | Rejected:
        """The telemetry of one received datagram, or why it was dropped. Never raises."""
        result = self._check(data)
        if isinstance(result, Rejected):
            self.rejected += 1
        else:
            self.accepted += 1
            self.last_seq = result.seq
        return result

    def _check(self, data: bytes) -> TelemetryRecord | Rejected:
        if len(data) != TELEMETRY_SIZE:
            return Rejected(RejectReason.BAD_LENGTH, f"{len(data)} bytes, want {TELEMETRY_SIZE}")
        body, tag = bytes(data[:-TAG_SIZE]), bytes(data[-TAG_SIZE:])
        if body[:2] != DATAGRAM_MAGIC:
            return Rejected(RejectReason.BAD_MAGIC, "not a coral v1 datagram")
        if not hmac.compare_digest(frame_tag(self._key, _VEHICLE, body), tag):
            return Rejected(RejectReason.BAD_TAG, "telemetry tag")
        _, ftype, seq, vtime, x, y, z, psi, ex, ey = _TELEMETRY.unpack(body)
        if ftype != _TELEMETRY_TYPE:
            return Rejected(RejectReason.UNKNOWN_TYPE, f"datagram type {ftype:#04x}")
        if seq <= self.last_seq:
            return Rejected(RejectReason.LATE, f"seq {seq} <= {self.last_seq} already accepted")
        isfinite = math.isfinite
        if not (isfinite(vtime) and isfinite(x) and isfinite(y) and isfinite(z) and isfinite(psi)):
            return Rejected(RejectReason.MALFORMED, "non-finite time or pose")
        if math.isinf(ex) or math.isinf(ey):
            return Rejected(RejectReason.MALFORMED, "infinite estimate")
        return TelemetryRecord(
            vtime,
            x,
            y,
            z,
            psi,
            None if math.isnan(ex) else ex,
            None if math.isnan(ey) else ey,
            seq,
        )
