"""The wire protocol: round trips, chunking, hostile input, replay, sizes, clock offset."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from runtime.protocol import (
    HEADER_SIZE,
    MAX_FRAME,
    MAX_PAYLOAD,
    STREAM_MAGIC,
    TAG_SIZE,
    TELEMETRY_SIZE,
    ClockSync,
    Command,
    DatagramReceiver,
    FrameType,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    ParamValue,
    ProtocolError,
    Rejected,
    RejectReason,
    Reply,
    ReplyAck,
    ReplyLedger,
    Role,
    StreamCodec,
    StreamMessage,
    TelemetryRecord,
    clock_offset,
    encode_datagram,
    frame_size,
    session_key,
)

PSK = bytes(range(100, 132))
C_NONCE = bytes(range(16))
V_NONCE = bytes(range(16, 32))
U32 = 2**32 - 1

HELLO = Hello(C_NONCE, 1.0, 42, telemetry_port=5005)
HELLO_REPLY = HelloReply(C_NONCE, V_NONCE, 1005.0, 1005.1, False, 0, 30.0)


def connect(
    c_nonce: bytes = C_NONCE, v_nonce: bytes = V_NONCE, psk: bytes = PSK
) -> tuple[StreamCodec, StreamCodec]:
    """A controller and a vehicle codec that completed the handshake."""
    ctl = StreamCodec(psk, Role.CONTROLLER, c_nonce)
    veh = StreamCodec(psk, Role.VEHICLE, v_nonce)
    hello = Hello(c_nonce, 1.0, 42)
    assert veh.feed(ctl.encode(hello)) == [hello]
    reply = HelloReply(c_nonce, v_nonce, 1005.0, 1005.1, False, 0, 30.0)
    assert ctl.feed(veh.encode(reply)) == [reply]
    return ctl, veh


def messages(items: list[StreamMessage | Rejected]) -> list[StreamMessage]:
    return [m for m in items if not isinstance(m, Rejected)]


def reasons(items: list[StreamMessage | Rejected]) -> list[RejectReason]:
    return [m.reason for m in items if isinstance(m, Rejected)]


# --- strategies ------------------------------------------------------------------------


def utf8_text(max_bytes: int, min_size: int = 0) -> st.SearchStrategy[str]:
    return st.text(min_size=min_size, max_size=max_bytes).filter(
        lambda s: len(s.encode("utf-8")) <= max_bytes
    )


finite = st.floats(allow_nan=False, allow_infinity=False)
names = utf8_text(32, min_size=1)
param_values: st.SearchStrategy[ParamValue] = st.one_of(
    finite, st.integers(-(2**63), 2**63 - 1), utf8_text(64)
)
commands = st.builds(
    Command,
    command_id=st.integers(0, U32),
    name=names,
    sent_at=finite,
    params=st.dictionaries(names, param_values, max_size=4),
)
replies = st.builds(
    Reply,
    reply_seq=st.integers(0, U32),
    command_id=st.integers(0, U32),
    kind=utf8_text(16, min_size=1),
    vehicle_time=finite,
    detail=utf8_text(200),
)
heartbeats = st.builds(Heartbeat, sent_at=finite)
make_safes = st.builds(
    MakeSafe, request_id=st.integers(0, U32), sent_at=finite, reason=utf8_text(200)
)
make_safe_acks = st.builds(
    MakeSafeAck, request_id=st.integers(0, U32), vehicle_time=finite, first=st.booleans()
)
controller_messages = st.lists(
    st.one_of(commands, st.builds(ReplyAck, st.integers(0, U32)), make_safes, heartbeats),
    max_size=6,
)
vehicle_messages = st.lists(st.one_of(replies, make_safe_acks, heartbeats), max_size=6)
nonces = st.binary(min_size=16, max_size=16)


# --- handshake and round trips ---------------------------------------------------------


def test_handshake_gives_both_ends_the_same_session_key() -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    veh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    assert not ctl.can_send and not veh.can_send
    assert veh.feed(ctl.encode(HELLO)) == [HELLO]
    assert veh.peer_nonce == C_NONCE and not veh.can_send and not veh.peer_verified
    assert ctl.feed(veh.encode(HELLO_REPLY)) == [HELLO_REPLY]
    assert ctl.can_send and veh.can_send and ctl.peer_verified
    assert ctl.session_key == veh.session_key == session_key(PSK, C_NONCE, V_NONCE)
    # The vehicle trusts the connection only once a session frame proves it live.
    assert veh.feed(ctl.encode(Heartbeat(2.0))) == [Heartbeat(2.0)]
    assert veh.peer_verified


@given(hello_nonce=nonces, v_nonce=nonces, t=finite, mission=st.integers(0, 2**64 - 1))
def test_handshake_round_trip(hello_nonce: bytes, v_nonce: bytes, t: float, mission: int) -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, hello_nonce)
    veh = StreamCodec(PSK, Role.VEHICLE, v_nonce)
    hello = Hello(hello_nonce, t, mission, True, 7, 65535)
    assert veh.feed(ctl.encode(hello)) == [hello]
    reply = HelloReply(hello_nonce, v_nonce, t, -t, True, U32, 0.5)
    assert ctl.feed(veh.encode(reply)) == [reply]


@given(controller_messages)
def test_controller_messages_round_trip(msgs: list[StreamMessage]) -> None:
    ctl, veh = connect()
    assert veh.feed(b"".join(ctl.encode(m) for m in msgs)) == msgs


@given(vehicle_messages)
def test_vehicle_messages_round_trip(msgs: list[StreamMessage]) -> None:
    ctl, veh = connect()
    assert ctl.feed(b"".join(veh.encode(m) for m in msgs)) == msgs


def test_unicode_detail_and_negative_large_params_round_trip() -> None:
    ctl, veh = connect()
    cmd = Command(7, "GOTO", 3.5, {"x": -1e300, "n": -(2**63), "tag": "bassin ü"})
    assert veh.feed(ctl.encode(cmd)) == [cmd]
    reply = Reply(1, 7, "error", 12.25, "refusé: profondeur > 5 m 🌊")
    assert ctl.feed(veh.encode(reply)) == [reply]


@given(msgs=controller_messages, data=st.data())
def test_any_chunking_decodes_the_same(msgs: list[StreamMessage], data: st.DataObject) -> None:
    ctl, veh = connect()
    stream = b"".join(ctl.encode(m) for m in msgs)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=12)))
    got: list[StreamMessage | Rejected] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += veh.feed(stream[start:end])
    assert got == msgs
    assert veh.buffered == 0


def test_byte_by_byte_feeding() -> None:
    ctl, veh = connect()
    msgs: list[StreamMessage] = [Command(i, "DEPTH", float(i), {"z": 2.0}) for i in range(1, 4)]
    msgs.append(Heartbeat(9.0))
    stream = b"".join(ctl.encode(m) for m in msgs)
    got: list[StreamMessage | Rejected] = []
    for i in range(len(stream)):
        got += veh.feed(stream[i : i + 1])
    assert got == msgs


# --- hostile input ---------------------------------------------------------------------


@given(st.binary(max_size=3000))
def test_random_bytes_never_raise_and_never_authenticate(data: bytes) -> None:
    for codec in (StreamCodec(PSK, Role.VEHICLE, V_NONCE), connect()[1]):
        out = codec.feed(data)
        assert all(isinstance(m, Rejected) for m in out)
        assert codec.buffered <= MAX_FRAME


@given(st.lists(st.one_of(st.binary(max_size=40), st.just(STREAM_MAGIC)), max_size=30))
def test_bytes_full_of_magic_never_raise(parts: list[bytes]) -> None:
    codec = connect()[1]
    for part in parts:
        assert all(isinstance(m, Rejected) for m in codec.feed(part))


@given(
    garbage=st.binary(min_size=1, max_size=200),
    msgs=st.lists(st.one_of(commands, heartbeats), min_size=1, max_size=4),
)
def test_garbage_before_frames_is_skipped(garbage: bytes, msgs: list[StreamMessage]) -> None:
    assume(STREAM_MAGIC not in garbage)
    ctl, veh = connect()
    out = veh.feed(garbage + b"".join(ctl.encode(m) for m in msgs))
    assert messages(out) == msgs
    assert reasons(out) == [RejectReason.BAD_MAGIC]


def test_truncated_frame_waits_for_the_rest() -> None:
    ctl, veh = connect()
    cmd = Command(1, "DEPTH", 0.0, {"z": 2.0})
    frame = ctl.encode(cmd)
    assert veh.feed(frame[:-1]) == []
    assert veh.buffered == len(frame) - 1
    assert veh.feed(frame[-1:]) == [cmd]


def _header(length: int, counter: int = 1, ftype: int = FrameType.COMMAND) -> bytes:
    import binascii

    head = struct.pack(">2sBHI", STREAM_MAGIC, ftype, length, counter)
    return head + struct.pack(">H", binascii.crc_hqx(head, 0xFFFF))


@pytest.mark.parametrize("length", [MAX_PAYLOAD + 1, 5000, 0xFFFF])
def test_oversized_length_rejected_at_once_without_buffering(length: int) -> None:
    ctl, veh = connect()
    out = veh.feed(_header(length))
    assert reasons(out) == [RejectReason.OVERSIZED]
    assert veh.buffered < HEADER_SIZE
    cmd = Command(1, "SURFACE", 0.0)
    assert messages(veh.feed(ctl.encode(cmd))) == [cmd]


def test_a_flipped_bit_anywhere_is_rejected_and_the_next_frame_decodes() -> None:
    ctl, veh = connect()
    first = ctl.encode(Command(1, "DEPTH", 1.0, {"z": 2.0}))
    frames = [
        ctl.encode(Command(2 + i, "HEADING", 2.0, {"psi": 90.0})) for i in range(len(first) * 8)
    ]
    for bit, good in enumerate(frames):
        bad = bytearray(first)
        bad[bit // 8] ^= 1 << (bit % 8)
        out = veh.feed(bytes(bad) + good)
        assert reasons(out), f"bit {bit} not rejected"
        assert messages(out) == [Command(2 + bit, "HEADING", 2.0, {"psi": 90.0})], f"bit {bit}"


def test_wrong_key_is_rejected() -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    veh = StreamCodec(bytes(32), Role.VEHICLE, V_NONCE)
    assert reasons(veh.feed(ctl.encode(HELLO))) == [RejectReason.BAD_TAG]
    assert veh.session_key is None


def test_replay_within_a_connection_is_rejected() -> None:
    ctl, veh = connect()
    old = ctl.encode(Command(1, "DEPTH", 1.0, {"z": 2.0}))
    new = ctl.encode(Command(2, "DEPTH", 1.0, {"z": 3.0}))
    assert len(messages(veh.feed(old + new))) == 2
    assert reasons(veh.feed(old)) == [RejectReason.REPLAY]
    assert reasons(veh.feed(new)) == [RejectReason.REPLAY]


def test_frames_of_an_earlier_connection_fail_on_a_later_one() -> None:
    ctl1, veh1 = connect()
    recorded = ctl1.encode(Command(1, "GOTO", 1.0, {"x": 5.0, "y": 3.0}))
    veh1.feed(recorded)
    # The controller crashed and restarted: a new connection, counters from 1 again.
    ctl2, veh2 = connect(c_nonce=b"c" * 16, v_nonce=b"v" * 16)
    assert reasons(veh2.feed(recorded)) == [RejectReason.BAD_TAG]
    fresh = Command(1, "GOTO", 9.0, {"x": 5.0, "y": 3.0})
    assert veh2.feed(ctl2.encode(fresh)) == [fresh]


def test_a_replayed_hello_never_verifies_the_connection() -> None:
    ctl, _ = connect()
    recorded = ctl.encode(Heartbeat(3.0))
    hello_bytes = StreamCodec(PSK, Role.CONTROLLER, C_NONCE).encode(Hello(C_NONCE, 1.0, 42))
    attacker_target = StreamCodec(PSK, Role.VEHICLE, b"n" * 16)
    assert attacker_target.feed(hello_bytes) == [Hello(C_NONCE, 1.0, 42)]
    assert reasons(attacker_target.feed(recorded)) == [RejectReason.BAD_TAG]
    assert not attacker_target.peer_verified


def test_a_stale_hello_reply_is_rejected() -> None:
    old_reply = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    old_reply.feed(StreamCodec(PSK, Role.CONTROLLER, C_NONCE).encode(HELLO))
    stale = old_reply.encode(HELLO_REPLY)
    ctl = StreamCodec(PSK, Role.CONTROLLER, b"x" * 16)
    ctl.encode(Hello(b"x" * 16, 50.0, 42))
    assert reasons(ctl.feed(stale)) == [RejectReason.UNEXPECTED]
    assert not ctl.can_send


def test_handshake_order_is_enforced() -> None:
    ctl, veh = connect()
    # A second Hello on a live connection, and session frames before any handshake.
    again = StreamCodec(PSK, Role.CONTROLLER, C_NONCE).encode(HELLO)
    assert reasons(veh.feed(again)) == [RejectReason.UNEXPECTED]
    fresh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    assert reasons(fresh.feed(ctl.encode(Heartbeat(1.0)))) == [RejectReason.NO_SESSION]


def test_authentic_but_malformed_or_unknown_frames_are_rejected() -> None:
    ctl, veh = connect()
    key = ctl.session_key
    assert key is not None
    # Frames with a valid tag built by hand: a peer with a bug, or a newer version.
    bad = ctl._frame(key, FrameType.COMMAND, 50, b"\x00\x01")
    assert reasons(veh.feed(bad)) == [RejectReason.MALFORMED]
    wrong_way = ctl._frame(key, FrameType.REPLY, 51, b"")
    assert reasons(veh.feed(wrong_way)) == [RejectReason.UNEXPECTED]
    unknown = ctl._frame(key, 0x7F, 52, b"")  # type: ignore[arg-type]
    assert reasons(veh.feed(unknown)) == [RejectReason.UNKNOWN_TYPE]
    # Authentic frames advance the counter even when rejected: no replay of them either.
    assert reasons(veh.feed(bad)) == [RejectReason.REPLAY]


# --- misuse raises ProtocolError ---------------------------------------------------------


@pytest.mark.parametrize(
    "msg",
    [
        Command(1, "X" * 33, 0.0),
        Command(1, "", 0.0),
        Command(1, "DEPTH", 0.0, {"z": math.nan}),
        Command(1, "DEPTH", math.inf),
        Command(1, "DEPTH", 0.0, {"z": True}),
        Command(1, "DEPTH", 0.0, {"p" * 33: 1.0}),
        Command(1, "DEPTH", 0.0, {"s": "s" * 65}),
        Command(1, "DEPTH", 0.0, {"n": 2**63}),
        Command(-1, "DEPTH", 0.0),
        Command(2**32, "DEPTH", 0.0),
        Command(1, "DEPTH", 0.0, {f"p{i}": 1.0 for i in range(17)}),
        ReplyAck(-1),
        MakeSafe(2**32, 0.0, "SIGTERM"),
        MakeSafe(1, math.nan, "SIGTERM"),
        MakeSafe(1, 0.0, "r" * 201),
    ],
)
def test_misuse_raises_protocol_error(msg: StreamMessage) -> None:
    ctl, _ = connect()
    with pytest.raises(ProtocolError):
        ctl.encode(msg)


def test_wrong_direction_or_order_raises() -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    with pytest.raises(ProtocolError, match="handshake"):
        ctl.encode(Heartbeat(0.0))
    with pytest.raises(ProtocolError):
        ctl.encode(Hello(b"z" * 16, 0.0, 1))  # not this codec's nonce
    ctl, veh = connect()
    with pytest.raises(ProtocolError):
        ctl.encode(Reply(1, 1, "done", 0.0))
    with pytest.raises(ProtocolError):
        veh.encode(Command(1, "DEPTH", 0.0))
    with pytest.raises(ProtocolError):
        veh.encode(HELLO_REPLY)  # twice
    with pytest.raises(ProtocolError):
        StreamCodec(b"short", Role.VEHICLE, V_NONCE)
    with pytest.raises(ValueError):  # ProtocolError is a ValueError too
        StreamCodec(PSK, Role.VEHICLE, b"short")


def test_a_frame_too_large_for_max_frame_raises() -> None:
    ctl, _ = connect()
    params: dict[str, ParamValue] = {f"p{i:02d}" + "x" * 28: "v" * 64 for i in range(16)}
    with pytest.raises(ProtocolError, match="at most 997"):
        ctl.encode(Command(1, "BIG", 0.0, params))


# --- documented sizes (docs/protocol.md) ------------------------------------------------


SIZES = [
    ("Hello", HELLO, 66),
    ("HelloReply", HELLO_REPLY, 88),
    ("Command DEPTH z=2.0", Command(1, "DEPTH", 0.0, {"z": 2.0}), 57),
    (
        "Command DEPTH? z=2.0 time_out=60",
        Command(2, "DEPTH?", 0.0, {"z": 2.0, "time_out": 60.0}),
        76,
    ),
    ("Command GOTO x, y", Command(3, "GOTO", 0.0, {"x": 5.0, "y": 3.0}), 67),
    ("Command FIX_XY", Command(4, "FIX_XY", 0.0), 47),
    ("Reply ack", Reply(1, 1, "ack", 0.0), 48),
    ("Reply done", Reply(2, 1, "done", 0.0), 49),
    ("ReplyAck", ReplyAck(2), 31),
    ("Heartbeat", Heartbeat(0.0), 35),
    ("MakeSafe SIGTERM", MakeSafe(1, 0.0, "SIGTERM"), 47),
    ("MakeSafeAck", MakeSafeAck(1, 0.0, True), 40),
]


@pytest.mark.parametrize(("label", "msg", "size"), SIZES, ids=[s[0] for s in SIZES])
def test_documented_frame_sizes(label: str, msg: StreamMessage, size: int) -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    veh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    if isinstance(msg, Hello):
        assert len(ctl.encode(msg)) == size
        return
    veh.feed(ctl.encode(HELLO))
    reply_frame = veh.encode(HELLO_REPLY)
    if isinstance(msg, HelloReply):
        assert len(reply_frame) == size
        return
    ctl.feed(reply_frame)
    sender = veh if isinstance(msg, Reply | MakeSafeAck) else ctl
    assert len(sender.encode(msg)) == size == frame_size(msg)


def test_documented_constants() -> None:
    assert (HEADER_SIZE, TAG_SIZE, MAX_FRAME, MAX_PAYLOAD) == (11, 16, 1024, 997)
    assert TELEMETRY_SIZE == 55
    assert len(encode_datagram(PSK, TelemetryRecord(0.0, 0.0, 0.0, 0.0, 0.0, seq=1))) == 55


# --- telemetry datagrams -----------------------------------------------------------------


def f32(value: float) -> float:
    result: float = struct.unpack(">f", struct.pack(">f", value))[0]
    return result


small = st.floats(-1e6, 1e6, allow_nan=False)


@given(
    seq=st.integers(1, U32),
    t=finite,
    pose=st.tuples(small, small, small, small),
    est=st.one_of(st.none(), small),
)
def test_telemetry_round_trip_in_float32(
    seq: int, t: float, pose: tuple[float, float, float, float], est: float | None
) -> None:
    sent = TelemetryRecord(t, *pose, est, est, seq=seq)
    got = DatagramReceiver(PSK).accept(encode_datagram(PSK, sent))
    rounded = None if est is None else f32(est)
    x, y, z, psi = (f32(v) for v in pose)
    assert got == TelemetryRecord(t, x, y, z, psi, rounded, rounded, seq=seq)


def test_late_and_duplicate_telemetry_dropped() -> None:
    rx = DatagramReceiver(PSK)
    got = [
        rx.accept(encode_datagram(PSK, TelemetryRecord(s, 0, 0, 1, 0, seq=s)))
        for s in (1, 3, 2, 3, 4)
    ]
    assert [g.seq if isinstance(g, TelemetryRecord) else g.reason for g in got] == [
        1,
        3,
        RejectReason.LATE,
        RejectReason.LATE,
        4,
    ]
    assert (rx.accepted, rx.rejected, rx.last_seq) == (3, 2, 4)


@given(st.binary(max_size=120))
def test_random_datagrams_never_raise(data: bytes) -> None:
    assert isinstance(DatagramReceiver(PSK).accept(data), Rejected)


def test_flipped_or_foreign_datagrams_rejected() -> None:
    good = encode_datagram(PSK, TelemetryRecord(5.0, 1.0, 2.0, 3.0, 45.0, 1.1, 2.1, seq=1))
    for bit in range(len(good) * 8):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert isinstance(DatagramReceiver(PSK).accept(bytes(bad)), Rejected), bit
    wrong = DatagramReceiver(bytes(32)).accept(good)
    assert isinstance(wrong, Rejected) and wrong.reason is RejectReason.BAD_TAG
    assert isinstance(DatagramReceiver(PSK).accept(good + b"x"), Rejected)


def test_datagram_misuse_raises() -> None:
    for bad in (
        TelemetryRecord(0.0, 0, 0, 0, 0),
        TelemetryRecord(math.nan, 0, 0, 0, 0, seq=1),
        TelemetryRecord(0.0, 1e39, 0, 0, 0, seq=1),
        TelemetryRecord(0.0, 0, 0, 0, 0, math.inf, seq=1),
    ):
        with pytest.raises(ProtocolError):
            encode_datagram(PSK, bad)


# --- reply ledger ------------------------------------------------------------------------


def test_reply_ledger_runs_each_command_once_and_keeps_replies_until_acked() -> None:
    ledger = ReplyLedger(42)
    assert ledger.first_time(1) and not ledger.first_time(1)
    ack = ledger.issue(1, "ack", 10.0)
    done = ledger.issue(1, "done", 20.0)
    other = ledger.issue(2, "ack", 21.0)
    assert [r.reply_seq for r in (ack, done, other)] == [1, 2, 3]
    assert ledger.replies_for(1) == [ack, done]
    ledger.acknowledge(1)
    assert ledger.unacknowledged() == [done, other]
    # Resume: the controller consumed up to 2 before the connection dropped.
    ledger.acknowledge(2)
    assert ledger.unacknowledged() == [other]
    ledger.acknowledge(1)  # stale acks change nothing
    assert ledger.acked_seq == 2
    ledger.acknowledge(99)  # beyond what was issued: capped
    assert ledger.unacknowledged() == [] and ledger.acked_seq == 3


# --- clock offset ------------------------------------------------------------------------


def test_clock_offset_symmetric_delay_is_exact() -> None:
    # Vehicle clock 1000 s ahead; 3.5 s each way, as on the paper's Internet link; 0.2 s
    # turnaround at the vehicle.
    t0_cmc, ahead, d, turn = 100.0, 1000.0, 3.5, 0.2
    t0_rcs = t0_cmc + d + ahead
    t1_rcs = t0_rcs + turn
    t1_cmc = t1_rcs - ahead + d
    assert clock_offset(t0_cmc, t1_cmc, t0_rcs, t1_rcs) == pytest.approx(d)
    sync = ClockSync(t0_cmc, t1_cmc, t0_rcs, t1_rcs)
    assert sync.vehicle_ahead == pytest.approx(ahead)
    assert sync.to_controller(t0_rcs) == pytest.approx(t0_cmc + d)
    assert sync.to_vehicle(sync.to_controller(1234.5)) == pytest.approx(1234.5)


@given(
    up=st.floats(0, 10),
    down=st.floats(0, 10),
    ahead=st.floats(-1e5, 1e5),
    turn=st.floats(0, 5),
)
def test_clock_offset_error_is_half_the_asymmetry(
    up: float, down: float, ahead: float, turn: float
) -> None:
    t0_cmc = 50.0
    t0_rcs = t0_cmc + up + ahead
    t1_rcs = t0_rcs + turn
    t1_cmc = t1_rcs - ahead + down
    offset = clock_offset(t0_cmc, t1_cmc, t0_rcs, t1_rcs)
    assert offset - up == pytest.approx((down - up) / 2, abs=1e-9)
    sync = ClockSync(t0_cmc, t1_cmc, t0_rcs, t1_rcs)
    assert sync.vehicle_ahead - ahead == pytest.approx((up - down) / 2, abs=1e-9)


def test_clock_sync_from_handshake() -> None:
    sync = ClockSync.from_handshake(HELLO, HELLO_REPLY, received_at=9.1)
    assert (sync.t0_cmc, sync.t1_cmc, sync.t0_rcs, sync.t1_rcs) == (1.0, 9.1, 1005.0, 1005.1)
    assert sync.delay == pytest.approx(4.0)


# --- import rule -------------------------------------------------------------------------


def test_protocol_imports_nothing_else_of_ours() -> None:
    """Every module of the package imports only itself, the shared telemetry record and
    ``coral_lang.diagnostics``: the vehicle side builds on it without the engine."""
    import ast
    from pathlib import Path

    import runtime.protocol

    folder = Path(runtime.protocol.__file__).parent
    modules = sorted(folder.glob("*.py"))
    assert {m.stem for m in modules} >= {"__init__", "codec", "datagrams", "ledger", "clock"}
    ours = {"runtime", "analysis", "romeo_sim", "coral_lang"}
    imported = set()
    for module in modules:
        for node in ast.walk(ast.parse(module.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                imported |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
    outside = {
        m for m in imported if m.split(".")[0] in ours and not m.startswith("runtime.protocol")
    }
    assert outside == {"coral_lang.diagnostics", "runtime.telemetry"}


def test_every_part_is_re_exported_by_the_package() -> None:
    """``from runtime.protocol import X`` reaches every public name of every part."""
    import importlib

    import runtime.protocol as protocol

    for part in ("wire", "messages", "auth", "payload", "codec", "datagrams", "ledger", "clock"):
        module = importlib.import_module(f"runtime.protocol.{part}")
        for name in module.__all__:
            if name in protocol.__all__:
                assert getattr(protocol, name) is getattr(module, name), name


# --- delivery across connection resets ---------------------------------------------------


class _Vehicle:
    """A minimal vehicle server following docs/protocol.md, on `ReplyLedger`."""

    def __init__(self) -> None:
        self.ledger: ReplyLedger | None = None
        self.executed: list[int] = []
        self.running: list[int] = []
        self.codec: StreamCodec | None = None
        self.resend_due = False

    def connect(self, nonce: bytes) -> None:
        self.codec = StreamCodec(PSK, Role.VEHICLE, nonce)
        self.resend_due = False

    @property
    def live(self) -> bool:
        return self.codec is not None and self.codec.peer_verified and not self.resend_due

    def receive(self, data: bytes) -> bytes:
        assert self.codec is not None
        out = b""
        for msg in self.codec.feed(data):
            assert not isinstance(msg, Rejected), msg
            if isinstance(msg, Hello):
                ledger = self.ledger
                resumed = ledger is not None and msg.resume and ledger.mission_id == msg.mission_id
                if ledger is None or not resumed:
                    ledger = self.ledger = ReplyLedger(msg.mission_id)
                out += self.codec.encode(
                    HelloReply(msg.nonce, self.codec.nonce, 0.0, 0.0, resumed, 0, 30.0)
                )
                # Act on the resume only once the connection is proven live.
                self.resend_due = True
                self.resume_from = msg.last_reply_seq
                continue
            assert self.ledger is not None
            if self.resend_due:
                self.ledger.acknowledge(self.resume_from)
                out += b"".join(self.codec.encode(r) for r in self.ledger.unacknowledged())
                self.resend_due = False
            if isinstance(msg, Command):
                if self.ledger.first_time(msg.command_id):
                    self.executed.append(msg.command_id)
                    self.running.append(msg.command_id)
                    out += self.codec.encode(self.ledger.issue(msg.command_id, "ack", 0.0))
                else:
                    replies = self.ledger.replies_for(msg.command_id)
                    out += b"".join(self.codec.encode(r) for r in replies)
            elif isinstance(msg, ReplyAck):
                self.ledger.acknowledge(msg.reply_seq)
        return out

    def finish_one(self) -> bytes:
        """The oldest running command completes; its reply goes now if the link is live."""
        assert self.ledger is not None and self.codec is not None
        reply = self.ledger.issue(self.running.pop(0), "done", 0.0)
        return self.codec.encode(reply) if self.live else b""


class _Controller:
    """A minimal engine side: resend pending commands, consume replies once, ack them."""

    def __init__(self) -> None:
        self.pending: dict[int, Command] = {}
        self.next_id = 1
        self.consumed_seq = 0
        self.consumed: list[Reply] = []
        self.started = False  # the vehicle has answered a Hello of this mission
        self.resume = False
        self.codec = StreamCodec(PSK, Role.CONTROLLER, bytes(16))

    def connect(self, nonce: bytes) -> bytes:
        self.codec = StreamCodec(PSK, Role.CONTROLLER, nonce)
        self.resume = self.started
        return self.codec.encode(Hello(nonce, 0.0, 7, self.resume, self.consumed_seq))

    def command(self) -> bytes:
        cmd = Command(self.next_id, "DEPTH", 0.0, {"z": 2.0})
        self.pending[cmd.command_id] = cmd
        self.next_id += 1
        return self.codec.encode(cmd) if self.codec.can_send else b""

    def receive(self, data: bytes) -> bytes:
        out = b""
        for msg in self.codec.feed(data):
            assert not isinstance(msg, Rejected), msg
            if isinstance(msg, HelloReply):
                assert msg.resumed == self.resume  # the vehicle never restarts here
                self.started = True
                out += self.codec.encode(Heartbeat(0.0))
                out += b"".join(self.codec.encode(c) for c in self.pending.values())
            elif isinstance(msg, Reply):
                if msg.reply_seq <= self.consumed_seq:
                    continue  # a re-sent reply, consumed already
                assert msg.reply_seq == self.consumed_seq + 1, "a reply was skipped"
                self.consumed_seq = msg.reply_seq
                self.consumed.append(msg)
                self.pending.pop(msg.command_id, None)
                out += self.codec.encode(ReplyAck(msg.reply_seq))
        return out


@pytest.mark.slow
@settings(max_examples=300)
@given(st.data())
def test_no_command_lost_none_done_twice_every_reply_consumed_once(data: st.DataObject) -> None:
    ctl, veh = _Controller(), _Vehicle()
    nonce_count = 0

    def fresh_nonce() -> bytes:
        nonlocal nonce_count
        nonce_count += 1
        return nonce_count.to_bytes(16, "big")

    def reconnect() -> tuple[bytearray, bytearray]:
        veh.connect(fresh_nonce())
        return bytearray(ctl.connect(fresh_nonce())), bytearray()

    to_veh, to_ctl = reconnect()
    # c: a new command; v / C: bytes reach the vehicle / controller; d: a command completes;
    # x: the connection drops.
    steps = data.draw(st.lists(st.sampled_from("cvCvCdx"), max_size=40))
    for step in steps:
        if step == "c":
            to_veh += ctl.command()
        elif step == "v" and to_veh:
            k = data.draw(st.sampled_from([len(to_veh), 1]) | st.integers(1, len(to_veh)))
            to_ctl += veh.receive(bytes(to_veh[:k]))
            del to_veh[:k]
        elif step == "C" and to_ctl:
            k = data.draw(st.sampled_from([len(to_ctl), 1]) | st.integers(1, len(to_ctl)))
            to_veh += ctl.receive(bytes(to_ctl[:k]))
            del to_ctl[:k]
        elif step == "d" and veh.running:
            to_ctl += veh.finish_one()
        elif step == "x":
            # The connection drops: part of what was in flight arrives, the rest is lost.
            veh.receive(bytes(to_veh[: data.draw(st.integers(0, len(to_veh)))]))
            ctl.receive(bytes(to_ctl[: data.draw(st.integers(0, len(to_ctl)))]))
            to_veh, to_ctl = reconnect()
    # Let the mission finish on a good connection.
    to_veh, to_ctl = reconnect()
    for _ in range(200):
        if to_veh:
            to_ctl += veh.receive(bytes(to_veh))
            to_veh.clear()
        elif to_ctl:
            to_veh += ctl.receive(bytes(to_ctl))
            to_ctl.clear()
        elif veh.running:
            to_ctl += veh.finish_one()
        else:
            break
    issued = list(range(1, ctl.next_id))
    assert sorted(veh.executed) == issued  # none lost, none done twice
    assert len(veh.executed) == len(set(veh.executed))
    assert [r.reply_seq for r in ctl.consumed] == list(range(1, 2 * len(issued) + 1))
    kinds = sorted((r.command_id, r.kind) for r in ctl.consumed)
    assert kinds == sorted([(i, "ack") for i in issued] + [(i, "done") for i in issued])
    assert ctl.pending == {}


def test_reset_scenarios_step_by_step() -> None:
    ctl, veh = _Controller(), _Vehicle()
    nonces = iter(n.to_bytes(16, "big") for n in range(1, 100))

    def reconnect() -> None:
        veh.connect(next(nonces))
        hello = ctl.connect(next(nonces))
        veh_out = ctl.receive(veh.receive(hello))  # Heartbeat and pending commands
        ctl_in = veh.receive(veh_out)
        while ctl_in:
            ctl_in = veh.receive(ctl.receive(ctl_in))

    reconnect()
    # 1. A command reaches the vehicle; the reset loses its ack on the way back.
    lost = veh.receive(ctl.command())
    assert lost and veh.executed == [1]
    reconnect()  # the command goes again; the vehicle re-sends the ack, runs nothing
    assert veh.executed == [1] and [(r.reply_seq, r.kind) for r in ctl.consumed] == [(1, "ack")]
    # 2. The command completes while the link is down: the reply is kept and re-sent.
    veh.connect(next(nonces))  # the controller side has not reconnected yet
    assert veh.finish_one() == b""
    reconnect()
    assert [(r.reply_seq, r.kind) for r in ctl.consumed] == [(1, "ack"), (2, "done")]
    # 3. The ReplyAck is lost: the Hello's last_reply_seq tells the vehicle instead.
    ctl_acks = ctl.receive(veh.receive(ctl.command()))
    assert veh.ledger is not None and veh.ledger.acked_seq == 2 and ctl_acks  # ack unsent
    reconnect()
    assert veh.ledger.acked_seq == 3 and veh.ledger.unacknowledged() == []
    assert [r.reply_seq for r in ctl.consumed] == [1, 2, 3] and veh.executed == [1, 2]


def test_status_line_and_rejection_count() -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    assert ctl.status == "controller link: awaiting handshake, sent 0, received 0, rejected 0"
    veh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    veh.feed(ctl.encode(HELLO))
    assert "Hello sent, awaiting HelloReply" in ctl.status
    ctl.feed(veh.encode(HELLO_REPLY))
    veh.feed(ctl.encode(Heartbeat(1.0)) + b"junk")
    assert veh.status == "vehicle link: live, sent 0, received 1, rejected 1"


def test_frame_size_checks_at_setup() -> None:
    with pytest.raises(ProtocolError, match="parameter name"):
        frame_size(Command(1, "GOTO", 0.0, {"x" * 40: 1.0}))


def test_public_surface() -> None:
    import runtime.protocol as protocol

    # Both the engine and the simulator build on these; change them on purpose only.
    assert sorted(protocol.__all__) == sorted(
        [
            "ClockSync",
            "Command",
            "DATAGRAM_MAGIC",
            "DatagramReceiver",
            "FrameType",
            "HEADER_SIZE",
            "Heartbeat",
            "Hello",
            "HelloReply",
            "MakeSafe",
            "MakeSafeAck",
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
            "ParamValue",
            "ProtocolError",
            "RejectReason",
            "Rejected",
            "Reply",
            "ReplyAck",
            "ReplyLedger",
            "Role",
            "STREAM_MAGIC",
            "StreamCodec",
            "StreamMessage",
            "TAG_SIZE",
            "TELEMETRY_SIZE",
            "TelemetryRecord",
            "clock_offset",
            "encode_datagram",
            "frame_size",
            "session_key",
        ]
    )
    assert all(hasattr(protocol, name) for name in protocol.__all__)


def test_session_frames_right_after_the_hello_reply_in_one_chunk() -> None:
    ctl = StreamCodec(PSK, Role.CONTROLLER, C_NONCE)
    veh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    veh.feed(ctl.encode(HELLO))
    resent: list[StreamMessage] = [Reply(4, 2, "done", 7.0), Heartbeat(8.0)]
    chunk = veh.encode(HELLO_REPLY) + b"".join(veh.encode(m) for m in resent)
    assert ctl.feed(chunk) == [HELLO_REPLY, *resent]


def test_hello_reply_before_our_hello_is_unexpected() -> None:
    veh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    veh.feed(StreamCodec(PSK, Role.CONTROLLER, C_NONCE).encode(HELLO))
    reply = veh.encode(HELLO_REPLY)
    assert reasons(StreamCodec(PSK, Role.CONTROLLER, C_NONCE).feed(reply)) == [
        RejectReason.UNEXPECTED
    ]


def test_counter_exhaustion_asks_for_a_reconnect() -> None:
    ctl, _ = connect()
    ctl._send_counter = 2**32 - 1
    with pytest.raises(ProtocolError, match="reconnect"):
        ctl.encode(Heartbeat(0.0))


def test_a_megabyte_of_garbage_buffers_nothing() -> None:
    ctl, veh = connect()
    out = veh.feed(bytes(range(256)) * 4096)
    assert reasons(out) == [RejectReason.BAD_MAGIC]
    assert veh.buffered <= 1
    assert veh.feed(ctl.encode(Heartbeat(1.0))) == [Heartbeat(1.0)]


# --- make-safe ----------------------------------------------------------------------------


def test_make_safe_is_only_taken_authenticated_once_and_in_its_direction() -> None:
    ctl, veh = connect()
    frame = ctl.encode(MakeSafe(7, 1.5, "SIGTERM"))
    assert veh.feed(frame) == [MakeSafe(7, 1.5, "SIGTERM")]
    # The same bytes again (a replay on this connection) are refused by the counter.
    assert reasons(veh.feed(frame)) == [RejectReason.REPLAY]
    # Under another key (an outsider, or a recorded frame of another connection): bad tag.
    other_ctl, _ = connect(psk=bytes(reversed(PSK)))
    forged = other_ctl.encode(MakeSafe(8, 2.0, "forged"))
    assert reasons(veh.feed(forged)) == [RejectReason.BAD_TAG]
    # Before the handshake a make-safe is no session frame at all.
    fresh = StreamCodec(PSK, Role.VEHICLE, V_NONCE)
    assert reasons(fresh.feed(frame)) == [RejectReason.NO_SESSION]
    # Only the vehicle acknowledges, only the controller asks.
    with pytest.raises(ProtocolError):
        veh.encode(MakeSafe(1, 0.0))
    with pytest.raises(ProtocolError):
        ctl.encode(MakeSafeAck(1, 0.0))
    assert ctl.feed(veh.encode(MakeSafeAck(7, 3.0, False))) == [MakeSafeAck(7, 3.0, False)]
