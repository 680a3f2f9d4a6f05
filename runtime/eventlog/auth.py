"""The event log's MAC chain: the log key, and the MACs of the header and of each commit.

Why: ``coral-run --resume`` drives a vehicle from the controller's log, so a log edited by
hand (an invented marking, ``{mission_complete: 1}`` half-way, ids set back, an older
checkpoint put back) must be refused even when it is consistent and reachable. Whoever
holds the run's pre-shared key can write a log the check accepts; nobody else can.

* The log key is derived from the pre-shared key with HMAC-SHA256 and a label of its own
  (`log_key`), so it is never the key of the link, whose tags use other labels.
* The header's MAC covers every header field; the first commit's MAC starts from it.
* Each commit's MAC covers the previous commit's MAC, the commit record (its number, the
  last event and sample it covers, the SHA-256 of the state it carried) and every event and
  telemetry row it wrote, in order. So any change, deletion, insertion or reordering of a
  row, or any change of a commit record, breaks the chain from that commit on.

Rows are encoded with `encode`, a type-tagged, length-prefixed encoding any language can
reproduce (``docs/eventlog.md``, "The MAC chain"). Only the standard library is used, so
the vehicle side may write authenticated logs too (the layering rule of
``docs/architecture.md``).
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from collections.abc import Iterable
from typing import Final, cast

__all__ = [
    "KEY_ID_SIZE",
    "CommitMac",
    "encode",
    "header_mac",
    "key_id",
    "log_key",
    "state_digest",
]

_KEY_LABEL: Final = b"coral/1 event log key"
_KEY_ID_LABEL: Final = b"coral/1 event log key id"
_HEADER_LABEL: Final = b"coral/1 event log header"
_COMMIT_LABEL: Final = b"coral/1 event log commit"

KEY_ID_SIZE: Final = 8
"""Bytes of the key id kept in the header: enough to tell keys apart, not to attack one."""

_INT: Final = struct.Struct(">q")
_REAL: Final = struct.Struct(">d")
_LENGTH: Final = struct.Struct(">I")


def log_key(psk: bytes) -> bytes:
    """The key that authenticates a run's event logs, derived from its pre-shared key.

    HMAC-SHA256 of a label of its own under the pre-shared key: a MAC made with it can
    never serve as a tag on the link, and the log key reveals nothing of the link's key.

    Raises:
        ValueError: the pre-shared key is empty.
    """
    if not psk:
        raise ValueError("the pre-shared key is empty")
    return hmac.new(bytes(psk), _KEY_LABEL, hashlib.sha256).digest()


def key_id(key: bytes) -> str:
    """A short public name of ``key`` (hex), kept in the header.

    It tells "written with another key" from "edited" in the refusal, and is a MAC of a
    fixed label, so it gives nothing away about the key.
    """
    return hmac.new(key, _KEY_ID_LABEL, hashlib.sha256).digest()[:KEY_ID_SIZE].hex()


def _encode_one(value: object) -> bytes:
    kind = type(value)  # the common cases first: every event row is int, float, str, str
    if kind is str:
        data = cast(str, value).encode("utf-8", "surrogatepass")
        return b"T" + _LENGTH.pack(len(data)) + data
    if kind is float:
        return b"R" + _REAL.pack(cast(float, value) + 0.0)
    if kind is int and -(2**63) <= cast(int, value) < 2**63:
        return b"I" + _INT.pack(value)
    return _encode_other(value)


def _encode_other(value: object) -> bytes:
    if value is None:
        return b"N"
    if isinstance(value, bool):  # SQLite has no booleans: a bool is an edit or a bug
        value = int(value)
    if isinstance(value, int):
        if -(2**63) <= value < 2**63:
            return b"I" + _INT.pack(value)
        text = str(value).encode()  # SQLite cannot hold it; encode it anyway, never raise
        return b"J" + _LENGTH.pack(len(text)) + text
    if isinstance(value, float):
        # + 0.0 makes -0.0 into 0.0: SQLite may store an integral REAL as an integer and
        # give back 0.0 for -0.0, and that must not read as an edit.
        return b"R" + _REAL.pack(value + 0.0)
    if isinstance(value, str):
        data = value.encode("utf-8", "surrogatepass")
        return b"T" + _LENGTH.pack(len(data)) + data
    if isinstance(value, bytes | bytearray | memoryview):
        data = bytes(value)
        return b"B" + _LENGTH.pack(len(data)) + data
    text = repr(value).encode("utf-8", "surrogatepass")
    return b"?" + _LENGTH.pack(len(text)) + text


def encode(values: Iterable[object]) -> bytes:
    """One row as bytes: each value type-tagged (N, I, R, T, B) and, if variable, sized.

    Each value delimits itself, so rows simply follow each other in a MAC's input; the
    type is part of it, so storing ``'1.0'`` where ``1.0`` was is an edit too.
    """
    return b"".join(map(_encode_one, values))


def _as_bytes(text: object) -> bytes:
    if isinstance(text, str):
        return text.encode("utf-8", "surrogatepass")
    if isinstance(text, bytes | bytearray | memoryview):
        return bytes(text)
    return encode([text])


def state_digest(state_text: object) -> str:
    """SHA-256 (hex) of a checkpoint's stored JSON text, as its commit record keeps it."""
    return hashlib.sha256(_as_bytes(state_text)).hexdigest()


def header_mac(key: bytes, fields: Iterable[object]) -> bytes:
    """The MAC of the header: schema version, role, mission, created, meta, net, digest."""
    mac = hmac.new(key, _HEADER_LABEL, hashlib.sha256)
    mac.update(encode(fields))
    return mac.digest()


class CommitMac:
    """The MAC of one commit, fed row by row (the writer at commit, the verifier reading).

    Input: a label, the previous MAC (the header's for commit 1), the commit record
    ``(n, event_seq, sample_n, state_sha)``, then each event row ``(seq, time, kind, data)``
    prefixed ``E`` and each telemetry row ``(n, time, seq, x, y, z, psi, est_x, est_y)``
    prefixed ``S``, in the order the commit wrote them (events, then samples).
    """

    __slots__ = ("_mac",)

    def __init__(
        self,
        key: bytes,
        previous: bytes,
        *,
        n: int,
        event_seq: int,
        sample_n: int,
        state_sha: str | None,
    ) -> None:
        self._mac = hmac.new(key, _COMMIT_LABEL, hashlib.sha256)
        self._mac.update(_LENGTH.pack(len(previous)) + previous)
        self._mac.update(encode((n, event_seq, sample_n, state_sha)))

    def event(self, row: Iterable[object]) -> None:
        """Add one event row ``(seq, time, kind, data)``."""
        self._mac.update(b"E" + encode(row))

    def sample(self, row: Iterable[object]) -> None:
        """Add one telemetry row ``(n, time, seq, x, y, z, psi, est_x, est_y)``."""
        self._mac.update(b"S" + encode(row))

    def digest(self) -> bytes:
        """The commit's MAC, the next commit's ``previous``."""
        return self._mac.digest()
