"""Shared helpers of the runtime tests: compile, verify and approve a mission."""

from __future__ import annotations

from pathlib import Path

from analysis.certificate import CertificateCheck, check_certificate, make_certificate
from analysis.certificate import write_certificate as write_cert
from analysis.verify import verify
from coral_lang.compiler import compile_source
from coral_lang.net import Net
from tests.conftest import EXAMPLES

POOL_MISSION = EXAMPLES / "pool_mission" / "pool_mission.coral"


def compile_text(text: str) -> Net:
    """Compile a mission given as text; any error fails the test."""
    return compile_source(text, "test.coral").raise_for_errors()


def approve(net: Net, directory: Path) -> CertificateCheck:
    """Verify ``net``, write its certificate into ``directory`` and check it."""
    path = directory / f"{net.name}.certificate.json"
    write_cert(make_certificate(verify(net)), path)
    return check_certificate(net, path)
