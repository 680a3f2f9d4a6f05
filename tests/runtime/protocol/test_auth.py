"""Frame tags: `frame_tag` keys HMAC-SHA256 once per key and sender and copies the keyed
state (issue 18); the tags must be exactly HMAC-SHA256 over the sender's byte and the
body, truncated, whatever the key, its type, and how many keys have been used since."""

from __future__ import annotations

import hashlib
import hmac

from hypothesis import given
from hypothesis import strategies as st

from runtime.protocol.auth import frame_tag
from runtime.protocol.wire import TAG_SIZE, Role


def plain_tag(key: bytes, sender: int, body: bytes) -> bytes:
    return hmac.new(key, bytes((sender,)) + body, hashlib.sha256).digest()[:TAG_SIZE]


@given(
    key=st.binary(min_size=16, max_size=100),  # longer than SHA-256's block, too
    sender=st.sampled_from(list(Role)),
    body=st.binary(max_size=300),
)
def test_tag_is_hmac_sha256_of_sender_and_body(key: bytes, sender: Role, body: bytes) -> None:
    expected = plain_tag(key, sender, body)
    assert frame_tag(key, sender, body) == expected
    mutable_key = bytearray(key)  # not the declared type, but hmac took it, so this does
    assert frame_tag(mutable_key, sender, bytearray(body)) == expected  # type: ignore[arg-type]
    assert frame_tag(key, sender, body) == expected  # the keyed state was not used up


def test_tags_stay_right_with_more_keys_than_are_kept() -> None:
    keys = [bytes([i]) * 32 for i in range(40)]
    for _ in range(2):
        for key in keys:
            for sender in Role:
                assert frame_tag(key, sender, b"frame") == plain_tag(key, sender, b"frame")
    assert frame_tag(keys[0], Role.VEHICLE, b"x") != frame_tag(keys[0], Role.CONTROLLER, b"x")
