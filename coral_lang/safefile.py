"""Reading input files without trusting them: regular files only, and never too much.

Missions, includes, vehicle profiles and PNML nets all come from paths a user (or a
mission) names. ``Path.read_text`` happily blocks forever on a FIFO, reads
``/dev/zero`` until memory runs out, and raises ``ValueError`` on a name holding a NUL.
`read_file_bytes` and `read_text_file` refuse all of that with a short reason instead:

* the path must name a regular file (not a FIFO, device, socket or directory); it is
  opened non-blocking, so even opening a FIFO cannot hang;
* at most ``limit`` bytes are read, checked against the size on disk first and while
  reading too (``/proc`` files say they are empty and are not);
* text must be UTF-8 without NUL characters, the mark of a binary file.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from coral_lang.diagnostics import CoralError

MISSION_LIMIT = 4 * 1024 * 1024
"""Largest mission or included file read, in bytes: the largest real missions are a
few hundred KB, so 4 MB leaves room while bounding time and memory."""

PROFILE_LIMIT = 1024 * 1024
"""Largest vehicle or link profile read, in bytes (real ones are a few KB)."""

PNML_LIMIT = 64 * 1024 * 1024
"""Largest PNML file read, in bytes: far above any net coral can verify, and a bound on
the memory an (untrusted) file can make the XML tree builder take. Kept here, not in
``coral_lang.pnml``, so that checking a file's size does not load the XML machinery."""

_CHUNK = 1024 * 1024


class UnreadableFile(CoralError, ValueError):
    """A file that coral refuses to read; ``reason`` says why in a few words.

    ``kind`` sorts the reasons for callers that word them differently: ``missing``,
    ``directory``, ``special`` (FIFO, device, socket), ``large``, ``encoding``,
    ``binary`` or ``other``.
    """

    def __init__(self, path: str, reason: str, kind: str = "other") -> None:
        self.path = path
        self.reason = reason
        self.kind = kind
        super().__init__(f"{path}: {reason}")


def read_file_bytes(path: str | os.PathLike[str], limit: int) -> bytes:
    """The bytes of regular file ``path``, at most ``limit`` of them.

    Raises:
        UnreadableFile: not a regular file, larger than ``limit``, or any OS error.
    """
    name = os.fspath(path)
    if "\0" in name:
        raise UnreadableFile(repr(name), "the file name contains a NUL character")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    flags |= getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(name, flags)
    except OSError as exc:
        raise _refusal(name, exc) from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise UnreadableFile(name, "is a directory", "directory")
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile(name, f"not a regular file ({_kind(info.st_mode)})", "special")
        if info.st_size > limit:
            raise _too_large(name, limit)
        chunks: list[bytes] = []
        total = 0
        while True:
            chunk = os.read(fd, min(_CHUNK, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:  # grew, or lied about its size (/proc): stop at the cap
                raise _too_large(name, limit)
        return b"".join(chunks)
    except OSError as exc:
        raise _refusal(name, exc) from None
    finally:
        os.close(fd)


def read_text_file(path: str | os.PathLike[str], limit: int) -> str:
    """The UTF-8 text of regular file ``path`` (at most ``limit`` bytes).

    A NUL character marks a binary file (``/proc/self/environ`` is NUL-separated): such
    a file is refused, so no part of it ends up quoted in an error message.

    Raises:
        UnreadableFile: see `read_file_bytes`; also not UTF-8, or holding a NUL.
    """
    data = read_file_bytes(path, limit)
    name = os.fspath(path)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UnreadableFile(
            name, f"not UTF-8 text ({exc.reason} at byte {exc.start})", "encoding"
        ) from None
    if "\0" in text:
        raise UnreadableFile(name, "holds NUL characters: not a text file", "binary")
    return text


def is_within(path: Path, folder: Path) -> bool:
    """Whether resolved ``path`` is ``folder`` or lies below it (both already resolved)."""
    return path == folder or folder in path.parents


def _too_large(name: str, limit: int) -> UnreadableFile:
    return UnreadableFile(name, f"too large (more than {limit:,} bytes)", "large")


def _refusal(name: str, exc: OSError) -> UnreadableFile:
    if exc.errno == errno.ENOENT:
        return UnreadableFile(name, "no such file", "missing")
    if exc.errno == errno.EISDIR:
        return UnreadableFile(name, "is a directory", "directory")
    if exc.errno == errno.ELOOP:
        return UnreadableFile(name, "too many levels of symbolic links (a symlink loop?)")
    return UnreadableFile(name, exc.strerror or str(exc))


def _kind(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"
