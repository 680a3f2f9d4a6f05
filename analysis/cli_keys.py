"""``coral-check keygen`` and ``coral-check resign``: the keys that sign certificates.

Kept apart from the checking commands: they never compile a mission, and only they
load the cryptography package (slow to import) at the top of their work.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.cli_check import SIGNING_KEY_ENV
from analysis.cli_options import PROG
from coral_lang.cliframe import EXIT_OK, EXIT_USAGE, print_error, writable_output

if TYPE_CHECKING:
    from analysis.signing import SigningKey

__all__ = [
    "KEYGEN_HELP",
    "RESIGN_HELP",
    "configure_keygen",
    "configure_resign",
    "run_keygen",
    "run_resign",
]

KEYGEN_HELP = (
    "Create an Ed25519 key pair for signing certificates: the private key in KEY (PEM, "
    "mode 0600: keep it with the verifier) and the public key in KEY.pub (one line: give "
    "it to the operators, whose coral-run trusts it with --trusted-keys). Prints the key "
    "id. Never overwrites a file."
)
KEYGEN_EPILOG = "exit codes: 0 written, 2 bad usage or a file that exists or cannot be written"
RESIGN_HELP = (
    "Sign a certificate with another key, to rotate keys without verifying again: the "
    "certificate's present signature must be by a key the trust store trusts and does not "
    "revoke, and must match its content; only the signature changes, so a run still "
    "checks everything else (net, profile, expiry, checker revision). A certificate whose "
    "signer is revoked must be verified again (coral-check verify ... --certificate FILE "
    "--signing-key KEY)."
)
RESIGN_EPILOG = (
    "exit codes: 0 re-signed, 2 bad usage, an unusable key or trust store, or a "
    "certificate that cannot be re-signed (the message says why)"
)


def configure_keygen(parser: argparse.ArgumentParser) -> None:
    """The options of ``coral-check keygen``."""
    parser.add_argument("--out", required=True, metavar="KEY", help="private key file to create")
    parser.add_argument(
        "--comment",
        metavar="TEXT",
        help="written after the public key, to tell keys apart (default USER@HOST)",
    )


def configure_resign(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check resign``."""
    parser.add_argument("certificate", metavar="CERT", help="the certificate to re-sign")
    parser.add_argument(
        "--signing-key",
        metavar="KEY",
        help=f"the new private key (default: ${SIGNING_KEY_ENV}, a key file or the PEM itself)",
    )
    parser.add_argument(
        "--trusted-keys",
        metavar="PATH",
        help="trust store to check the present signature against: a file of public key "
        "lines or a folder of .pub files, with any revocations (default: "
        "$XDG_CONFIG_HOME/coral/trusted_keys)",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=writable_output,
        metavar="OUT",
        help="write the re-signed certificate here (default: CERT)",
    )


def run_keygen(args: argparse.Namespace) -> int:
    """Write a key pair; the exit code."""
    import getpass
    import socket

    from analysis.signing import KeyFileError, generate_key_files, public_path

    comment = args.comment
    if comment is None:
        try:
            comment = f"{getpass.getuser()}@{socket.gethostname()}"
        except (OSError, KeyError):
            comment = "coral"
    try:
        public = generate_key_files(args.out, comment)
    except KeyFileError as exc:
        print_error(PROG, str(exc))
        return EXIT_USAGE
    print(f"key id: {public.key_id}")
    print(f"private key: {args.out} (keep it secret; the verifier signs with it)")
    print(f"public key: {public_path(Path(args.out))} (give it to operators: --trusted-keys)")
    return EXIT_OK


def run_resign(args: argparse.Namespace) -> int:
    """Re-sign a certificate with a new key; the exit code."""
    from analysis.certificate import CertificateError, resign_certificate, write_certificate
    from analysis.signing import (
        KeyFileError,
        load_signing_key,
        resolve_trust_store,
        signing_key_from_env,
    )

    output = Path(args.output or args.certificate)
    key: SigningKey | None
    try:
        if args.signing_key is not None:
            key = load_signing_key(args.signing_key)
        else:
            key = signing_key_from_env(os.environ)
        trusted = resolve_trust_store(args.trusted_keys, os.environ)
    except KeyFileError as exc:
        print_error(PROG, str(exc))
        return EXIT_USAGE
    if key is None:
        print_error(PROG, f"no signing key: give --signing-key KEY (or ${SIGNING_KEY_ENV})")
        return EXIT_USAGE
    try:
        certificate = resign_certificate(args.certificate, key, trusted)
    except CertificateError as exc:
        print_error(PROG, f"not re-signed: {exc}")
        return EXIT_USAGE
    old = _certificate_signer(args.certificate)
    partial = output.with_name(f".{output.name}.{os.getpid()}.tmp")
    try:  # a new file renamed over the old: never a half-written certificate
        write_certificate(certificate, partial)
        partial.replace(output)
    except OSError as exc:
        partial.unlink(missing_ok=True)
        print_error(PROG, f"cannot write '{output}': {exc.strerror}")
        return EXIT_USAGE
    print(
        f"{PROG}: {output}: re-signed by key {key.public.key_id} (was {old}); once "
        "every certificate is re-signed, revoke the old key in the trust stores",
        file=sys.stderr,
    )
    if trusted.get(key.public.key_id) is None:
        print(
            f"{PROG}: note: key {key.public.key_id} is not in the trust store "
            f"({trusted.describe()}): add its .pub line there before runs use {output}",
            file=sys.stderr,
        )
    return EXIT_OK


def _certificate_signer(path: str) -> str:
    """The key id a certificate file names as its signer ("unknown" if unreadable)."""
    from analysis.certificate import CertificateError, read_certificate

    try:
        signature = read_certificate(Path(path)).get("signature")
    except CertificateError:
        return "unknown"
    kid = signature.get("key_id") if isinstance(signature, dict) else None
    return kid if isinstance(kid, str) else "unknown"
