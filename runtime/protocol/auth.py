"""Keys and tags: the session key of a connection and the tag on every frame.

Frames are tagged with HMAC-SHA256 truncated to `TAG_SIZE` bytes, keyed with the
pre-shared key during the handshake and with the connection's `session_key` after it;
the sender's `Role` is mixed in so a frame cannot be reflected back. The header CRC is
not security (the tag is): it only lets the decoder refuse a corrupted length at once.
"""

from __future__ import annotations

import binascii
import functools
import hashlib
import hmac

from runtime.protocol.wire import MIN_KEY_SIZE, NONCE_SIZE, TAG_SIZE, ProtocolError, Role

__all__ = ["check_key", "check_nonce", "frame_tag", "header_crc", "session_key"]


def check_key(key: bytes, what: str) -> bytes:
    """``key`` as bytes, refused (`ProtocolError`) when shorter than `MIN_KEY_SIZE`."""
    if not isinstance(key, bytes | bytearray) or len(key) < MIN_KEY_SIZE:
        raise ProtocolError(f"{what} must be at least {MIN_KEY_SIZE} bytes")
    return bytes(key)


def check_nonce(nonce: bytes, what: str) -> bytes:
    """``nonce`` as bytes, refused (`ProtocolError`) unless exactly `NONCE_SIZE` long."""
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
    psk = check_key(psk, "the pre-shared key")
    info = (
        b"coral/1 session"
        + check_nonce(controller_nonce, "controller nonce")
        + check_nonce(vehicle_nonce, "vehicle nonce")
    )
    return hmac.new(psk, info, hashlib.sha256).digest()


def frame_tag(key: bytes, sender: Role, body: bytes | bytearray) -> bytes:
    """The tag ``sender`` puts after ``body`` (a frame's header and payload)."""
    mac = _keyed(key if type(key) is bytes else bytes(key), sender).copy()
    mac.update(body)
    return mac.digest()[:TAG_SIZE]


@functools.lru_cache(maxsize=16)
def _keyed(key: bytes, sender: int) -> hmac.HMAC:
    """HMAC-SHA256 keyed with ``key`` that has already taken ``sender``'s byte.

    Keying (hashing the padded key) costs as much as tagging a frame; a connection tags
    every frame and datagram with one of a few keys, so `frame_tag` keys once per key and
    sender and copies the keyed state (the cached state is never updated itself): the
    same tags, a third of the work. The cache holds the last few keys in use, which their
    codecs hold anyway.
    """
    return hmac.new(key, bytes((sender,)), hashlib.sha256)


def header_crc(head: bytes | bytearray) -> int:
    """The CRC-16 that closes a frame header."""
    # CRC-16/CCITT over magic..counter: catches a corrupted length at once, so the decoder
    # never waits for bytes of a frame that does not exist. Not security: the tag is.
    return binascii.crc_hqx(head, 0xFFFF)
