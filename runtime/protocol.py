"""The wire protocol between the CORAL engine (controller) and a vehicle, defined once.

The engine and the vehicle simulator both speak it; each does its own socket I/O (asyncio)
and hands the bytes to the codecs here. This module is pure: no sockets, no clocks, no
randomness. Times and nonces are passed in, so tests can run it under a virtual clock.

What travels where (after the paper, Bruzzone et al., sections III-IV):

* Stream (TCP), both directions, framed and authenticated: the handshake (`Hello`,
  `HelloReply`, which also carries the times for the paper's INIT clock offset), commands
  (`Command`), the vehicle's replies (`Reply`), the controller's acknowledgement of replies
  (`ReplyAck`), the controller's request that the vehicle make itself safe at once
  (`MakeSafe`, answered by `MakeSafeAck`) and `Heartbeat`. One `StreamCodec` per
  connection encodes and decodes them.
* Datagrams (UDP), vehicle to controller: `Telemetry`, sequence-numbered; `DatagramReceiver`
  drops late and duplicate ones.

The byte layout, sizes at 9600 bps, the key schedule and the delivery rules (no command
lost, none done twice, every reply consumed exactly once) are in ``docs/protocol.md``;
``tests/runtime/test_protocol.py`` pins the documented sizes.

Import rule: the vehicle simulator may import this module and nothing else of ``runtime``,
so this module imports nothing from ``runtime``, ``analysis`` or ``romeo_sim``.
"""

from __future__ import annotations

import binascii
import enum
import hashlib
import hmac
import math
import struct
from dataclasses import dataclass, field
from typing import Final, TypeAlias

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
    "TELEMETRY_SIZE",
    "ClockSync",
    "Command",
    "DatagramReceiver",
    "FrameType",
    "Heartbeat",
    "Hello",
    "HelloReply",
    "MakeSafe",
    "MakeSafeAck",
    "ParamValue",
    "ProtocolError",
    "RejectReason",
    "Rejected",
    "Reply",
    "ReplyAck",
    "ReplyLedger",
    "Role",
    "StreamCodec",
    "StreamMessage",
    "Telemetry",
    "clock_offset",
    "encode_datagram",
    "frame_size",
    "session_key",
]


class ProtocolError(CoralError, ValueError):
    """Our own code asked the protocol to do something it cannot (a programming error).

    Usually a name or text too long for its length prefix, a number out of its field's
    range, a non-finite float, a message sent in the wrong direction, or a session message
    sent before the handshake finished. Fix the caller: shorten the name, check the value,
    wait for `StreamCodec.can_send`. Bytes received from the network never raise this;
    bad input comes back as a `Rejected` value instead.
    """


# --- constants ---------------------------------------------------------------------------

STREAM_MAGIC: Final = b"\xc5\x01"
"""First two bytes of every stream frame: 0xC5 ("coral"), then protocol version 1."""
DATAGRAM_MAGIC: Final = b"\xc5\x81"
"""First two bytes of every datagram: version 1 with the datagram bit (0x80) set."""

_HEADER = struct.Struct(">2sBHIH")  # magic, type, payload length, counter, header CRC
HEADER_SIZE: Final = _HEADER.size  # 11
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

_U16 = 2**16 - 1
_U32 = 2**32 - 1
_U64 = 2**64 - 1


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


_HANDSHAKE_TYPES: Final = frozenset({FrameType.HELLO, FrameType.HELLO_REPLY})
_KNOWN_TYPES: Final = frozenset(int(t) for t in FrameType)


# --- messages ----------------------------------------------------------------------------

ParamValue: TypeAlias = float | int | str


@dataclass(frozen=True)
class Hello:
    """Controller to vehicle, first frame on every connection (the INIT handshake).

    Attributes:
        nonce: 16 fresh random bytes of the controller for this connection (the same
            ``nonce`` its `StreamCodec` was built with).
        sent_at: t0 of the paper, the controller's clock when it sent this.
        mission_id: identifies the mission across reconnects and controller restarts
            (unsigned 64-bit, chosen at mission start and kept in the event log).
        resume: True when this controller continues ``mission_id`` after a lost connection
            or a restart; False starts a new mission.
        last_reply_seq: highest reply sequence number the controller has consumed for
            this mission (0: none). The vehicle re-sends every reply after it.
        telemetry_port: UDP port on the controller's host for telemetry (0: send none).
    """

    nonce: bytes
    sent_at: float
    mission_id: int
    resume: bool = False
    last_reply_seq: int = 0
    telemetry_port: int = 0


@dataclass(frozen=True)
class HelloReply:
    """Vehicle to controller, the answer to `Hello`.

    Attributes:
        controller_nonce: the `Hello`'s nonce, echoed (proves this reply is fresh).
        vehicle_nonce: 16 fresh random bytes of the vehicle for this connection.
        received_at: t0 of the vehicle (RCS) clock, when the `Hello` arrived.
        sent_at: t1 of the vehicle clock, when this reply left.
        resumed: True when the vehicle knows the mission and will re-send the replies
            after the `Hello`'s ``last_reply_seq``; False when it starts afresh (a resume
            it could not honour means the vehicle lost the mission: treat it as an abort).
        last_reply_seq: highest reply sequence number the vehicle has issued in it.
        silence_timeout: seconds without any valid frame from the controller after which
            the vehicle surfaces by itself; send heartbeats well within it.
    """

    controller_nonce: bytes
    vehicle_nonce: bytes
    received_at: float
    sent_at: float
    resumed: bool
    last_reply_seq: int
    silence_timeout: float


