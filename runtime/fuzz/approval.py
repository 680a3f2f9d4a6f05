"""The gate of fuzzing: a certified mission keeps its certificate; any other is fuzzed
only with ``--unverified``, under an approval (`UNVERIFIED`) that names no file, exists in
this process alone and is only ever handed to a simulated run.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from analysis.certificate import CertificateCheck, CertificateError
from coral_lang.mission import Mission

if TYPE_CHECKING:
    from analysis.signing import TrustStore
    from coral_lang.net import Net

__all__ = ["UNVERIFIED", "approval_for", "unverified_approval"]

UNVERIFIED = "unverified (fuzz only)"
"""The ``path`` of the approval `--unverified` builds: it names no file, so it can never
be mistaken for a certificate, and it is only ever handed to a simulated run."""


def approval_for(
    mission: Mission,
    certificate: Path | None,
    *,
    unverified: bool,
    trusted: TrustStore | None = None,
) -> tuple[CertificateCheck, str | None]:
    """The approval to fuzz with, and the reason it is unverified (None if verified).

    The certificate is checked as a run checks it: against the net, the vehicle profile
    the mission was compiled with, and the trusted keys (``trusted``, default the
    run's default trust store), so it must be signed.

    Raises:
        CertificateError: no passing certificate and not ``unverified``.
    """
    from runtime.gate import check_mission_certificate

    net = mission.net
    try:
        return check_mission_certificate(mission, certificate, trusted=trusted), None
    except CertificateError as exc:
        if not unverified:
            raise CertificateError(
                f"{exc}; or, to fuzz it as it is against the simulator, add --unverified"
            ) from None
        return unverified_approval(net), str(exc)


def unverified_approval(net: Net) -> CertificateCheck:
    """The approval ``--unverified`` runs ``net`` under: named `UNVERIFIED`, no file."""
    from analysis.certificate import tool_version

    return CertificateCheck(
        path=UNVERIFIED, net_digest=net.digest(), issued="", tool_version=tool_version()
    )
