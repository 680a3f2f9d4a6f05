"""The pre-shared key, read the same way by ``coral-run`` and ``romeo-sim serve``.

The key is hex text (white space ignored), from a file (``--key-file``, the safe way: it
stays out of the process list and the shell history) or the command line (``--key-hex``).
"""

from __future__ import annotations

from pathlib import Path

from coral_lang.diagnostics import CoralError
from coral_lang.safefile import UnreadableFile, read_text_file
from runtime.protocol import MIN_KEY_SIZE

__all__ = ["KEY_HINT", "TRUSTED_KEYS_HELP", "KeyProblem", "load_psk"]

KEY_FILE_LIMIT = 64 * 1024
"""Largest key file read, in bytes (a key is 64 hex digits; room for white space)."""

KEY_HINT = (
    f"give --key-file FILE or --key-hex HEX with at least {MIN_KEY_SIZE} bytes "
    "(32 random bytes recommended: python -c 'import secrets; print(secrets.token_hex(32))')"
)


TRUSTED_KEYS_HELP = (
    "public keys whose signed certificates are accepted: a file of 'coral-ed25519 ...' "
    "lines or a folder of .pub files (default ~/.config/coral/trusted_keys if it exists)"
)
"""The help of ``--trusted-keys``, the same on ``coral-run`` and ``coral-run fuzz``."""


class KeyProblem(CoralError, ValueError):
    """The pre-shared key is missing, unreadable, not hex or too short."""


def load_psk(key_file: Path | None, key_hex: str | None, *, who: str = "this command") -> bytes:
    """The key from ``key_file`` or, failing that, ``key_hex``.

    Raises:
        KeyProblem: no key given, unreadable file, not hex, or shorter than
            `MIN_KEY_SIZE` bytes; the message says how to make one.
    """
    if key_file is not None:
        try:  # a regular file of bounded size: never a FIFO or /dev/zero
            text = read_text_file(key_file, KEY_FILE_LIMIT)
        except UnreadableFile as exc:
            raise KeyProblem(f"cannot read the key file {key_file}: {exc.reason}") from None
        source = f"the key file {key_file}"
    elif key_hex is not None:
        text, source = key_hex, "--key-hex"
    else:
        raise KeyProblem(f"{who} needs a pre-shared key: {KEY_HINT}")
    try:
        key = bytes.fromhex("".join(text.split()))
    except ValueError:
        raise KeyProblem(f"{source} is not hex: {KEY_HINT}") from None
    if len(key) < MIN_KEY_SIZE:
        raise KeyProblem(f"{source} holds {len(key)} bytes, too short: {KEY_HINT}")
    return key
