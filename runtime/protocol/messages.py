"""The messages of the wire protocol, as values: what each frame and datagram means.

Every stream message is a frozen dataclass; `StreamMessage` is their union, the one type
`runtime.protocol.codec.StreamCodec` encodes and decodes. Telemetry is the shared
`runtime.telemetry.TelemetryRecord` (re-exported here), because the event log and the
vehicle models use the same record. Input that is not accepted comes back as a `Rejected`
value, never an exception: data for the log.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TypeAlias

from runtime.telemetry import TelemetryRecord

__all__ = [
    "Command",
    "Heartbeat",
    "Hello",
    "HelloReply",
    "MakeSafe",
    "MakeSafeAck",
    "ParamValue",
    "RejectReason",
    "Rejected",
    "Reply",
    "ReplyAck",
    "StreamMessage",
    "TelemetryRecord",
]

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
