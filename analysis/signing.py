"""Ed25519 keys and signatures for pre-mission certificates.

A certificate is a JSON file anyone can edit; a signature is what lets the runtime tell
one written by the verifier from one typed by hand. The verifier holds a private key
(``coral-check keygen``) and signs each certificate it writes; the operator's runtime
holds a set of public keys it trusts (`TrustStore`) and runs only certificates signed by
one of them. The cryptography is the ``cryptography`` package's Ed25519, not our own.

Formats:

* private key: PEM (PKCS#8, unencrypted), file mode 0600. A key readable by the group
  or others is refused: anyone who can read it can issue certificates.
* public key: one line ``coral-ed25519 <base64 of the 32 raw bytes> <comment>``, as in an
  SSH ``authorized_keys`` file; a trust store is such a file (blank lines and ``#``
  comments allowed) or a folder of ``*.pub`` files holding such lines.
* key id: the first 16 hex digits of the SHA-256 of the raw public key; a certificate
  names its signer by it, and refusals quote it.
* signed bytes: the certificate's canonical JSON (`canonical_bytes`): sorted keys, no
  whitespace, ASCII only, without the ``signature`` field itself.
* revocation: a line ``revoked <key id> <YYYY-MM-DD> <reason>`` in a trust store file,
  or in a file named ``revoked`` in a trust store folder. A certificate signed by a
  revoked key is refused even when the key is also listed as trusted: removing a key
  line is easy to undo by accident (a backup, another copy of the folder), a revocation
  line says on purpose that the key must never be accepted again, and why.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import os
import stat
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from cryptography.exceptions import InvalidSignature, UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import (
    Ed25519PrivateKey,
    Ed25519PublicKey,
)

from coral_lang.diagnostics import CoralError

__all__ = [
    "ALGORITHM",
    "KEY_TYPE",
    "SIGNING_KEY_ENV",
    "KeyFileError",
    "PublicKey",
    "Revocation",
    "SigningKey",
    "TrustStore",
    "canonical_bytes",
    "default_trust_path",
    "generate_key_files",
    "key_id",
    "load_signing_key",
    "load_trust_store",
    "sign_certificate",
    "signing_key_from_env",
]

KEY_TYPE = "coral-ed25519"
"""The first word of a public key line."""
ALGORITHM = "ed25519"
"""The ``algorithm`` of a certificate's ``signature``."""
SIGNING_KEY_ENV = "CORAL_SIGNING_KEY"
"""Environment variable naming the private key file (or holding the PEM itself, for CI
secrets) when ``--signing-key`` is not given."""
TRUSTED_KEYS_NAME = "trusted_keys"
REVOKED_NAME = "revoked"
"""The file of revocation lines in a trust store folder."""
REVOKED_WORD = "revoked"
"""The first word of a revocation line."""
KEY_ID_DIGITS = 16
RAW_KEY_BYTES = 32
MAX_KEY_FILE_BYTES = 64 * 1024
"""A key file or trust store file larger than this is not one: refused unread."""


class KeyFileError(CoralError, ValueError):
    """A key file or trust store is missing, unreadable, malformed or too open.

    The message names the file (and line) and says how to fix it: ``chmod 600`` for a
    private key others can read, ``coral-check keygen --out FILE`` for a new key pair.
    """


def key_id(raw: bytes) -> str:
    """The short name of a public key: 16 hex digits of the SHA-256 of its raw bytes."""
    return hashlib.sha256(raw).hexdigest()[:16]


def canonical_bytes(certificate: Mapping[str, object]) -> bytes:
    """What is signed: the certificate without ``signature``, as canonical JSON.

    Sorted keys and no whitespace, so the indentation of the file on disk does not
    matter; ASCII only, so no Unicode normalisation can change the bytes. Raises
    ``ValueError`` for NaN or infinities (not JSON) and ``RecursionError`` for absurd
    nesting; callers turn both into a refusal.
    """
    content = {k: v for k, v in certificate.items() if k != "signature"}
    text = json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return text.encode("ascii")


