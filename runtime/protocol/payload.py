"""Payloads: each stream message to bytes and back, and the size of its frame.

Encoding checks every field against the wire's limits and raises `ProtocolError` for
our own mistakes (a name too long, a non-finite float); decoding reads bytes from the
network and raises only `Malformed`, which the codec turns into a `Rejected` value.
The layout of each payload is in ``docs/protocol.md``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from typing import Any

from runtime.protocol.auth import check_nonce
from runtime.protocol.messages import (
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    ParamValue,
    Reply,
    ReplyAck,
    StreamMessage,
    TelemetryRecord,
)
from runtime.protocol.wire import (
    HEADER_SIZE,
    MAX_DETAIL_BYTES,
    MAX_KIND_BYTES,
    MAX_NAME_BYTES,
    MAX_PARAMS,
    MAX_PAYLOAD,
    MAX_TEXT_BYTES,
    TAG_SIZE,
    U16,
    U32,
    U64,
    FrameType,
    ProtocolError,
)

__all__ = ["Malformed", "decode_payload", "encode_payload", "finite", "frame_size", "uint"]


class Malformed(Exception):
    """A payload that does not decode; the codec turns it into a `Rejected` value."""


def finite(value: float, what: str) -> float:
    """``value`` as a float; `ProtocolError` naming ``what`` unless a finite number."""
    if type(value) is float and math.isfinite(value):
        return value  # the usual case, checked first (float(value) would be value itself)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(f"{what} must be a number, not {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ProtocolError(f"{what} must be finite, got {value!r}")
    return value


def uint(value: int, limit: int, what: str) -> int:
    """``value``; `ProtocolError` naming ``what`` unless an int in ``0..limit``."""
    if type(value) is int and 0 <= value <= limit:
        return value  # the usual case, checked first
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
# The frame types as plain module constants (an enum member costs a lookup per use).
_HELLO_TYPE = FrameType.HELLO
_HELLO_REPLY_TYPE = FrameType.HELLO_REPLY
_COMMAND_TYPE = FrameType.COMMAND
_REPLY_TYPE = FrameType.REPLY
_REPLY_ACK_TYPE = FrameType.REPLY_ACK
_MAKE_SAFE_TYPE = FrameType.MAKE_SAFE
_MAKE_SAFE_ACK_TYPE = FrameType.MAKE_SAFE_ACK
_HEARTBEAT_TYPE = FrameType.HEARTBEAT


def encode_payload(msg: StreamMessage) -> tuple[FrameType, bytes]:
    """The frame type and payload of ``msg``; `ProtocolError` for a field out of range."""
    encoder = _ENCODERS.get(type(msg))
    if encoder is None:
        # A subclass of a message encodes as the first message class it is an instance of.
        for cls, candidate in _ENCODERS.items():
            if isinstance(msg, cls):
                encoder = candidate
                break
        else:
            raise ProtocolError(
                f"{type(msg).__name__} is not a stream message"
                + (
                    " (telemetry goes by datagram: use encode_datagram)"
                    if isinstance(msg, TelemetryRecord)
                    else ""
                )
            )
    return encoder(msg)


def _encode_hello(msg: Hello) -> tuple[FrameType, bytes]:
    return _HELLO_TYPE, _HELLO.pack(
        check_nonce(msg.nonce, "Hello.nonce"),
        finite(msg.sent_at, "Hello.sent_at"),
        uint(msg.mission_id, U64, "Hello.mission_id"),
        1 if msg.resume else 0,
        uint(msg.last_reply_seq, U32, "Hello.last_reply_seq"),
        uint(msg.telemetry_port, U16, "Hello.telemetry_port"),
    )


def _encode_hello_reply(msg: HelloReply) -> tuple[FrameType, bytes]:
    return _HELLO_REPLY_TYPE, _HELLO_REPLY.pack(
        check_nonce(msg.controller_nonce, "HelloReply.controller_nonce"),
        check_nonce(msg.vehicle_nonce, "HelloReply.vehicle_nonce"),
        finite(msg.received_at, "HelloReply.received_at"),
        finite(msg.sent_at, "HelloReply.sent_at"),
        1 if msg.resumed else 0,
        uint(msg.last_reply_seq, U32, "HelloReply.last_reply_seq"),
        finite(msg.silence_timeout, "HelloReply.silence_timeout"),
    )


def _encode_command_frame(msg: Command) -> tuple[FrameType, bytes]:
    return _COMMAND_TYPE, _encode_command(msg)


def _encode_reply(msg: Reply) -> tuple[FrameType, bytes]:
    return _REPLY_TYPE, b"".join(
        (
            _REPLY_HEAD.pack(
                uint(msg.reply_seq, U32, "Reply.reply_seq"),
                uint(msg.command_id, U32, "Reply.command_id"),
            ),
            _text(msg.kind, MAX_KIND_BYTES, "reply kind"),
            _F64.pack(finite(msg.vehicle_time, "Reply.vehicle_time")),
            _text(msg.detail, MAX_DETAIL_BYTES, "reply detail", empty=True),
        )
    )


def _encode_reply_ack(msg: ReplyAck) -> tuple[FrameType, bytes]:
    return _REPLY_ACK_TYPE, _U32S.pack(uint(msg.reply_seq, U32, "ReplyAck.reply_seq"))


def _encode_make_safe(msg: MakeSafe) -> tuple[FrameType, bytes]:
    return _MAKE_SAFE_TYPE, _MAKE_SAFE_HEAD.pack(
        uint(msg.request_id, U32, "MakeSafe.request_id"),
        finite(msg.sent_at, "MakeSafe.sent_at"),
    ) + _text(msg.reason, MAX_DETAIL_BYTES, "make-safe reason", empty=True)


def _encode_make_safe_ack(msg: MakeSafeAck) -> tuple[FrameType, bytes]:
    return _MAKE_SAFE_ACK_TYPE, _MAKE_SAFE_ACK.pack(
        uint(msg.request_id, U32, "MakeSafeAck.request_id"),
        finite(msg.vehicle_time, "MakeSafeAck.vehicle_time"),
        1 if msg.first else 0,
    )


def _encode_heartbeat(msg: Heartbeat) -> tuple[FrameType, bytes]:
    return _HEARTBEAT_TYPE, _F64.pack(finite(msg.sent_at, "Heartbeat.sent_at"))


# Looked up by the message's class: one dict lookup, not a chain of isinstance tests.
_ENCODERS: dict[type, Callable[[Any], tuple[FrameType, bytes]]] = {
    Hello: _encode_hello,
    HelloReply: _encode_hello_reply,
    Command: _encode_command_frame,
    Reply: _encode_reply,
    ReplyAck: _encode_reply_ack,
    MakeSafe: _encode_make_safe,
    MakeSafeAck: _encode_make_safe_ack,
    Heartbeat: _encode_heartbeat,
}


def _encode_command(msg: Command) -> bytes:
    if len(msg.params) > MAX_PARAMS:
        raise ProtocolError(
            f"command {msg.name!r} has {len(msg.params)} params; at most {MAX_PARAMS}"
        )
    parts = [
        _COMMAND_HEAD.pack(
            uint(msg.command_id, U32, "Command.command_id"),
            finite(msg.sent_at, "Command.sent_at"),
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
            parts.append(bytes((_PARAM_FLOAT,)) + _F64.pack(finite(value, what)))
        elif isinstance(value, str):
            parts.append(bytes((_PARAM_TEXT,)) + _text(value, MAX_TEXT_BYTES, what, empty=True))
        else:
            raise ProtocolError(f"{what} is a {type(value).__name__}; use float, int or str")
    return b"".join(parts)


class _Reader:
    """Reads a payload front to back; any shortfall or bad value raises `Malformed`."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0

    def unpack(self, fmt: struct.Struct) -> tuple[object, ...]:
        if self.pos + fmt.size > len(self.data):
            raise Malformed("payload too short")
        values = fmt.unpack_from(self.data, self.pos)
        self.pos += fmt.size
        return values

    def byte(self) -> int:
        if self.pos >= len(self.data):
            raise Malformed("payload too short")
        self.pos += 1
        return self.data[self.pos - 1]

    def text(self, limit: int, what: str, *, empty: bool = False) -> str:
        size = self.byte()
        if size > limit or (size == 0 and not empty) or self.pos + size > len(self.data):
            raise Malformed(f"bad length {size} of {what}")
        raw = self.data[self.pos : self.pos + size]
        self.pos += size
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            raise Malformed(f"{what} is not UTF-8") from None

    def f64(self, what: str) -> float:
        (value,) = _F64.unpack(self._take(8))
        if not math.isfinite(value):
            raise Malformed(f"{what} is not finite")
        return float(value)

    def _take(self, size: int) -> bytes:
        if self.pos + size > len(self.data):
            raise Malformed("payload too short")
        self.pos += size
        return self.data[self.pos - size : self.pos]

    def end(self) -> None:
        if self.pos != len(self.data):
            raise Malformed(f"{len(self.data) - self.pos} bytes after the payload")


