"""Payloads: encoding looks the encoder up by the message's class and decoding by frame
type (issue 18), so the bytes of every message must be exactly what they were, a
subclass of a message must still encode as it, and the field checks must still refuse
what they refused."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from runtime.protocol.datagrams import encode_datagram
from runtime.protocol.messages import (
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    Reply,
    ReplyAck,
    StreamMessage,
    TelemetryRecord,
)
from runtime.protocol.payload import decode_payload, encode_payload, finite, uint
from runtime.protocol.wire import FrameType, ProtocolError

# Recorded with the code before issue 18: type byte and payload of one message each.
RECORDED: list[tuple[StreamMessage, int, str]] = [
    (
        Hello(bytes(range(16)), 12.5, 2**40 + 3, True, 7, 40000),
        0x01,
        "000102030405060708090a0b0c0d0e0f4029000000000000000001000000000301000000079c40",
    ),
    (
        HelloReply(bytes(range(16)), bytes(range(16, 32)), 1.25, 1.5, False, 9, 30.0),
        0x02,
        "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f3ff40000000000003ff8"
        "0000000000000000000009403e000000000000",
    ),
    (
        Command(5, "XYPSI?", 3.75, {"x": 6.0, "y": -4, "name": "déjà", "time_out": 45.0}),
        0x10,
        "00000005400e0000000000000658595053493f040178014018000000000000017902ffffffffffff"
        "fffc046e616d65030664c3a96ac3a00874696d655f6f7574014046800000000000",
    ),
    (
        Reply(3, 5, "done", 17.125, "tracked for 3 s (range 0.09 m)"),
        0x11,
        "000000030000000504646f6e6540312000000000001e747261636b656420666f722033207320287261"
        "6e676520302e3039206d29",
    ),
    (ReplyAck(3), 0x12, "00000003"),
    (
        MakeSafe(2, 99.5, "operator stop"),
        0x13,
        "000000024058e000000000000d6f70657261746f722073746f70",
    ),
    (MakeSafeAck(2, 100.25, False), 0x14, "00000002405910000000000000"),
    (Heartbeat(13.0), 0x20, "402a000000000000"),
]


@pytest.mark.parametrize(("msg", "ftype", "payload"), RECORDED, ids=lambda v: type(v).__name__)
def test_payloads_are_the_recorded_bytes_and_decode_back(
    msg: StreamMessage, ftype: int, payload: str
) -> None:
    assert encode_payload(msg) == (ftype, bytes.fromhex(payload))
    assert decode_payload(FrameType(ftype), bytes.fromhex(payload)) == msg


def test_datagram_is_the_recorded_bytes() -> None:
    record = TelemetryRecord(12.5, 1.5, 2.5, 2.0, 90.0, 1.4, None, 7)
    assert encode_datagram(bytes(range(32)), record).hex() == (
        "c581400000000740290000000000003fc00000402000004000000042b400003fb333337fc00000"
        "8df311a0dfd15411328dbbaace3aa7de"
    )


@dataclass(frozen=True)
class LabelledReply(Reply):
    label: str = ""


def test_a_subclass_of_a_message_encodes_as_the_message() -> None:
    plain = Reply(3, 5, "done", 17.125, "ok")
    assert encode_payload(LabelledReply(3, 5, "done", 17.125, "ok", "x")) == encode_payload(plain)


def test_a_telemetry_record_is_not_a_stream_message() -> None:
    with pytest.raises(ProtocolError, match="telemetry goes by datagram"):
        encode_payload(TelemetryRecord(1.0, 0.0, 0.0, 0.0, 0.0))  # type: ignore[arg-type]


def test_number_checks_refuse_what_they_refused() -> None:
    assert finite(2, "t") == 2.0 and type(finite(2, "t")) is float
    value = 1.5
    assert finite(value, "t") is value
    for bad in (math.nan, math.inf, True, "1.0", None):
        with pytest.raises(ProtocolError, match=r"^t must be"):
            finite(bad, "t")  # type: ignore[arg-type]
    assert uint(7, 10, "n") == 7
    for bad_int in (-1, 11, True, 1.0):
        with pytest.raises(ProtocolError, match=r"^n must be an integer in 0\.\.10"):
            uint(bad_int, 10, "n")  # type: ignore[arg-type]
