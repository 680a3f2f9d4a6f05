"""The wire protocol between the CORAL engine (controller) and a vehicle, defined once.

The engine and the vehicle simulator both speak it; each does its own socket I/O (asyncio)
and hands the bytes to the codecs here. This package is pure: no sockets, no clocks, no
randomness. Times and nonces are passed in, so tests can run it under a virtual clock.

What travels where (after the paper, Bruzzone et al., sections III-IV):

* Stream (TCP), both directions, framed and authenticated: the handshake (`Hello`,
  `HelloReply`, which also carries the times for the paper's INIT clock offset), commands
  (`Command`), the vehicle's replies (`Reply`), the controller's acknowledgement of replies
  (`ReplyAck`), the controller's request that the vehicle make itself safe at once
  (`MakeSafe`, answered by `MakeSafeAck`) and `Heartbeat`. One `StreamCodec` per
  connection encodes and decodes them.
* Datagrams (UDP), vehicle to controller: a `TelemetryRecord` each, sequence-numbered;
  `DatagramReceiver` drops late and duplicate ones.

One module per part, each importable on its own; everything public is re-exported here,
so ``from runtime.protocol import X`` is the way to use it:

* `runtime.protocol.wire`: version magics, sizes and limits, `Role`, `FrameType`,
  `ProtocolError`;
* `runtime.protocol.messages`: the messages as frozen dataclasses, `Rejected`;
* `runtime.protocol.auth`: the session key and frame tags;
* `runtime.protocol.payload`: each message's payload to bytes and back, `frame_size`;
* `runtime.protocol.codec`: `StreamCodec`, framing and the handshake;
* `runtime.protocol.datagrams`: telemetry datagrams;
* `runtime.protocol.ledger`: the vehicle's `ReplyLedger` (the delivery rules);
* `runtime.protocol.clock`: the INIT clock offset, `ClockSync`.

The byte layout, sizes at 9600 bps, the key schedule and the delivery rules (no command
lost, none done twice, every reply consumed exactly once) are in ``docs/protocol.md``;
``tests/runtime/test_protocol.py`` pins the documented sizes.

Import rule: the vehicle simulator may import this package, so it imports nothing from
``runtime`` but the shared `runtime.telemetry`, and nothing from ``analysis`` or
``romeo_sim`` (``tests/test_layering.py``).
"""

from __future__ import annotations

from runtime.protocol.auth import session_key
from runtime.protocol.clock import ClockSync, clock_offset
from runtime.protocol.codec import StreamCodec
from runtime.protocol.datagrams import TELEMETRY_SIZE, DatagramReceiver, encode_datagram
from runtime.protocol.ledger import ReplyLedger
from runtime.protocol.messages import (
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    ParamValue,
    Rejected,
    RejectReason,
    Reply,
    ReplyAck,
    StreamMessage,
    TelemetryRecord,
)
from runtime.protocol.payload import frame_size
from runtime.protocol.wire import (
    DATAGRAM_MAGIC,
    HEADER_SIZE,
    MAX_COUNTER,
    MAX_DETAIL_BYTES,
    MAX_FRAME,
    MAX_KIND_BYTES,
    MAX_NAME_BYTES,
    MAX_PARAMS,
    MAX_PAYLOAD,
    MAX_TEXT_BYTES,
    MIN_KEY_SIZE,
    NONCE_SIZE,
    STREAM_MAGIC,
    TAG_SIZE,
    FrameType,
    ProtocolError,
    Role,
)

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
    "TelemetryRecord",
    "clock_offset",
    "encode_datagram",
    "frame_size",
    "session_key",
]