def _flag(value: object) -> bool:
    if value not in (0, 1):
        raise Malformed(f"flag byte {value!r} is neither 0 nor 1")
    return value == 1


def _finite_field(value: object, what: str) -> float:
    assert isinstance(value, float)
    if not math.isfinite(value):
        raise Malformed(f"{what} is not finite")
    return value


def decode_payload(ftype: FrameType, payload: bytes) -> StreamMessage:
    """The message in ``payload`` (of a known type); `Malformed` when it does not decode."""
    r = _Reader(payload)
    # Any type without a decoder of its own is read as a heartbeat: the caller has
    # checked the type, and HEARTBEAT is the one left.
    msg = _DECODERS.get(ftype, _decode_heartbeat)(r)
    r.end()
    return msg


def _decode_hello(r: _Reader) -> Hello:
    nonce, sent_at, mission_id, resume, last_seq, port = r.unpack(_HELLO)
    assert isinstance(nonce, bytes)
    assert isinstance(mission_id, int) and isinstance(last_seq, int) and isinstance(port, int)
    return Hello(
        nonce,
        _finite_field(sent_at, "sent_at"),
        mission_id,
        _flag(resume),
        last_seq,
        port,
    )


def _decode_hello_reply(r: _Reader) -> HelloReply:
    c_nonce, v_nonce, received_at, sent_at, resumed, last_seq, silence = r.unpack(_HELLO_REPLY)
    assert isinstance(c_nonce, bytes) and isinstance(v_nonce, bytes)
    assert isinstance(last_seq, int)
    return HelloReply(
        c_nonce,
        v_nonce,
        _finite_field(received_at, "received_at"),
        _finite_field(sent_at, "sent_at"),
        _flag(resumed),
        last_seq,
        _finite_field(silence, "silence_timeout"),
    )