@dataclass(frozen=True)
class Command:
    """Controller to vehicle: run one command of the vehicle profile.

    Attributes:
        command_id: unique within the mission (unsigned 32-bit). The vehicle carries out
            each id once; a repeat gets the same replies again, never a second run.
        name: the profile's command name, for example ``"DEPTH"`` or ``"DEPTH?"``.
        sent_at: the controller's clock when it (first) sent the command.
        params: parameter name to value: finite float, signed 64-bit int, or short text.
    """

    command_id: int
    name: str
    sent_at: float
    params: dict[str, ParamValue] = field(default_factory=dict)


@dataclass(frozen=True)
class Reply:
    """Vehicle to controller: one outcome of a command (``ack``, ``done``, ``timeout``...).

    Attributes:
        reply_seq: the vehicle numbers its replies 1, 2, 3... within a mission; the
            controller acknowledges them with `ReplyAck` and ignores numbers it has seen.
        command_id: the command this answers.
        kind: a reply kind the profile lists for the command.
        vehicle_time: the vehicle's clock when the outcome happened.
        detail: optional short human-readable text (UTF-8, at most 200 bytes).
    """

    reply_seq: int
    command_id: int
    kind: str
    vehicle_time: float
    detail: str = ""


@dataclass(frozen=True)
class ReplyAck:
    """Controller to vehicle: every reply numbered up to ``reply_seq`` has been consumed.

    Cumulative: the vehicle may forget those replies and will not re-send them.
    """

    reply_seq: int


@dataclass(frozen=True)
class MakeSafe:
    """Controller to vehicle: stop everything and make yourself safe now (the watchdog's
    behaviour, without waiting for the silence).

    Sent when the operator stops the controller (Ctrl-C, SIGTERM), so a vehicle is never
    left running a mission nobody drives. The vehicle answers `MakeSafeAck`; the replies
    its stopped commands give go into the mission's reply ledger as usual, so a later
    resume consumes them.

    Attributes:
        request_id: chosen by the controller (unsigned 32-bit); a repeat of an id the
            vehicle already carried out for this mission is acknowledged again, not
            carried out twice.
        sent_at: the controller's clock when it sent the request.
        reason: short text for the vehicle's log (UTF-8, at most 200 bytes, may be empty).
    """

    request_id: int
    sent_at: float
    reason: str = ""


@dataclass(frozen=True)
class MakeSafeAck:
    """Vehicle to controller: the `MakeSafe` ``request_id`` has been carried out.

    Attributes:
        request_id: the request's id.
        vehicle_time: the vehicle's clock when it made itself safe (or acknowledged again).
        first: True when this request made the vehicle safe now, False for a repeat of a
            request id it had already carried out (nothing was done again).
    """

    request_id: int
    vehicle_time: float
    first: bool = True


@dataclass(frozen=True)
class Heartbeat:
    """Either direction: I am alive; ``sent_at`` is the sender's clock."""

    sent_at: float


@dataclass(frozen=True)
class Telemetry:
    """Vehicle to controller, one datagram.

    Positions in metres, ``z`` is depth (down positive), ``psi`` the heading in degrees
    clockwise from north, as in the ROMEO profile. Sent as float32 (see docs/protocol.md),
    so a decoded value equals the sent one rounded to float32.

    Attributes:
        seq: sequence number, 1, 2, 3... per connection; the receiver drops any datagram
            not newer than the last one it accepted.
        vehicle_time: the vehicle's clock at the sample.
        x: north position the vehicle reports (the simulator sends its true position).
        y: east position.
        z: depth.
        psi: heading.
        est_x: the navigation filter's estimate of x; None before it is initialised
            (FIX_XY), on the wire a NaN.
        est_y: likewise for y.
    """

    seq: int
    vehicle_time: float
    x: float
    y: float
    z: float
    psi: float
    est_x: float | None = None
    est_y: float | None = None


StreamMessage: TypeAlias = (
    Hello | HelloReply | Command | Reply | ReplyAck | MakeSafe | MakeSafeAck | Heartbeat
)


class RejectReason(enum.Enum):
    """Why incoming bytes were not accepted; the value is a stable short code for logs."""

    BAD_MAGIC = "bad-magic"
    """Bytes that do not start a frame; the decoder skipped to the next magic."""
    BAD_HEADER = "bad-header"
    """The header check (CRC-16) failed: a corrupted length or counter; resynchronised."""
    OVERSIZED = "oversized"
    """A declared payload length above `MAX_PAYLOAD`; nothing buffered, resynchronised."""
    BAD_TAG = "bad-tag"
    """The authentication tag is wrong: corruption, a wrong key, or someone else."""
    REPLAY = "replay"
    """A counter not above the highest accepted one: a replayed or duplicated frame."""
    NO_SESSION = "no-session"
    """A session frame before the handshake finished."""
    UNEXPECTED = "unexpected"
    """An authentic frame out of place: a second handshake, a stale nonce, wrong direction."""
    UNKNOWN_TYPE = "unknown-type"
    """An authentic frame of a type this version does not know."""
    MALFORMED = "malformed"
    """An authentic frame whose payload does not decode (a bug in the peer)."""
    BAD_LENGTH = "bad-length"
    """A datagram of the wrong size."""
    LATE = "late"
    """A datagram whose sequence number is not newer than the last accepted one."""


@dataclass(frozen=True)
class Rejected:
    """Input that was dropped, and why: data for the log, never an exception.

    Attributes:
        reason: the category; see `RejectReason`.
        detail: one line for the event log.
    """

    reason: RejectReason
    detail: str


# --- keys and tags -----------------------------------------------------------------------


def _check_key(key: bytes, what: str) -> bytes:
    if not isinstance(key, bytes | bytearray) or len(key) < MIN_KEY_SIZE:
        raise ProtocolError(f"{what} must be at least {MIN_KEY_SIZE} bytes")
    return bytes(key)


def _check_nonce(nonce: bytes, what: str) -> bytes:
    if not isinstance(nonce, bytes | bytearray) or len(nonce) != NONCE_SIZE:
        raise ProtocolError(f"{what} must be exactly {NONCE_SIZE} bytes (use os.urandom)")
    return bytes(nonce)


