"""Pre-mission certificates: proof, in a file, that a net passed verification.

The runtime refuses to run a net unless a certificate for the same net digest says
every required property was proven, among them the termination properties every
mission needs (``no_engine_cycle``, ``final_always_reachable``, and ``terminates`` when
the mission says ``require termination``: `analysis.termination.required_keys`); a
certificate without them, such as one issued before they existed, is refused. The
digest covers everything that changes the vehicle's behaviour and nothing that does not
(``Net.digest``), so reformatting a mission keeps its certificate valid and changing any
parameter, arc or final marking voids it.

A certificate is JSON (format documented in ``docs/verify.md``)::

    {"format": 1, "tool": "coral", "tool_version": "0.1.0", "net": "pool_mission",
     "net_digest": "sha256:...", "verdict": "proven", "issued": "2026-11-21T07:00:00Z",
     "properties": [{"key": "deadlock", "verdict": "proven", "method": "...",
                     "required": true}, ...],
     "options": {"max_states": 2000000, ...}}
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from analysis.report import Report, Verdict
from analysis.termination import certificate_gaps
from analysis.verify import VerifyOptions
from coral_lang.diagnostics import CoralError
from coral_lang.net import Net

CERTIFICATE_FORMAT = 1
Clock = Callable[[], dt.datetime]


class CertificateError(CoralError, ValueError):
    """A certificate is missing, unreadable, for another net, or not a passing one.

    Run ``coral-check verify MISSION --certificate FILE`` on the mission as it is now,
    fix whatever it reports, and give the runtime the certificate it writes.
    """


def tool_version() -> str:
    """The installed coral version (``0+unknown`` when run from an uninstalled tree)."""
    from importlib import metadata  # about 20 ms to import: only when a version is asked

    try:
        return metadata.version("coral")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def _utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def make_certificate(
    report: Report, options: VerifyOptions | None = None, clock: Clock = _utc_now
) -> dict[str, object]:
    """The certificate for ``report``: its digest, verdicts and the date of issue.

    A certificate is made for any report; only one whose verdict is ``proven`` lets the
    runtime run the net (see `check_certificate`). Every property is listed with its
    verdict, its method and whether it was required: one that is not (``terminates``
    without ``require termination``) may be violated in a passing certificate.
    """
    settings = asdict(options or VerifyOptions())
    settings.pop("progress", None)
    return {
        "format": CERTIFICATE_FORMAT,
        "tool": "coral",
        "tool_version": tool_version(),
        "net": report.net_name,
        "net_digest": report.digest,
        "sources": list(report.sources),
        "verdict": report.verdict.value,
        "issued": clock().astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "properties": [
            {
                "key": p.key,
                "title": p.title,
                "verdict": p.verdict.value,
                "method": p.method,
                "required": p.required,
            }
            for p in report.properties
        ],
        "options": settings,
    }


def write_certificate(certificate: dict[str, object], path: str | Path) -> None:
    """Write ``certificate`` as indented JSON."""
    Path(path).write_text(json.dumps(certificate, indent=2) + "\n", encoding="utf-8")


@dataclass(frozen=True)
class CertificateCheck:
    """A certificate that was read and found to pass for a given net."""

    path: str
    net_digest: str
    issued: str
    tool_version: str


def check_certificate(net: Net, path: str | Path) -> CertificateCheck:
    """Accept the certificate at ``path`` for ``net``, or explain why not.

    Raises:
        CertificateError: the file is missing or not a certificate, it was issued for
            another net (the mission changed since it was verified), some required
            property was not proven, or it lacks a property this version requires (it
            was issued by an older version). The message says which, and how to get a
            valid one.
    """
    path = Path(path)
    how = f"run 'coral-check verify MISSION --certificate {path}' and fix what it reports"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CertificateError(f"{path}: no certificate; {how}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CertificateError(f"{path}: not a readable certificate ({exc}); {how}") from None
    if not isinstance(data, dict) or data.get("format") != CERTIFICATE_FORMAT:
        raise CertificateError(f"{path}: not a coral certificate (format 1); {how}")
    digest = net.digest()
    if data.get("net_digest") != digest:
        raise CertificateError(
            f"{path}: issued for net {data.get('net_digest')!s}, but this mission compiles to "
            f"{digest}: it changed since it was verified; {how}"
        )
    listed = [p for p in data.get("properties", []) if isinstance(p, dict)]
    if data.get("verdict") != Verdict.PROVEN.value:
        failing = [
            f"{p.get('key')} {p.get('verdict')}"
            for p in listed
            if p.get("verdict") != Verdict.PROVEN.value and p.get("required", True)
        ]
        raise CertificateError(
            f"{path}: verification did not pass ({', '.join(failing) or data.get('verdict')}); "
            f"{how}"
        )
    gaps = certificate_gaps(net, listed)
    if gaps:
        version = data.get("tool_version", "an unknown version")
        raise CertificateError(
            f"{path}: the certificate does not show what this coral requires of the mission "
            f"({', '.join(gaps)}): it was issued by coral {version}, which did not check "
            "termination (no engine cycle, a final marking always reachable, 'require "
            f"termination'); {how} with this version to get a new one"
        )
    return CertificateCheck(
        path=str(path),
        net_digest=digest,
        issued=str(data.get("issued", "")),
        tool_version=str(data.get("tool_version", "")),
    )
