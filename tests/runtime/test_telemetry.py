"""The one telemetry record (runtime/telemetry.py): the same fields from model to timeline.

A sample made by a vehicle model is numbered by the server, sent as a datagram, decoded by
the controller, stored in both event logs and read back: every step hands on the same
`TelemetryRecord`, so a field cannot be renamed or dropped on the way.
"""

from __future__ import annotations

import dataclasses
import math
import sqlite3
import struct
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from romeo_sim.vehicle import Telemetry as RomeoTelemetry
from romeo_sim.vehicle import Vehicle
from runtime import eventlog, protocol
from runtime.eventlog import EventLog
from runtime.protocol import DatagramReceiver, encode_datagram
from runtime.telemetry import TelemetryRecord
from runtime.vehicle import model

KEY = bytes(range(32))
FIELDS = ("vehicle_time", "x", "y", "z", "psi", "est_x", "est_y", "seq")


def f32(value: float) -> float:
    """What a float32 field on the wire gives back."""
    return float(struct.unpack(">f", struct.pack(">f", value))[0])


def test_one_class_under_every_name_it_had() -> None:
    """The protocol, the event log and the vehicle models share the record, not copies."""
    assert [f.name for f in dataclasses.fields(TelemetryRecord)] == list(FIELDS)
    assert protocol.TelemetryRecord is TelemetryRecord
    assert eventlog.TelemetryRecord is model.TelemetryRecord is TelemetryRecord
    for module, old in (
        (protocol, "Telemetry"),
        (eventlog, "TelemetrySample"),
        (model, "TelemetryState"),
        (model, "TelemetrySnapshot"),
    ):
        assert not hasattr(module, old), f"{module.__name__}.{old} is a second name"


def test_a_model_writes_the_pose_positionally_and_leaves_seq_to_the_sender() -> None:
    sample = TelemetryRecord(5.0, 1.0, 2.0, 3.0, 90.0)
    assert (sample.est_x, sample.est_y, sample.seq) == (None, None, 0)
    assert sample.numbered(7) == TelemetryRecord(5.0, 1.0, 2.0, 3.0, 90.0, seq=7)


def test_romeos_snapshot_is_a_record_and_is_sent_as_the_plain_one() -> None:
    snapshot = Vehicle().telemetry()
    assert isinstance(snapshot, RomeoTelemetry) and isinstance(snapshot, TelemetryRecord)
    sent = snapshot.numbered(1)
    assert type(sent) is TelemetryRecord
    assert [getattr(sent, f) for f in FIELDS[:-1]] == [getattr(snapshot, f) for f in FIELDS[:-1]]


finite = st.floats(-1e4, 1e4, allow_nan=False)


@given(
    pose=st.tuples(finite, finite, finite, finite),
    time=st.floats(0.0, 1e6, allow_nan=False),
    est=st.one_of(st.none(), finite),
    seq=st.integers(1, 2**32 - 1),
)
def test_the_datagram_gives_back_the_record_sent_in_float32(
    pose: tuple[float, float, float, float], time: float, est: float | None, seq: int
) -> None:
    sent = TelemetryRecord(time, *pose, est, est).numbered(seq)
    got = DatagramReceiver(KEY).accept(encode_datagram(KEY, sent))
    rounded = None if est is None else f32(est)
    x, y, z, psi = (f32(v) for v in pose)
    assert got == TelemetryRecord(time, x, y, z, psi, rounded, rounded, seq)


def test_the_log_stores_the_record_and_gives_it_back(tmp_path: Path) -> None:
    path = tmp_path / "vehicle.sqlite"
    samples = [
        TelemetryRecord(10.0, 1.0, 2.0, 3.0, 45.0, seq=1),
        TelemetryRecord(10.5, 1.5, 2.0, 3.0, 46.0, 1.4, 2.1, seq=2),
    ]
    with EventLog.create(path, role="vehicle", mission="m", meta={}) as log:
        for sample in samples:
            log.telemetry(sample)
        log.commit()
    with EventLog.open(path) as log:
        assert list(log.samples()) == samples


def test_the_stored_columns_keep_their_names_so_older_logs_still_read(tmp_path: Path) -> None:
    """The table was not renamed: ``time`` holds ``vehicle_time``, as it always did."""
    path = tmp_path / "vehicle.sqlite"
    with EventLog.create(path, role="vehicle", mission="m", meta={}) as log:
        log.telemetry(TelemetryRecord(12.5, 1.0, 2.0, 3.0, 4.0, math.nan, 0.5, seq=3))
        log.commit()
    db = sqlite3.connect(path)
    try:
        columns = [row[1] for row in db.execute("PRAGMA table_info(telemetry)")]
        row = db.execute("SELECT time, seq, est_x, est_y FROM telemetry").fetchone()
    finally:
        db.close()
    assert columns == ["n", "time", "seq", "x", "y", "z", "psi", "est_x", "est_y"]
    assert row == (12.5, 3, None, 0.5)
    assert eventlog.SCHEMA_VERSION == 2


def test_a_sample_the_wire_cannot_carry_is_refused_by_field_name() -> None:
    with pytest.raises(protocol.ProtocolError, match=r"TelemetryRecord\.psi"):
        encode_datagram(KEY, TelemetryRecord(1.0, 0.0, 0.0, 0.0, math.inf, seq=1))
    with pytest.raises(protocol.ProtocolError, match=r"TelemetryRecord\.seq starts at 1"):
        encode_datagram(KEY, TelemetryRecord(1.0, 0.0, 0.0, 0.0, 0.0))