def session_key(psk: bytes, controller_nonce: bytes, vehicle_nonce: bytes) -> bytes:
    """The key of one connection, from the pre-shared key and both handshake nonces.

    Every frame after the handshake, and every telemetry datagram of the connection, is
    tagged with it. Both nonces are fresh per connection, so frames recorded on an earlier
    connection fail the tag on a later one: replay protection needs no counter kept across
    connections or restarts.

    Raises:
        ProtocolError: a key shorter than `MIN_KEY_SIZE` or a nonce not `NONCE_SIZE` long.
    """
    psk = _check_key(psk, "the pre-shared key")
    info = (
        b"coral/1 session"
        + _check_nonce(controller_nonce, "controller nonce")
        + _check_nonce(vehicle_nonce, "vehicle nonce")
    )
    return hmac.new(psk, info, hashlib.sha256).digest()


def _tag(key: bytes, sender: Role, body: bytes | bytearray) -> bytes:
    mac = hmac.new(key, bytes((sender,)), hashlib.sha256)
    mac.update(body)
    return mac.digest()[:TAG_SIZE]


def _header_crc(head: bytes | bytearray) -> int:
    # CRC-16/CCITT over magic..counter: catches a corrupted length at once, so the decoder
    # never waits for bytes of a frame that does not exist. Not security: the tag is.
    return binascii.crc_hqx(head, 0xFFFF)


# --- payload encoding --------------------------------------------------------------------


class _Malformed(Exception):
    """Internal: a payload that does not decode. Never leaves this module."""


