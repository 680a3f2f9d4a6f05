"""The pre-run gate: compile a mission and accept it only with a passing certificate.

``coral-run`` calls `approve_mission` before anything talks to the vehicle. With
``issue=True`` a mission without a certificate is verified first, and a certificate is
written only if every property was proven; the run then uses that certificate.

The mission is compiled against the vehicle profiles the user gave (``--profile``)
before the bundled ones, and the certificate must cover the profile it compiled
against: one issued for an older version of the profile, or before certificates
recorded profiles at all, is refused (`analysis.certificate.check_certificate`).

A run accepts only a certificate signed by a key in its trust store (``trusted``:
``--trusted-keys``, else ``~/.config/coral/trusted_keys``; `analysis.signing`) that the
store does not revoke, written by a checker revision without a known soundness bug in
the methods behind its proofs (`analysis.soundness`). With
``issue=True`` (``coral-run --verify``) the gate has just verified the net itself, in
this process: it signs the certificate it made with a key generated for this call alone
and checks it, in memory, against a store holding only that key, so the run goes through
exactly the checks a signed certificate does. That key is never written anywhere; the
certificate written to disk is unsigned, so a later run with it is refused unless it
verifies again (``--verify``) or the certificate is signed by a trusted verifier.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.certificate import (
    CertificateCheck,
    CertificateError,
    check_certificate,
    check_certificate_data,
    make_certificate,
    write_certificate,
)
from analysis.signing import SigningKey, TrustStore, resolve_trust_store, sign_certificate
from coral_lang.diagnostics import CompileError
from coral_lang.mission import Mission, load_mission
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile

if TYPE_CHECKING:
    from analysis.report import Report

__all__ = [
    "ApprovedMission",
    "approve_mission",
    "check_mission_certificate",
    "default_certificate_path",
    "trust_store",
]


@dataclass(frozen=True)
class ApprovedMission:
    """A compiled mission and the certificate that lets it run."""

    mission: Mission
    approval: CertificateCheck
    issued_now: bool

    @property
    def path(self) -> Path:
        """The mission file (an approved mission always comes from one)."""
        if self.mission.path is None:
            raise ValueError("an approved mission is compiled from a file")
        return self.mission.path

    @property
    def net(self) -> Net:
        """The compiled net the certificate is for."""
        return self.mission.net


def default_certificate_path(mission: Path) -> Path:
    """``MISSION.certificate.json`` beside the mission file."""
    return mission.with_name(mission.stem + ".certificate.json")


def trust_store(path: str | Path | None = None) -> TrustStore:
    """The keys a run trusts: those in ``path`` (``--trusted-keys``), else in the
    default trust store if it exists, else none.

    Raises:
        analysis.signing.KeyFileError: ``path`` (or the default store) is missing or
            holds a line that is not a public key.
    """
    return resolve_trust_store(path, os.environ)


def check_mission_certificate(
    mission: Mission,
    certificate: str | Path | None = None,
    *,
    trusted: TrustStore | None = None,
) -> CertificateCheck:
    """Check ``mission``'s certificate against its net, its vehicle profile and the
    trusted keys.

    ``certificate`` defaults to `default_certificate_path` beside the mission file. The
    profile content is always passed, so a certificate that does not cover the profile
    as it is now is refused; and a trust store always is (``trusted``, default
    `trust_store`), so an unsigned or forged certificate is refused. This is the check
    every run (and fuzzing) must use.

    Raises:
        CertificateError: as `analysis.certificate.check_certificate`, or no
            ``certificate`` given for a mission compiled from text.
        analysis.signing.KeyFileError: the default trust store cannot be read.
    """
    if certificate is None:
        if mission.path is None:
            raise CertificateError("a mission compiled from text needs a certificate path")
        certificate = default_certificate_path(mission.path)
    return check_certificate(
        mission.net,
        certificate,
        profile_content=mission.profile_content(),
        trusted=trust_store() if trusted is None else trusted,
        mission=mission.path,
    )


def approve_mission(
    mission: str | Path,
    certificate: str | Path | None = None,
    *,
    issue: bool = False,
    profiles: Sequence[VehicleProfile] = (),
    trusted: TrustStore | None = None,
    include_path: Sequence[str | Path] = (),
) -> ApprovedMission:
    """Compile ``mission`` with ``profiles`` and check its certificate against
    ``trusted`` (default `trust_store`), or, if that fails and ``issue``, verify it here
    and approve it on that verification (see the module docstring).

    ``include_path`` lists folders the mission's includes may come from besides its own
    folder (``coral-run --include-path``; `coral_lang.compiler.compile_file`). It changes
    only where files are found: the certificate covers the net they compile to, so the
    same mission with the same included content passes with or without it.

    Raises:
        coral_lang.diagnostics.CompileError: the mission does not compile (for instance
            no profile for its vehicle: neither given nor bundled).
        CertificateError: no passing certificate for this net and profile (and
            ``issue`` is False, or verification did not prove every property: the
            message lists what failed).
    """
    path = Path(mission)
    compiled = load_mission(path, profiles, include_path=include_path)
    cert_path = Path(certificate) if certificate is not None else default_certificate_path(path)
    try:
        approval = check_mission_certificate(compiled, cert_path, trusted=trusted)
        return ApprovedMission(compiled, approval, False)
    except CertificateError:
        if not issue:
            raise
    compiled, report = _verify(path, compiled, profiles, include_path)
    certificate_data = make_certificate(report, profile_content=compiled.profile_content())
    if certificate_data["verdict"] != "proven":
        failing = ", ".join(
            f"{p.key} {p.verdict.value}"
            for p in report.properties
            if p.required and p.verdict.value != "proven"
        )
        options = "".join(f" --profile {p.file}" for p in profiles)
        options += "".join(f" --include-path {folder}" for folder in include_path)
        raise CertificateError(
            f"{path}: verification did not pass ({failing}); run 'coral-check verify "
            f"{path}{options}' for the evidence, fix the mission, and run again"
        )
    # Approved on this verification, in memory: signed by a key that lives only in this
    # call and checked against a store of that key alone, through the same checks as any
    # signed certificate. The file written is unsigned: it records, it does not approve.
    own_key = SigningKey.generate("coral-run --verify (in-process)")
    approval = check_certificate_data(
        compiled.net,
        sign_certificate(certificate_data, own_key),
        str(cert_path),
        profile_content=compiled.profile_content(),
        trusted=TrustStore.of([own_key.public], "this process's own verification"),
        mission=path,
    )
    write_certificate(certificate_data, cert_path)
    return ApprovedMission(compiled, approval, True)


def _verify(
    path: Path,
    compiled: Mission,
    profiles: Sequence[VehicleProfile],
    include_path: Sequence[str | Path],
) -> tuple[Mission, Report]:
    """Verify the mission through the one check pipeline (`analysis.pipeline`), as
    ``coral-check verify`` does, so both reach the same verdict on the same file.

    Returns the mission as the pipeline compiled it (the net the report is about) and
    the report. Only the verdicts decide: lint findings are ``coral-check``'s business.

    Raises:
        CompileError: the file no longer compiles (it changed since ``compiled``).
    """
    from analysis.pipeline import CheckOptions, check_file  # loads the solvers
    from analysis.verify import VerifyOptions

    outcome = check_file(path, CheckOptions(profiles, include_path, verify=VerifyOptions()))
    result = outcome.result
    if result is None or outcome.report is None:
        if result is not None and result.errors:
            raise CompileError(result.errors, result.sources)
        return compiled, _verify_net(compiled)
    mission = Mission.from_result(result, path, profiles, include_path)
    return mission, outcome.report


def _verify_net(compiled: Mission) -> Report:
    """The report on the net already compiled, when the pipeline gave none: the file
    became unreadable since, or it is a part of a mission (which the pipeline checks
    without verifying)."""
    from analysis.verify import verify

    return verify(compiled.net)