@dataclass(frozen=True)
class PublicKey:
    """A public key and where it came from (for messages)."""

    raw: bytes
    comment: str = ""
    source: str = ""

    @property
    def key_id(self) -> str:
        """See `key_id`."""
        return key_id(self.raw)

    def line(self) -> str:
        """The one-line form written to ``FILE.pub`` and read by `TrustStore`."""
        encoded = base64.b64encode(self.raw).decode("ascii")
        return f"{KEY_TYPE} {encoded} {self.comment}".rstrip()

    def verifies(self, signature: bytes, message: bytes) -> bool:
        """Whether ``signature`` is this key's signature of ``message``."""
        try:
            Ed25519PublicKey.from_public_bytes(self.raw).verify(signature, message)
        except InvalidSignature:
            return False
        return True


@dataclass(frozen=True)
class SigningKey:
    """A private key, able to sign certificates."""

    private: Ed25519PrivateKey
    comment: str = ""

    @classmethod
    def generate(cls, comment: str = "") -> SigningKey:
        """A fresh key (``coral-run --verify`` uses one that never leaves the process)."""
        return cls(Ed25519PrivateKey.generate(), comment)

    @property
    def public(self) -> PublicKey:
        """The matching public key."""
        raw = self.private.public_key().public_bytes(
            serialization.Encoding.Raw, serialization.PublicFormat.Raw
        )
        return PublicKey(raw, self.comment)

    def sign(self, message: bytes) -> bytes:
        """The 64-byte Ed25519 signature of ``message``."""
        return self.private.sign(message)


def sign_certificate(certificate: Mapping[str, object], key: SigningKey) -> dict[str, object]:
    """``certificate`` with a ``signature`` over its `canonical_bytes` by ``key``."""
    signature = key.sign(canonical_bytes(certificate))
    signed = {k: v for k, v in certificate.items() if k != "signature"}
    signed["signature"] = {
        "algorithm": ALGORITHM,
        "key_id": key.public.key_id,
        "value": base64.b64encode(signature).decode("ascii"),
    }
    return signed


# -- key files ----------------------------------------------------------------------------


def generate_key_files(out: str | Path, comment: str) -> PublicKey:
    """Write a new private key to ``out`` (mode 0600) and its public key to ``out.pub``.

    Refuses to overwrite either file: replacing a key silently would orphan every
    trust store that lists the old one, or lose the only copy of a private key.

    Raises:
        KeyFileError: a file exists already, the folder is missing, or the comment holds a
            line break (it would split the public key line).
    """
    out = Path(out)
    pub = public_path(out)
    if "\n" in comment or "\r" in comment:
        raise KeyFileError("a key comment must be one line")
    for path in (out, pub):
        if path.exists():
            raise KeyFileError(
                f"{path}: exists already; not overwriting a key (choose another --out)"
            )
    if not out.resolve().parent.is_dir():
        raise KeyFileError(f"{out}: no such folder")
    key = SigningKey.generate(comment)
    pem = key.private.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    try:
        # O_EXCL: created here, never an existing file; 0600 from the start, never
        # briefly readable by others.
        fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as handle:
            handle.write(pem)
        with pub.open("x", encoding="ascii") as handle:
            handle.write(key.public.line() + "\n")
    except OSError as exc:
        raise KeyFileError(f"{exc.filename or out}: cannot write key ({exc.strerror})") from None
    return PublicKey(key.public.raw, comment, str(pub))


def public_path(private: Path) -> Path:
    """``FILE.pub`` beside the private key ``FILE``."""
    return private.with_name(private.name + ".pub")