def _finite(value: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(f"{what} must be a number, not {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ProtocolError(f"{what} must be finite, got {value!r}")
    return value


def _uint(value: int, limit: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
        raise ProtocolError(f"{what} must be an integer in 0..{limit}, got {value!r}")
    return value


def _text(value: str, limit: int, what: str, *, empty: bool = False) -> bytes:
    if not isinstance(value, str):
        raise ProtocolError(f"{what} must be a str, not {type(value).__name__}")
    raw = value.encode("utf-8")
    if len(raw) > limit:
        raise ProtocolError(f"{what} {value!r} is {len(raw)} bytes of UTF-8; at most {limit}")
    if not raw and not empty:
        raise ProtocolError(f"{what} must not be empty")
    return bytes((len(raw),)) + raw


_F64 = struct.Struct(">d")
_I64 = struct.Struct(">q")
_HELLO = struct.Struct(">16sdQBIH")
_HELLO_REPLY = struct.Struct(">16s16sddBId")
_COMMAND_HEAD = struct.Struct(">Id")
_REPLY_HEAD = struct.Struct(">II")
_U32S = struct.Struct(">I")
_MAKE_SAFE_HEAD = struct.Struct(">Id")
_MAKE_SAFE_ACK = struct.Struct(">IdB")
_PARAM_FLOAT, _PARAM_INT, _PARAM_TEXT = 1, 2, 3


def _encode_payload(msg: StreamMessage) -> tuple[FrameType, bytes]:
    if isinstance(msg, Hello):
        return FrameType.HELLO, _HELLO.pack(
            _check_nonce(msg.nonce, "Hello.nonce"),
            _finite(msg.sent_at, "Hello.sent_at"),
            _uint(msg.mission_id, _U64, "Hello.mission_id"),
            1 if msg.resume else 0,
            _uint(msg.last_reply_seq, _U32, "Hello.last_reply_seq"),
            _uint(msg.telemetry_port, _U16, "Hello.telemetry_port"),
        )
    if isinstance(msg, HelloReply):
        return FrameType.HELLO_REPLY, _HELLO_REPLY.pack(
            _check_nonce(msg.controller_nonce, "HelloReply.controller_nonce"),
            _check_nonce(msg.vehicle_nonce, "HelloReply.vehicle_nonce"),
            _finite(msg.received_at, "HelloReply.received_at"),
            _finite(msg.sent_at, "HelloReply.sent_at"),
            1 if msg.resumed else 0,
            _uint(msg.last_reply_seq, _U32, "HelloReply.last_reply_seq"),
            _finite(msg.silence_timeout, "HelloReply.silence_timeout"),
        )
    if isinstance(msg, Command):
        return FrameType.COMMAND, _encode_command(msg)
    if isinstance(msg, Reply):
        return FrameType.REPLY, b"".join(
            (
                _REPLY_HEAD.pack(
                    _uint(msg.reply_seq, _U32, "Reply.reply_seq"),
                    _uint(msg.command_id, _U32, "Reply.command_id"),
                ),
                _text(msg.kind, MAX_KIND_BYTES, "reply kind"),
                _F64.pack(_finite(msg.vehicle_time, "Reply.vehicle_time")),
                _text(msg.detail, MAX_DETAIL_BYTES, "reply detail", empty=True),
            )
        )
    if isinstance(msg, ReplyAck):
        return FrameType.REPLY_ACK, _U32S.pack(_uint(msg.reply_seq, _U32, "ReplyAck.reply_seq"))
    if isinstance(msg, MakeSafe):
        return FrameType.MAKE_SAFE, _MAKE_SAFE_HEAD.pack(
            _uint(msg.request_id, _U32, "MakeSafe.request_id"),
            _finite(msg.sent_at, "MakeSafe.sent_at"),
        ) + _text(msg.reason, MAX_DETAIL_BYTES, "make-safe reason", empty=True)
    if isinstance(msg, MakeSafeAck):
        return FrameType.MAKE_SAFE_ACK, _MAKE_SAFE_ACK.pack(
            _uint(msg.request_id, _U32, "MakeSafeAck.request_id"),
            _finite(msg.vehicle_time, "MakeSafeAck.vehicle_time"),
            1 if msg.first else 0,
        )
    if isinstance(msg, Heartbeat):
        return FrameType.HEARTBEAT, _F64.pack(_finite(msg.sent_at, "Heartbeat.sent_at"))
    raise ProtocolError(
        f"{type(msg).__name__} is not a stream message"
        + (
            " (telemetry goes by datagram: use encode_datagram)"
            if isinstance(msg, Telemetry)
            else ""
        )
    )


def _encode_command(msg: Command) -> bytes:
    if len(msg.params) > MAX_PARAMS:
        raise ProtocolError(
            f"command {msg.name!r} has {len(msg.params)} params; at most {MAX_PARAMS}"
        )
    parts = [
        _COMMAND_HEAD.pack(
            _uint(msg.command_id, _U32, "Command.command_id"),
            _finite(msg.sent_at, "Command.sent_at"),
        ),
        _text(msg.name, MAX_NAME_BYTES, "command name"),
        bytes((len(msg.params),)),
    ]
    for name, value in msg.params.items():
        parts.append(_text(name, MAX_NAME_BYTES, "parameter name"))
        what = f"parameter {name!r} of {msg.name!r}"
        if isinstance(value, bool):
            # bool is an int in Python; refuse it so True never arrives as 1 unnoticed.
            raise ProtocolError(f"{what} is a bool; send 0 or 1 as an int if that is meant")
        if isinstance(value, int):
            if not -(2**63) <= value < 2**63:
                raise ProtocolError(f"{what} does not fit in a signed 64-bit int")
            parts.append(bytes((_PARAM_INT,)) + _I64.pack(value))
        elif isinstance(value, float):
            parts.append(bytes((_PARAM_FLOAT,)) + _F64.pack(_finite(value, what)))
        elif isinstance(value, str):
            parts.append(bytes((_PARAM_TEXT,)) + _text(value, MAX_TEXT_BYTES, what, empty=True))
        else:
            raise ProtocolError(f"{what} is a {type(value).__name__}; use float, int or str")
    return b"".join(parts)


class _Reader:
    """Reads a payload front to back; any shortfall or bad value raises `_Malformed`."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0

    def unpack(self, fmt: struct.Struct) -> tuple[object, ...]:
        if self.pos + fmt.size > len(self.data):
            raise _Malformed("payload too short")
        values = fmt.unpack_from(self.data, self.pos)
        self.pos += fmt.size
        return values

    def byte(self) -> int:
        if self.pos >= len(self.data):
            raise _Malformed("payload too short")
        self.pos += 1
        return self.data[self.pos - 1]

    def text(self, limit: int, what: str, *, empty: bool = False) -> str:
        size = self.byte()
        if size > limit or (size == 0 and not empty) or self.pos + size > len(self.data):
            raise _Malformed(f"bad length {size} of {what}")
        raw = self.data[self.pos : self.pos + size]
        self.pos += size
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            raise _Malformed(f"{what} is not UTF-8") from None

    def f64(self, what: str) -> float:
        (value,) = _F64.unpack(self._take(8))
        if not math.isfinite(value):
            raise _Malformed(f"{what} is not finite")
        return float(value)

    def _take(self, size: int) -> bytes:
        if self.pos + size > len(self.data):
            raise _Malformed("payload too short")
        self.pos += size
        return self.data[self.pos - size : self.pos]

    def end(self) -> None:
        if self.pos != len(self.data):
            raise _Malformed(f"{len(self.data) - self.pos} bytes after the payload")


def _flag(value: object) -> bool:
    if value not in (0, 1):
        raise _Malformed(f"flag byte {value!r} is neither 0 nor 1")
    return value == 1


def _finite_field(value: object, what: str) -> float:
    assert isinstance(value, float)
    if not math.isfinite(value):
        raise _Malformed(f"{what} is not finite")
    return value


def _decode_payload(ftype: FrameType, payload: bytes) -> StreamMessage:
    r = _Reader(payload)
    msg: StreamMessage
    if ftype is FrameType.HELLO:
        nonce, sent_at, mission_id, resume, last_seq, port = r.unpack(_HELLO)
        assert isinstance(nonce, bytes)
        assert isinstance(mission_id, int) and isinstance(last_seq, int) and isinstance(port, int)
        msg = Hello(
            nonce,
            _finite_field(sent_at, "sent_at"),
            mission_id,
            _flag(resume),
            last_seq,
            port,
        )
    elif ftype is FrameType.HELLO_REPLY:
        c_nonce, v_nonce, received_at, sent_at, resumed, last_seq, silence = r.unpack(_HELLO_REPLY)
        assert isinstance(c_nonce, bytes) and isinstance(v_nonce, bytes)
        assert isinstance(last_seq, int)
        msg = HelloReply(
            c_nonce,
            v_nonce,
            _finite_field(received_at, "received_at"),
            _finite_field(sent_at, "sent_at"),
            _flag(resumed),
            last_seq,
            _finite_field(silence, "silence_timeout"),
        )
    elif ftype is FrameType.COMMAND:
        msg = _decode_command(r)
    elif ftype is FrameType.REPLY:
        reply_seq, command_id = r.unpack(_REPLY_HEAD)
        assert isinstance(reply_seq, int) and isinstance(command_id, int)
        kind = r.text(MAX_KIND_BYTES, "reply kind")
        vehicle_time = r.f64("vehicle_time")
        detail = r.text(MAX_DETAIL_BYTES, "detail", empty=True)
        msg = Reply(reply_seq, command_id, kind, vehicle_time, detail)
    elif ftype is FrameType.REPLY_ACK:
        (reply_seq,) = r.unpack(_U32S)
        assert isinstance(reply_seq, int)
        msg = ReplyAck(reply_seq)
    elif ftype is FrameType.MAKE_SAFE:
        request_id, asked_at = r.unpack(_MAKE_SAFE_HEAD)
        assert isinstance(request_id, int)
        reason = r.text(MAX_DETAIL_BYTES, "reason", empty=True)
        msg = MakeSafe(request_id, _finite_field(asked_at, "sent_at"), reason)
    elif ftype is FrameType.MAKE_SAFE_ACK:
        request_id, safe_at, first = r.unpack(_MAKE_SAFE_ACK)
        assert isinstance(request_id, int)
        msg = MakeSafeAck(request_id, _finite_field(safe_at, "vehicle_time"), _flag(first))
    else:  # FrameType.HEARTBEAT; the caller has checked the type
        msg = Heartbeat(r.f64("sent_at"))
    r.end()
    return msg


def _decode_command(r: _Reader) -> Command:
    command_id, sent_at = r.unpack(_COMMAND_HEAD)
    assert isinstance(command_id, int)
    name = r.text(MAX_NAME_BYTES, "command name")
    count = r.byte()
    if count > MAX_PARAMS:
        raise _Malformed(f"{count} params; at most {MAX_PARAMS}")
    params: dict[str, ParamValue] = {}
    for _ in range(count):
        pname = r.text(MAX_NAME_BYTES, "parameter name")
        if pname in params:
            raise _Malformed(f"parameter {pname!r} twice")
        kind = r.byte()
        if kind == _PARAM_FLOAT:
            params[pname] = r.f64(f"parameter {pname!r}")
        elif kind == _PARAM_INT:
            (ivalue,) = r.unpack(_I64)
            assert isinstance(ivalue, int)
            params[pname] = ivalue
        elif kind == _PARAM_TEXT:
            params[pname] = r.text(MAX_TEXT_BYTES, f"parameter {pname!r}", empty=True)
        else:
            raise _Malformed(f"parameter {pname!r} has unknown value type {kind}")
    return Command(command_id, name, _finite_field(sent_at, "sent_at"), params)


def frame_size(msg: StreamMessage) -> int:
    """The size in bytes of ``msg``'s frame; checks it as `StreamCodec.encode` would.

    The engine calls it on every action of a mission at setup, so a name too long or a
    parameter the wire cannot carry is refused before anything moves.

    Raises:
        ProtocolError: the message cannot be encoded (the message says which field).
    """
    ftype, payload = _encode_payload(msg)
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(
            f"{ftype.name} payload is {len(payload)} bytes; at most {MAX_PAYLOAD} fit in a frame"
        )
    return HEADER_SIZE + len(payload) + TAG_SIZE


# --- the stream codec --------------------------------------------------------------------

_SENDS: Final = {
    Role.CONTROLLER: (Command, ReplyAck, MakeSafe, Heartbeat),
    Role.VEHICLE: (Reply, MakeSafeAck, Heartbeat),
}
_RECEIVES: Final = {
    Role.CONTROLLER: frozenset({FrameType.REPLY, FrameType.MAKE_SAFE_ACK, FrameType.HEARTBEAT}),
    Role.VEHICLE: frozenset(
        {FrameType.COMMAND, FrameType.REPLY_ACK, FrameType.MAKE_SAFE, FrameType.HEARTBEAT}
    ),
}


_UNAUTHENTICATED: Final = frozenset({RejectReason.BAD_TAG, RejectReason.NO_SESSION})


class StreamCodec:
    """Both directions of one stream connection: handshake, session key, counters, framing.

    Make a new one for every connection, with a fresh random nonce (``os.urandom(16)``).
    The controller encodes a `Hello` first; the vehicle answers with a `HelloReply`; from
    then on both sides send session messages, tagged with `session_key` and numbered by
    a counter that starts at 1 and must strictly increase.

    ``feed`` never raises: every input, however hostile, comes back as messages and
    `Rejected` entries, and the decoder resynchronises on the next frame start.

    Args:
        psk: the pre-shared key (at least 16 bytes; 32 random bytes recommended).
        role: which end this codec is.
        nonce: this end's fresh random nonce for the connection, `NONCE_SIZE` bytes.

    Raises:
        ProtocolError: a key or nonce of the wrong size.
    """

    def __init__(self, psk: bytes, role: Role, nonce: bytes) -> None:
        self._psk = _check_key(psk, "the pre-shared key")
        self.role = Role(role)
        self.nonce = _check_nonce(nonce, "the nonce")
        self._peer = self.role.peer
        self._peer_nonce: bytes | None = None
        self._key: bytes | None = None  # session key, once the handshake gave both nonces
        self._handshake_sent = False
        self._handshake_received = False
        self._peer_verified = False
        self._send_counter = 0
        self._recv_counter = 0
        self._buf = bytearray()
        self._skipping = False
        self.rejected = 0
        """How many `Rejected` entries `feed` has returned on this connection."""

    # -- state --

    @property
    def session_key(self) -> bytes | None:
        """The connection's key once both nonces are known; also keys telemetry datagrams."""
        return self._key

    @property
    def peer_nonce(self) -> bytes | None:
        """The other end's nonce, once its handshake frame arrived."""
        return self._peer_nonce

    @property
    def can_send(self) -> bool:
        """True once session messages (commands, replies, heartbeats...) may be encoded.

        The controller may send after it received the `HelloReply`; the vehicle after it
        sent it.
        """
        return self._key is not None and self._handshake_sent and self._handshake_received

    @property
    def peer_verified(self) -> bool:
        """True once the peer proved this connection is live, not a recording.

        For the controller, a `HelloReply` echoing its nonce does; for the vehicle, the
        first session frame from the controller does. A `Hello` alone proves nothing (it
        can be replayed): a vehicle server takes a new connection as its controller, and
        acts on the Hello's resume request, only when this becomes True.
        """
        return self._peer_verified

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame (never more than `MAX_FRAME`)."""
        return len(self._buf)

    @property
    def status(self) -> str:
        """One line for the log and the live view, for example
        ``"controller link: live, sent 12, received 10, rejected 0"``."""
        if self.can_send:
            state = "live" if self._peer_verified else "handshake done, peer not yet verified"
        elif self._handshake_sent:
            state = "Hello sent, awaiting HelloReply"
        elif self._handshake_received:
            state = "Hello received, HelloReply not sent"
        else:
            state = "awaiting handshake"
        return (
            f"{self.role.name.lower()} link: {state}, sent {self._send_counter}, "
            f"received {self._recv_counter}, rejected {self.rejected}"
        )

    # -- encoding --

    def encode(self, msg: StreamMessage) -> bytes:
        """One frame for ``msg``: header, payload and tag.

        Raises:
            ProtocolError: the message is invalid (see `ProtocolError`), goes the wrong
                way for this role, comes out of handshake order, or does not fit in a
                frame; or the counter is exhausted (reconnect: a new connection starts
                a new session).
        """
        if isinstance(msg, Hello | HelloReply):
            return self._encode_handshake(msg)
        if not isinstance(msg, _SENDS[self.role]):
            raise ProtocolError(f"the {self.role.name.lower()} does not send {type(msg).__name__}")
        if not self.can_send:
            raise ProtocolError(
                f"cannot send {type(msg).__name__} before the handshake finished "
                "(wait for StreamCodec.can_send)"
            )
        assert self._key is not None
        if self._send_counter >= MAX_COUNTER:
            raise ProtocolError("frame counter exhausted; reconnect to start a new session")
        ftype, payload = _encode_payload(msg)
        frame = self._frame(self._key, ftype, self._send_counter + 1, payload)
        self._send_counter += 1
        return frame

    def _encode_handshake(self, msg: Hello | HelloReply) -> bytes:
        if isinstance(msg, Hello):
            if self.role is not Role.CONTROLLER:
                raise ProtocolError("only the controller sends Hello")
            if self._handshake_sent:
                raise ProtocolError("Hello already sent on this connection; make a new codec")
            if msg.nonce != self.nonce:
                raise ProtocolError("Hello.nonce must be the nonce this codec was built with")
        else:
            if self.role is not Role.VEHICLE:
                raise ProtocolError("only the vehicle sends HelloReply")
            if not self._handshake_received or self._handshake_sent:
                raise ProtocolError("HelloReply goes once, after a Hello was received")
            if msg.controller_nonce != self._peer_nonce or msg.vehicle_nonce != self.nonce:
                raise ProtocolError(
                    "HelloReply must echo the Hello's nonce and carry this codec's nonce"
                )
        ftype, payload = _encode_payload(msg)
        frame = self._frame(self._psk, ftype, 0, payload)
        self._handshake_sent = True
        return frame

    def _frame(self, key: bytes, ftype: FrameType, counter: int, payload: bytes) -> bytes:
        if len(payload) > MAX_PAYLOAD:
            raise ProtocolError(
                f"{ftype.name} payload is {len(payload)} bytes; at most {MAX_PAYLOAD} "
                "fit in a frame (shorten names, texts or params)"
            )
        head = struct.pack(">2sBHI", STREAM_MAGIC, ftype, len(payload), counter)
        body = head + struct.pack(">H", _header_crc(head)) + payload
        return body + _tag(key, self.role, body)

    # -- decoding --

    def feed(self, data: bytes) -> list[StreamMessage | Rejected]:
        """Add received bytes; return the messages and rejections they complete, in order.

        Any chunking works, one byte at a time included. Incomplete frames wait for more
        bytes. Never raises.
        """
        out: list[StreamMessage | Rejected] = []
        buf = self._buf
        buf += data
        pos = 0
        while len(buf) - pos >= len(STREAM_MAGIC):
            if buf[pos : pos + 2] != STREAM_MAGIC:
                nxt = buf.find(STREAM_MAGIC, pos + 1)
                if nxt < 0:
                    # Keep a last byte that may be the first half of the next magic.
                    nxt = len(buf) - 1 if buf[-1] == STREAM_MAGIC[0] else len(buf)
                self._garbage(out, nxt - pos)
                pos = nxt
                continue
            if len(buf) - pos < HEADER_SIZE:
                break
            _, ftype, length, counter, crc = _HEADER.unpack_from(buf, pos)
            if _header_crc(buf[pos : pos + HEADER_SIZE - 2]) != crc:
                self._reject_start(out, RejectReason.BAD_HEADER, "header check failed")
                pos += 1
                continue
            if length > MAX_PAYLOAD:
                self._reject_start(
                    out, RejectReason.OVERSIZED, f"declared payload {length} > {MAX_PAYLOAD}"
                )
                pos += 1
                continue
            total = HEADER_SIZE + length + TAG_SIZE
            if len(buf) - pos < total:
                break
            frame = bytes(buf[pos : pos + total])
            result = self._accept(ftype, counter, frame)
            out.append(result)
            if isinstance(result, Rejected) and result.reason in _UNAUTHENTICATED:
                # The length may be the corrupted part: rescan from the next byte so a
                # good frame inside the claimed span is not lost.
                self._skipping = True
                pos += 1
            else:
                self._skipping = False
                pos += total
        del buf[:pos]
        self.rejected += sum(isinstance(m, Rejected) for m in out)
        return out

    def _garbage(self, out: list[StreamMessage | Rejected], count: int) -> None:
        if not self._skipping:
            out.append(
                Rejected(
                    RejectReason.BAD_MAGIC,
                    f"{count} bytes not starting a frame; skipping to the next frame start",
                )
            )
            self._skipping = True

    def _reject_start(
        self, out: list[StreamMessage | Rejected], reason: RejectReason, detail: str
    ) -> None:
        # One report per incident: the bytes skipped while resynchronising stay quiet.
        out.append(Rejected(reason, detail))
        self._skipping = True

    def _accept(self, ftype: int, counter: int, frame: bytes) -> StreamMessage | Rejected:
        handshake = ftype in _HANDSHAKE_TYPES
        if handshake:
            key = self._psk
        elif self._key is None:
            return Rejected(RejectReason.NO_SESSION, f"frame type {ftype:#04x} before handshake")
        else:
            key = self._key
        body, tag = frame[:-TAG_SIZE], frame[-TAG_SIZE:]
        if not hmac.compare_digest(_tag(key, self._peer, body), tag):
            return Rejected(RejectReason.BAD_TAG, f"frame type {ftype:#04x}, counter {counter}")
        payload = body[HEADER_SIZE:]
        if handshake:
            return self._accept_handshake(FrameType(ftype), counter, payload)
        if counter <= self._recv_counter:
            return Rejected(
                RejectReason.REPLAY, f"counter {counter} <= {self._recv_counter} already seen"
            )
        self._recv_counter = counter
        self._peer_verified = True
        if ftype not in _KNOWN_TYPES:
            return Rejected(RejectReason.UNKNOWN_TYPE, f"frame type {ftype:#04x}")
        if ftype not in _RECEIVES[self.role]:
            return Rejected(
                RejectReason.UNEXPECTED,
                f"{FrameType(ftype).name} does not go to the {self.role.name.lower()}",
            )
        try:
            return _decode_payload(FrameType(ftype), payload)
        except _Malformed as exc:
            return Rejected(RejectReason.MALFORMED, f"{FrameType(ftype).name}: {exc}")

    def _accept_handshake(
        self, ftype: FrameType, counter: int, payload: bytes
    ) -> StreamMessage | Rejected:
        wanted = FrameType.HELLO_REPLY if self.role is Role.CONTROLLER else FrameType.HELLO
        if ftype is not wanted or self._handshake_received or counter != 0:
            return Rejected(RejectReason.UNEXPECTED, f"{ftype.name} out of handshake order")
        if self.role is Role.CONTROLLER and not self._handshake_sent:
            return Rejected(RejectReason.UNEXPECTED, "HelloReply before our Hello")
        try:
            msg = _decode_payload(ftype, payload)
        except _Malformed as exc:
            return Rejected(RejectReason.MALFORMED, f"{ftype.name}: {exc}")
        if isinstance(msg, HelloReply):
            if not hmac.compare_digest(msg.controller_nonce, self.nonce):
                return Rejected(RejectReason.UNEXPECTED, "HelloReply for another Hello (stale)")
            self._peer_nonce = msg.vehicle_nonce
            self._key = session_key(self._psk, self.nonce, msg.vehicle_nonce)
            self._peer_verified = True
        elif isinstance(msg, Hello):
            self._peer_nonce = msg.nonce
            self._key = session_key(self._psk, msg.nonce, self.nonce)
        self._handshake_received = True
        return msg


# --- datagrams ---------------------------------------------------------------------------

_TELEMETRY = struct.Struct(">2sBId6f")
TELEMETRY_SIZE: Final = _TELEMETRY.size + TAG_SIZE  # 55


def encode_datagram(key: bytes, msg: Telemetry) -> bytes:
    """One telemetry datagram, tagged with the connection's `StreamCodec.session_key`.

    Raises:
        ProtocolError: a short key, a sequence number outside 1..2**32-1, a non-finite
            time or pose, or a value beyond float32 range.
    """
    key = _check_key(key, "the session key")
    if not isinstance(msg, Telemetry):
        raise ProtocolError(f"only Telemetry goes by datagram, not {type(msg).__name__}")
    seq = _uint(msg.seq, _U32, "Telemetry.seq")
    if seq == 0:
        raise ProtocolError("Telemetry.seq starts at 1")
    pose = [_finite(v, f"Telemetry.{n}") for n, v in zip("xyz", (msg.x, msg.y, msg.z), strict=True)]
    pose.append(_finite(msg.psi, "Telemetry.psi"))
    for name, est in (("est_x", msg.est_x), ("est_y", msg.est_y)):
        pose.append(math.nan if est is None else _finite(est, f"Telemetry.{name}"))
    try:
        body = _TELEMETRY.pack(
            DATAGRAM_MAGIC,
            FrameType.TELEMETRY,
            seq,
            _finite(msg.vehicle_time, "Telemetry.vehicle_time"),
            *pose,
        )
    except (OverflowError, struct.error) as exc:
        raise ProtocolError(f"telemetry value out of float32 range: {exc}") from None
    return body + _tag(key, Role.VEHICLE, body)


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
        self._key = _check_key(key, "the session key")
        self.last_seq = 0
        """Sequence number of the newest accepted datagram (0: none yet)."""
        self.accepted = 0
        self.rejected = 0

    def accept(self, data: bytes) -> Telemetry | Rejected:
        """Telemetry from one received datagram, or why it was dropped. Never raises."""
        result = self._check(data)
        if isinstance(result, Rejected):
            self.rejected += 1
        else:
            self.accepted += 1
            self.last_seq = result.seq
        return result

    def _check(self, data: bytes) -> Telemetry | Rejected:
        if len(data) != TELEMETRY_SIZE:
            return Rejected(RejectReason.BAD_LENGTH, f"{len(data)} bytes, want {TELEMETRY_SIZE}")
        body, tag = bytes(data[:-TAG_SIZE]), bytes(data[-TAG_SIZE:])
        if body[:2] != DATAGRAM_MAGIC:
            return Rejected(RejectReason.BAD_MAGIC, "not a coral v1 datagram")
        if not hmac.compare_digest(_tag(self._key, Role.VEHICLE, body), tag):
            return Rejected(RejectReason.BAD_TAG, "telemetry tag")
        _, ftype, seq, vtime, x, y, z, psi, ex, ey = _TELEMETRY.unpack(body)
        if ftype != FrameType.TELEMETRY:
            return Rejected(RejectReason.UNKNOWN_TYPE, f"datagram type {ftype:#04x}")
        if seq <= self.last_seq:
            return Rejected(RejectReason.LATE, f"seq {seq} <= {self.last_seq} already accepted")
        if not all(math.isfinite(v) for v in (vtime, x, y, z, psi)):
            return Rejected(RejectReason.MALFORMED, "non-finite time or pose")
        if math.isinf(ex) or math.isinf(ey):
            return Rejected(RejectReason.MALFORMED, "infinite estimate")
        return Telemetry(
            seq,
            vtime,
            x,
            y,
            z,
            psi,
            None if math.isnan(ex) else ex,
            None if math.isnan(ey) else ey,
        )


# --- the vehicle's reply ledger ----------------------------------------------------------


class ReplyLedger:
    """The vehicle's record of one mission: which commands ran, which replies are unacked.

    It implements the delivery rules of docs/protocol.md so that every vehicle server gets
    them right: run each command id once; number replies 1, 2, 3...; keep each until the
    controller's cumulative `ReplyAck` covers it; re-send the unacknowledged ones after a
    resume, and a command's replies again when its id arrives twice.

    Args:
        mission_id: the `Hello.mission_id` this ledger belongs to.
    """

    def __init__(self, mission_id: int) -> None:
        self.mission_id = mission_id
        self._seen: set[int] = set()
        self._unacked: dict[int, Reply] = {}  # reply_seq -> reply, in issue order
        self.last_reply_seq = 0
        """Highest reply sequence number issued."""
        self.acked_seq = 0
        """Highest reply sequence number the controller has acknowledged."""

    def first_time(self, command_id: int) -> bool:
        """Record ``command_id``; True if it is new (run it), False if a repeat (do not)."""
        if command_id in self._seen:
            return False
        self._seen.add(command_id)
        return True

    def issue(self, command_id: int, kind: str, vehicle_time: float, detail: str = "") -> Reply:
        """A new reply with the next sequence number, kept until acknowledged."""
        self.last_reply_seq += 1
        reply = Reply(self.last_reply_seq, command_id, kind, vehicle_time, detail)
        self._unacked[reply.reply_seq] = reply
        return reply

    def acknowledge(self, reply_seq: int) -> None:
        """Forget every reply up to ``reply_seq`` (cumulative; stale acks are harmless)."""
        reply_seq = min(reply_seq, self.last_reply_seq)
        if reply_seq <= self.acked_seq:
            return
        self.acked_seq = reply_seq
        for seq in [s for s in self._unacked if s <= reply_seq]:
            del self._unacked[seq]

    def unacknowledged(self, after: int = 0) -> list[Reply]:
        """Replies still unacknowledged with a sequence number above ``after``, in order.

        After a resume, call ``acknowledge(hello.last_reply_seq)`` and re-send these.
        """
        return [r for s, r in self._unacked.items() if s > after]

    def replies_for(self, command_id: int) -> list[Reply]:
        """The unacknowledged replies already issued for ``command_id`` (re-send on a repeat)."""
        return [r for r in self._unacked.values() if r.command_id == command_id]


# --- clocks ------------------------------------------------------------------------------


def clock_offset(t0_cmc: float, t1_cmc: float, t0_rcs: float, t1_rcs: float) -> float:
    """The paper's INIT time offset: t_offset = (t1_cmc - t0_cmc)/2 - (t1_rcs - t0_rcs)/2.

    t0_cmc and t1_cmc are the controller (CMC) clock when it sent the `Hello` and when the
    `HelloReply` arrived; t0_rcs and t1_rcs the vehicle (RCS) clock when the Hello arrived
    and the reply left. The result is half the round trip minus the vehicle's turnaround:
    the estimated one-way delay, which is the offset between the two event logs when each
    is timed from its own INIT event (an RCS event at RCS log time t happened at CMC log
    time t + t_offset). It does not depend on how far apart the clocks are set.

    It assumes the delay is the same both ways. If the Hello took d_up and the reply
    d_down, the estimate is (d_up + d_down)/2 and its error is (d_down - d_up)/2, half
    the asymmetry; on the paper's Internet link, with one-way delays of about 7 s, that
    can be seconds. It also assumes neither clock drifts during the exchange.
    """
    return (t1_cmc - t0_cmc) / 2 - (t1_rcs - t0_rcs) / 2


@dataclass(frozen=True)
class ClockSync:
    """The four INIT times, and conversions between the two clocks built on them.

    Attributes:
        t0_cmc: controller clock when the `Hello` was sent (`Hello.sent_at`).
        t1_cmc: controller clock when the `HelloReply` arrived.
        t0_rcs: vehicle clock when the Hello arrived (`HelloReply.received_at`).
        t1_rcs: vehicle clock when the reply left (`HelloReply.sent_at`).
    """

    t0_cmc: float
    t1_cmc: float
    t0_rcs: float
    t1_rcs: float

    @classmethod
    def from_handshake(cls, hello: Hello, reply: HelloReply, received_at: float) -> ClockSync:
        """Build from the two handshake messages and the controller's arrival time."""
        return cls(hello.sent_at, received_at, reply.received_at, reply.sent_at)

    @property
    def delay(self) -> float:
        """The paper's t_offset, the estimated one-way delay (see `clock_offset`)."""
        return clock_offset(self.t0_cmc, self.t1_cmc, self.t0_rcs, self.t1_rcs)

    @property
    def vehicle_ahead(self) -> float:
        """How far the vehicle clock reads ahead of the controller's (same assumptions)."""
        return self.t0_rcs - (self.t0_cmc + self.delay)

    def to_controller(self, vehicle_time: float) -> float:
        """A vehicle-clock time on the controller's clock, to merge the event logs."""
        return vehicle_time - self.vehicle_ahead

    def to_vehicle(self, controller_time: float) -> float:
        """A controller-clock time on the vehicle's clock."""
        return controller_time + self.vehicle_ahead
