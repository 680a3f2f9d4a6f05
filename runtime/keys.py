"""The pre-shared key, read the same way by ``coral-run``, ``coral-vehicle`` and ``romeo-sim``.

The key is hex text (white space ignored), from a file (``--key-file``, the safe way: it
stays out of the process list and the shell history) or the command line (``--key-hex``).

Two refusals guard against keys that protect nothing:

* a key file the group or others may read or write (any of the mode bits 0o077): anyone
  who can read the key can command the vehicle, anyone who can write it can swap it. The
  same rule ``analysis.signing`` applies to the verifier's signing key; the fix is
  ``chmod 600 FILE``. Checked on POSIX only (Windows has no such bits).
* a degenerate key, all of whose bytes are equal (``00`` x 16, ``ff`` x 32): the mark of
  a placeholder, never of a random key (the chance that 16 random bytes are all equal is
  2**-120).

``--key-hex`` is kept (tests and one-off runs need no file), but every command's help
says to prefer ``--key-file``: a command line is visible to every user of the machine
(``ps``, ``/proc/PID/cmdline``) and lands in the shell history.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from coral_lang.diagnostics import CoralError
from coral_lang.safefile import UnreadableFile, read_text_file
from runtime.protocol import MIN_KEY_SIZE

__all__ = [
    "KEY_HEX_HELP",
    "KEY_HINT",
    "TRUSTED_KEYS_HELP",
    "KeyProblem",
    "load_psk",
    "write_key_file",
]

KEY_FILE_LIMIT = 64 * 1024
"""Largest key file read, in bytes (a key is 64 hex digits; room for white space)."""

KEY_HINT = (
    f"give --key-file FILE or --key-hex HEX with at least {MIN_KEY_SIZE} random bytes; make "
    "a key file readable by you alone with: (umask 077; python3 -c 'import secrets; "
    "print(secrets.token_hex(32))' > psk.hex)"
)

KEY_HEX_HELP = (
    "the pre-shared key as hex on the command line; other users can see it in the process "
    "list: prefer --key-file"
)
"""The help of ``--key-hex``, the same on every command that takes a key."""

TRUSTED_KEYS_HELP = (
    "public keys whose signed certificates are accepted: a file of 'coral-ed25519 ...' "
    "lines or a folder of .pub files (default ~/.config/coral/trusted_keys if it exists); "
    "revoke a key with a line 'revoked KEY_ID YYYY-MM-DD REASON' (in the file, or in a "
    "'revoked' file in the folder)"
)
"""The help of ``--trusted-keys``, the same on ``coral-run`` and ``coral-run fuzz``."""


class KeyProblem(CoralError, ValueError):
    """The pre-shared key is missing, unreadable, too open, not hex, too short or degenerate."""


def load_psk(key_file: Path | None, key_hex: str | None, *, who: str = "this command") -> bytes:
    """The key from ``key_file`` or, failing that, ``key_hex``.

    Raises:
        KeyProblem: no key given; an unreadable key file, or one the group or others may
            read or write (the message says ``chmod 600 FILE``); not hex; shorter than
            `MIN_KEY_SIZE` bytes; or all bytes equal. The message says how to make a key.
    """
    if key_file is not None:
        _check_private(key_file)
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
    if len(set(key)) == 1:
        raise KeyProblem(
            f"{source} is degenerate (all {len(key)} bytes are {key[0]:02x}), not a random "
            f"key: {KEY_HINT}"
        )
    return key


def _check_private(path: Path) -> None:
    """Refuse a key file the group or others may read or write.

    The mode is read from the file the path leads to (a symlink's own mode means
    nothing). A missing or special file is left to the reader, which names the problem.
    """
    if os.name != "posix":
        return
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return
    if stat.S_ISREG(mode) and mode & 0o077:
        raise KeyProblem(
            f"the key file {path} is accessible by group or others (mode "
            f"{stat.S_IMODE(mode):04o}): anyone who can read it can command the vehicle; "
            f"fix with 'chmod 600 {path}'"
        )


def write_key_file(path: Path, key: bytes) -> None:
    """Write ``key`` as hex to the new file ``path``, mode 0600 from the start.

    For tests, scripts and examples that make a key file: created with ``O_EXCL`` (never
    an existing file) and never briefly readable by others, so `load_psk` accepts it.

    Raises:
        OSError: the file exists or cannot be written.
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as handle:
        handle.write(key.hex() + "\n")
