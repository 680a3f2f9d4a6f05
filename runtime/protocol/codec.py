"""The stream codec: both directions of one TCP connection, framed and authenticated.

A `StreamCodec` runs the handshake, derives the session key, numbers and tags outgoing
frames, and turns received bytes (in any chunking, however hostile) into messages and
`Rejected` entries, resynchronising on the next frame start. One per connection.
"""

from __future__ import annotations

import hmac
import struct
from typing import Final

from runtime.protocol.auth import check_key, check_nonce, frame_tag, header_crc, session_key
from runtime.protocol.messages import (
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    Rejected,
    RejectReason,
    Reply,
    ReplyAck,
    StreamMessage,
)
from runtime.protocol.payload import Malformed, decode_payload, encode_payload
from runtime.protocol.wire import (
    HANDSHAKE_TYPES,
    HEADER,
    HEADER_SIZE,
    KNOWN_TYPES,
    MAX_COUNTER,
    MAX_PAYLOAD,
    STREAM_MAGIC,
    TAG_SIZE,
    FrameType,
    ProtocolError,
    Role,
)

__all__ = ["StreamCodec"]


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
_HEAD: Final = struct.Struct(">2sBHI")  # the header up to its CRC (magic..counter)
_CRC: Final = struct.Struct(">H")
# FrameType(value) for the known values, without the enum's call machinery.
_FRAME_TYPES: Final = {int(t): t for t in FrameType}


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
        self._psk = check_key(psk, "the pre-shared key")
        self.role = Role(role)
        self.nonce = check_nonce(nonce, "the nonce")
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
        if isinstance(msg, (Hello, HelloReply)):
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
        ftype, payload = encode_payload(msg)
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
        ftype, payload = encode_payload(msg)
        frame = self._frame(self._psk, ftype, 0, payload)
        self._handshake_sent = True
        return frame

    def _frame(self, key: bytes, ftype: FrameType, counter: int, payload: bytes) -> bytes:
        if len(payload) > MAX_PAYLOAD:
            raise ProtocolError(
                f"{ftype.name} payload is {len(payload)} bytes; at most {MAX_PAYLOAD} "
                "fit in a frame (shorten names, texts or params)"
            )
        head = _HEAD.pack(STREAM_MAGIC, ftype, len(payload), counter)
        body = head + _CRC.pack(header_crc(head)) + payload
        return body + frame_tag(key, self.role, body)

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
            _, ftype, length, counter, crc = HEADER.unpack_from(buf, pos)
            if header_crc(buf[pos : pos + HEADER_SIZE - 2]) != crc:
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
            if isinstance(result, Rejected):
                self.rejected += 1
                if result.reason in _UNAUTHENTICATED:
                    # The length may be the corrupted part: rescan from the next byte so
                    # a good frame inside the claimed span is not lost.
                    self._skipping = True
                    pos += 1
                    continue
            self._skipping = False
            pos += total
        del buf[:pos]
        return out

    def _garbage(self, out: list[StreamMessage | Rejected], count: int) -> None:
        if not self._skipping:
            out.append(
                Rejected(
                    RejectReason.BAD_MAGIC,
                    f"{count} bytes not starting a frame; skipping to the next frame start",
                )
            )
            self.rejected += 1
            self._skipping = True

    def _reject_start(
        self, out: list[StreamMessage | Rejected], reason: RejectReason, detail: str
    ) -> None:
        # One report per incident: the bytes skipped while resynchronising stay quiet.
        out.append(Rejected(reason, detail))
        self.rejected += 1
        self._skipping = True

    def _accept(self, ftype: int, counter: int, frame: bytes) -> StreamMessage | Rejected:
        handshake = ftype in HANDSHAKE_TYPES
        if handshake:
            key = self._psk
        elif self._key is None:
            return Rejected(RejectReason.NO_SESSION, f"frame type {ftype:#04x} before handshake")
        else:
            key = self._key
        body, tag = frame[:-TAG_SIZE], frame[-TAG_SIZE:]
        if not hmac.compare_digest(frame_tag(key, self._peer, body), tag):
            return Rejected(RejectReason.BAD_TAG, f"frame type {ftype:#04x}, counter {counter}")
        payload = body[HEADER_SIZE:]
        if handshake:
            return self._accept_handshake(_FRAME_TYPES[ftype], counter, payload)
        if counter <= self._recv_counter:
            return Rejected(
                RejectReason.REPLAY, f"counter {counter} <= {self._recv_counter} already seen"
            )
        self._recv_counter = counter
        self._peer_verified = True
        if ftype not in KNOWN_TYPES:
            return Rejected(RejectReason.UNKNOWN_TYPE, f"frame type {ftype:#04x}")
        known = _FRAME_TYPES[ftype]
        if known not in _RECEIVES[self.role]:
            return Rejected(
                RejectReason.UNEXPECTED,
                f"{known.name} does not go to the {self.role.name.lower()}",
            )
        try:
            return decode_payload(known, payload)
        except Malformed as exc:
            return Rejected(RejectReason.MALFORMED, f"{known.name}: {exc}")

    def _accept_handshake(
        self, ftype: FrameType, counter: int, payload: bytes
    ) -> StreamMessage | Rejected:
        wanted = FrameType.HELLO_REPLY if self.role is Role.CONTROLLER else FrameType.HELLO
        if ftype is not wanted or self._handshake_received or counter != 0:
            return Rejected(RejectReason.UNEXPECTED, f"{ftype.name} out of handshake order")
        if self.role is Role.CONTROLLER and not self._handshake_sent:
            return Rejected(RejectReason.UNEXPECTED, "HelloReply before our Hello")
        try:
            msg = decode_payload(ftype, payload)
        except Malformed as exc:
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