def load_signing_key(path: str | Path) -> SigningKey:
    """The private key in the PEM file ``path``.

    Raises:
        KeyFileError: missing or unreadable, readable by the group or others (the message
            says ``chmod 600``), or not an Ed25519 private key.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise KeyFileError(
            f"{path}: no such signing key; create one with 'coral-check keygen --out {path}'"
        ) from None
    except OSError as exc:
        raise KeyFileError(f"{path}: cannot read signing key ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise KeyFileError(f"{path}: not a signing key file")
    if os.name == "posix" and mode & 0o077:
        raise KeyFileError(
            f"{path}: signing key is accessible by group or others (mode "
            f"{stat.S_IMODE(mode):04o}): anyone who can read it can issue certificates; "
            f"fix with 'chmod 600 {path}'"
        )
    return _parse_private(_read_limited(path, "signing key"), str(path))


def signing_key_from_env(environ: Mapping[str, str]) -> SigningKey | None:
    """The key `SIGNING_KEY_ENV` names (a file, checked as `load_signing_key` does) or
    holds (PEM text, as CI secrets are given); None when it is unset or empty."""
    value = environ.get(SIGNING_KEY_ENV, "")
    if not value:
        return None
    if value.lstrip().startswith("-----BEGIN"):
        return _parse_private(value.encode("utf-8"), f"${SIGNING_KEY_ENV}")
    return load_signing_key(value)


def _parse_private(data: bytes, source: str) -> SigningKey:
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm) as exc:
        reason = "it is encrypted" if isinstance(exc, TypeError) else "not a PEM private key"
        raise KeyFileError(
            f"{source}: not a usable signing key ({reason}); create one with "
            "'coral-check keygen --out FILE'"
        ) from None
    if not isinstance(key, Ed25519PrivateKey):
        raise KeyFileError(f"{source}: not an Ed25519 key; create one with 'coral-check keygen'")
    return SigningKey(key)


def _read_limited(path: Path, what: str) -> bytes:
    from coral_lang.safefile import UnreadableFile, read_file_bytes

    try:  # a regular file of bounded size: never a FIFO or /dev/zero
        return read_file_bytes(path, MAX_KEY_FILE_BYTES)
    except UnreadableFile as exc:
        if exc.kind == "large":
            raise KeyFileError(
                f"{path}: too large for a {what} (over {MAX_KEY_FILE_BYTES} bytes)"
            ) from None
        raise KeyFileError(f"{path}: cannot read {what} ({exc.reason})") from None


# -- trust ----------------------------------------------------------------------------------


def parse_public_key(line: str, source: str) -> PublicKey:
    """One ``coral-ed25519 <base64> [comment]`` line; ``source`` (``FILE:LINE``) names it
    in errors."""
    parts = line.strip().split(maxsplit=2)
    if len(parts) < 2 or parts[0] != KEY_TYPE:
        raise KeyFileError(
            f"{source}: not a public key line (expected '{KEY_TYPE} BASE64 COMMENT')"
        )
    try:
        raw = base64.b64decode(parts[1], validate=True)
    except (binascii.Error, ValueError):
        raise KeyFileError(f"{source}: the key is not valid base64") from None
    if len(raw) != RAW_KEY_BYTES:
        raise KeyFileError(f"{source}: an Ed25519 key has {RAW_KEY_BYTES} bytes, not {len(raw)}")
    return PublicKey(raw, parts[2] if len(parts) > 2 else "", source)


@dataclass(frozen=True)
class Revocation:
    """A key that must never be accepted again: when and why (from ``source``)."""

    key_id: str
    date: str
    reason: str
    source: str = ""

    def line(self) -> str:
        """The line form, as written in a trust store."""
        return f"{REVOKED_WORD} {self.key_id} {self.date} {self.reason}"


def parse_revocation(line: str, source: str) -> Revocation:
    """One ``revoked <key id> <YYYY-MM-DD> <reason>`` line; ``source`` names it in errors."""
    import datetime as dt

    parts = line.strip().split(maxsplit=3)
    usage = f"expected '{REVOKED_WORD} KEY_ID YYYY-MM-DD REASON'"
    if len(parts) < 4 or parts[0] != REVOKED_WORD:
        raise KeyFileError(f"{source}: not a revocation line ({usage})")
    kid, date, reason = parts[1], parts[2], parts[3].strip()
    if len(kid) != KEY_ID_DIGITS or any(c not in "0123456789abcdef" for c in kid):
        raise KeyFileError(
            f"{source}: '{kid[:40]}' is not a key id ({KEY_ID_DIGITS} lowercase hex digits, "
            "as 'coral-check keygen' prints); " + usage
        )
    try:
        dt.date.fromisoformat(date)
    except ValueError:
        raise KeyFileError(f"{source}: '{date[:40]}' is not a date; {usage}") from None
    return Revocation(kid, date, reason, source)


@dataclass(frozen=True)
class TrustStore:
    """The public keys whose certificates the runtime accepts, by key id, and the keys
    it refuses whatever else it lists (``revoked``).

    ``sources`` lists the files read (for messages: "trusted keys: none (from X)").
    """

    keys: Mapping[str, PublicKey] = field(default_factory=dict)
    sources: tuple[str, ...] = ()
    revoked: Mapping[str, Revocation] = field(default_factory=dict)

    @classmethod
    def of(
        cls, keys: Iterable[PublicKey], source: str = "", revoked: Iterable[Revocation] = ()
    ) -> TrustStore:
        """A store holding ``keys`` (tests, and the in-process key of ``--verify``)."""
        return cls(
            {k.key_id: k for k in keys},
            (source,) if source else (),
            {r.key_id: r for r in revoked},
        )

    def get(self, wanted: str) -> PublicKey | None:
        """The trusted key with id ``wanted``, if any (revoked or not: see `revocation`)."""
        return self.keys.get(wanted)

    def revocation(self, wanted: str) -> Revocation | None:
        """Why key ``wanted`` is revoked, if it is."""
        return self.revoked.get(wanted)

    def describe(self) -> str:
        """Where the keys came from, for refusals."""
        where = ", ".join(self.sources) if self.sources else "no trust store"
        revoked = f", {len(self.revoked)} revoked" if self.revoked else ""
        return f"{len(self.keys)} trusted key(s){revoked} from {where}"


def load_trust_store(path: str | Path) -> TrustStore:
    """The keys in ``path``: a file of public key lines, or a folder of ``*.pub`` files,
    with the revocation lines of that file (or of the folder's ``revoked`` file and its
    ``*.pub`` files).

    Raises:
        KeyFileError: the path is missing, a file cannot be read, or a line is neither a
            public key nor a revocation (named by file and line number).
    """
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.glob("*.pub") if p.is_file())
        revoked_file = path / REVOKED_NAME
        if revoked_file.exists():
            files.append(revoked_file)  # read (and refused if unreadable) like the rest
    elif path.is_file():
        files = [path]
    else:
        raise KeyFileError(f"{path}: no such trusted keys file or folder")
    keys: dict[str, PublicKey] = {}
    revoked: dict[str, Revocation] = {}
    for file in files:
        try:
            text = _read_limited(file, "trusted keys file").decode("utf-8")
        except UnicodeDecodeError:
            raise KeyFileError(f"{file}: trusted keys file is not UTF-8 text") from None
        for number, line in enumerate(text.splitlines(), start=1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            where = f"{file}:{number}"
            if line.split(maxsplit=1)[0] == REVOKED_WORD:
                revocation = parse_revocation(line, where)
                revoked.setdefault(revocation.key_id, revocation)  # the first one says why
            elif file.name == REVOKED_NAME and path.is_dir():
                raise KeyFileError(
                    f"{where}: a '{REVOKED_NAME}' file holds only revocation lines "
                    f"('{REVOKED_WORD} KEY_ID YYYY-MM-DD REASON')"
                )
            else:
                key = parse_public_key(line, where)
                keys[key.key_id] = key
    return TrustStore(keys, (str(path),), revoked)


def default_trust_path(environ: Mapping[str, str]) -> Path:
    """``$XDG_CONFIG_HOME/coral/trusted_keys`` (``~/.config/coral/trusted_keys``)."""
    config = environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(config) / "coral" / TRUSTED_KEYS_NAME


def resolve_trust_store(path: str | Path | None, environ: Mapping[str, str]) -> TrustStore:
    """The store ``--trusted-keys PATH`` names, else the default one if it exists, else
    an empty store (every certificate is then refused as from an unknown signer)."""
    if path is not None:
        return load_trust_store(path)
    default = default_trust_path(environ)
    if default.exists():
        return load_trust_store(default)
    return TrustStore(sources=(f"{default} (absent)",))