def _decode_reply(r: _Reader) -> Reply:
    reply_seq, command_id = r.unpack(_REPLY_HEAD)
    assert isinstance(reply_seq, int) and isinstance(command_id, int)
    kind = r.text(MAX_KIND_BYTES, "reply kind")
    vehicle_time = r.f64("vehicle_time")
    detail = r.text(MAX_DETAIL_BYTES, "detail", empty=True)
    return Reply(reply_seq, command_id, kind, vehicle_time, detail)


def _decode_reply_ack(r: _Reader) -> ReplyAck:
    (reply_seq,) = r.unpack(_U32S)
    assert isinstance(reply_seq, int)
    return ReplyAck(reply_seq)


def _decode_make_safe(r: _Reader) -> MakeSafe:
    request_id, asked_at = r.unpack(_MAKE_SAFE_HEAD)
    assert isinstance(request_id, int)
    reason = r.text(MAX_DETAIL_BYTES, "reason", empty=True)
    return MakeSafe(request_id, _finite_field(asked_at, "sent_at"), reason)


def _decode_make_safe_ack(r: _Reader) -> MakeSafeAck:
    request_id, safe_at, first = r.unpack(_MAKE_SAFE_ACK)
    assert isinstance(request_id, int)
    return MakeSafeAck(request_id, _finite_field(safe_at, "vehicle_time"), _flag(first))


def _decode_heartbeat(r: _Reader) -> Heartbeat:
    return Heartbeat(r.f64("sent_at"))


def _decode_command(r: _Reader) -> Command:
    command_id, sent_at = r.unpack(_COMMAND_HEAD)
    assert isinstance(command_id, int)
    name = r.text(MAX_NAME_BYTES, "command name")
    count = r.byte()
    if count > MAX_PARAMS:
        raise Malformed(f"{count} params; at most {MAX_PARAMS}")
    params: dict[str, ParamValue] = {}
    for _ in range(count):
        pname = r.text(MAX_NAME_BYTES, "parameter name")
        if pname in params:
            raise Malformed(f"parameter {pname!r} twice")
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
            raise Malformed(f"parameter {pname!r} has unknown value type {kind}")
    return Command(command_id, name, _finite_field(sent_at, "sent_at"), params)


# Looked up by frame type: one dict lookup, not a chain of comparisons.
_DECODERS: dict[FrameType, Callable[[_Reader], StreamMessage]] = {
    FrameType.HELLO: _decode_hello,
    FrameType.HELLO_REPLY: _decode_hello_reply,
    FrameType.COMMAND: _decode_command,
    FrameType.REPLY: _decode_reply,
    FrameType.REPLY_ACK: _decode_reply_ack,
    FrameType.MAKE_SAFE: _decode_make_safe,
    FrameType.MAKE_SAFE_ACK: _decode_make_safe_ack,
    FrameType.HEARTBEAT: _decode_heartbeat,
}


def frame_size(msg: StreamMessage) -> int:
    """The size in bytes of ``msg``'s frame; checks it as `StreamCodec.encode` would.

    The engine calls it on every action of a mission at setup, so a name too long or a
    parameter the wire cannot carry is refused before anything moves.

    Raises:
        ProtocolError: the message cannot be encoded (the message says which field).
    """
    ftype, payload = encode_payload(msg)
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(
            f"{ftype.name} payload is {len(payload)} bytes; at most {MAX_PAYLOAD} fit in a frame"
        )
    return HEADER_SIZE + len(payload) + TAG_SIZE
