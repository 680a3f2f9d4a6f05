"""The pre-run gate: compile a mission and accept it only with a passing certificate.

``coral-run`` calls `approve_mission` before anything talks to the vehicle. With
``issue=True`` a mission without a certificate is verified first, and a certificate is
written only if every property was proven; the run then uses that certificate.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from analysis.certificate import (
    CertificateCheck,
    CertificateError,
    check_certificate,
    make_certificate,
    write_certificate,
)
from coral_lang.compiler import compile_mission
from coral_lang.net import Net

__all__ = ["ApprovedMission", "approve_mission", "default_certificate_path"]


@dataclass(frozen=True)
class ApprovedMission:
    """A compiled mission and the certificate that lets it run."""

    path: Path
    net: Net
    approval: CertificateCheck
    issued_now: bool


def default_certificate_path(mission: Path) -> Path:
    """``MISSION.certificate.json`` beside the mission file."""
    return mission.with_name(mission.stem + ".certificate.json")


def approve_mission(
    mission: str | Path, certificate: str | Path | None = None, *, issue: bool = False
) -> ApprovedMission:
    """Compile ``mission`` and check its certificate (verifying first if ``issue``).

    Raises:
        coral_lang.diagnostics.CompileError: the mission does not compile.
        CertificateError: no passing certificate for this net (and ``issue`` is False, or
            verification did not prove every property: the message lists what failed).
    """
    path = Path(mission)
    net = compile_mission(path)
    cert_path = Path(certificate) if certificate is not None else default_certificate_path(path)
    try:
        return ApprovedMission(path, net, check_certificate(net, cert_path), False)
    except CertificateError:
        if not issue:
            raise
    from analysis.verify import verify  # only when verifying: it loads the solvers

    report = verify(net)
    certificate_data = make_certificate(report)
    if certificate_data["verdict"] != "proven":
        failing = ", ".join(
            f"{p.key} {p.verdict.value}"
            for p in report.properties
            if p.required and p.verdict.value != "proven"
        )
        raise CertificateError(
            f"{path}: verification did not pass ({failing}); run 'coral-check verify {path}' "
            "for the evidence, fix the mission, and run again"
        )
    write_certificate(certificate_data, cert_path)
    return ApprovedMission(path, net, check_certificate(net, cert_path), True)
