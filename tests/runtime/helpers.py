"""Shared helpers of the runtime tests: compile, verify and approve a mission."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from analysis.certificate import CertificateCheck, check_certificate, make_certificate
from analysis.certificate import write_certificate as write_cert
from analysis.signing import sign_certificate
from analysis.verify import verify
from coral_lang.compiler import compile_source
from coral_lang.mission import profile_content
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile, bundled_profile_path, load_bundled_profile
from tests.conftest import EXAMPLES, session_signing_key

POOL_MISSION = EXAMPLES / "pool_mission" / "pool_mission.coral"
BIN = Path(sys.executable).parent
"""Where this environment's ``coral-run``, ``coral-vehicle`` and ``romeo-sim`` are."""


def compile_text(text: str) -> Net:
    """Compile a mission given as text; any error fails the test."""
    return compile_source(text, "test.coral").raise_for_errors()


def approve(net: Net, directory: Path, profile: VehicleProfile | None = None) -> CertificateCheck:
    """Verify ``net``, write its certificate into ``directory`` and check it.

    The certificate covers ``profile`` (default: the net's bundled vehicle profile, if
    there is one) and is signed with the session's test key, and checked against a
    store trusting that key, as a run's gate requires (pass ``--trusted-keys
    session_signing_key().public`` to a ``coral-run`` given this certificate)."""
    path = directory / f"{net.name}.certificate.json"
    if profile is None and net.vehicle and bundled_profile_path(net.vehicle) is not None:
        profile = load_bundled_profile(net.vehicle)
    content = profile_content(net, profile)
    test_key = session_signing_key()
    certificate = make_certificate(verify(net), profile_content=content)
    write_cert(sign_certificate(certificate, test_key.key), path)
    return check_certificate(net, path, profile_content=content, trusted=test_key.trusted)


def sign_file(path: Path) -> Path:
    """Sign the certificate at ``path`` in place with the session's test key, as a
    verifier would sign what ``coral-run --verify`` wrote unsigned; returns the public key
    file to give ``coral-run --trusted-keys``."""
    test_key = session_signing_key()
    write_cert(sign_certificate(json.loads(path.read_text()), test_key.key), path)
    return test_key.public


def kill_9_at(argv: list[str], line: str, *, settle: float, timeout: float = 120) -> list[str]:
    """Run ``argv``, read its output until a line matches the regex ``line`` (or
    ``timeout`` passes), wait ``settle`` seconds, then ``kill -9`` it.

    Returns:
        The output lines read, for the caller to check where the kill fell.
    """
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert process.stdout is not None
    seen = []
    deadline = time.monotonic() + timeout
    for text in process.stdout:
        seen.append(text)
        if re.match(line, text) or time.monotonic() > deadline:
            break
    time.sleep(settle)
    process.send_signal(signal.SIGKILL)
    process.wait()
    return seen


def write_psk(directory: Path) -> Path:
    """A fresh pre-shared key file in ``directory``, mode 0600 (others may not read it)."""
    key = directory / "psk.hex"
    key.write_text(os.urandom(32).hex())
    key.chmod(0o600)
    return key


def start_server(argv: list[str], listening: str = r"\S+:\d+") -> tuple[subprocess.Popen[str], str]:
    """Start a vehicle server (``coral-vehicle serve``, ``romeo-sim serve``) and wait for
    its ``listening on HOST:PORT`` line; the process and the address it names.

    The first stdout line must match ``listening on (listening)``, else the server is
    killed and the test fails with what it printed.
    """
    server = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert server.stdout is not None
    line = server.stdout.readline()
    match = re.match(rf"listening on ({listening})", line)
    if not match:
        server.kill()
        raise AssertionError(f"{argv[0]} did not start: {line!r} {server.communicate()[1]}")
    return server, match.group(1)
