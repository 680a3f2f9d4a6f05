"""Pre-mission certificates: proof, in a file, that a net passed verification.

The runtime refuses to run a net unless a certificate for the same net digest says
every required property was proven, among them the termination properties every
mission needs (``no_engine_cycle``, ``final_always_reachable``, and ``terminates`` when
the mission says ``require termination``: `analysis.termination.required_keys`); a
certificate without them, such as one issued before they existed, is refused. The
digest covers everything that changes the vehicle's behaviour and nothing that does not
(``Net.digest``), so reformatting a mission keeps its certificate valid and changing any
parameter, arc or final marking voids it.

The net does not hold everything verification and the run assume about the vehicle: a
command's nominal duration, its parameter ranges and its tracking criterion live in the
vehicle profile. So a certificate also records, for each command the mission sends,
what the profile says of it (`coral_lang.mission.profile_content`), with a digest. When
the runtime checks a certificate it passes the profile it compiled against; a
difference is refused with a message naming each changed field, and a certificate
without a ``profile`` section (issued before profiles were covered) is refused too.
Descriptions, reply meanings, the profile file's path and commands the mission does
not use are not recorded, so changing them keeps the certificate valid.

A certificate is JSON (format documented in ``docs/verify.md``)::

    {"format": 1, "tool": "coral", "tool_version": "0.1.0", "net": "pool_mission",
     "net_digest": "sha256:...", "verdict": "proven", "issued": "2026-11-21T07:00:00Z",
     "properties": [{"key": "deadlock", "verdict": "proven", "method": "...",
                     "required": true}, ...],
     "options": {"max_states": 2000000, ...},
     "profile": {"vehicle": "ROMEO", "file": ".../romeo.yaml", "digest": "sha256:...",
                 "commands": {"DEPTH?": {"kind": "query", "params": [...],
                                         "replies": ["done", "timeout"], ...}}}}
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

from analysis.report import Report, Verdict
from analysis.termination import certificate_gaps
from analysis.verify import VerifyOptions
from coral_lang.diagnostics import CoralError
from coral_lang.mission import profile_digest
from coral_lang.net import Net
from coral_lang.profile import bundled_profile_path

CERTIFICATE_FORMAT = 1
Clock = Callable[[], dt.datetime]
MAX_LISTED_CHANGES = 6
"""How many profile changes a refusal names before it says "and N more"."""


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
    report: Report,
    options: VerifyOptions | None = None,
    clock: Clock = _utc_now,
    *,
    profile_content: Mapping[str, object] | None = None,
) -> dict[str, object]:
    """The certificate for ``report``: its digest, verdicts and the date of issue.

    A certificate is made for any report; only one whose verdict is ``proven`` lets the
    runtime run the net (see `check_certificate`). Every property is listed with its
    verdict, its method and whether it was required: one that is not (``terminates``
    without ``require termination``) may be violated in a passing certificate.

    ``profile_content`` (`coral_lang.mission.Mission.profile_content`) is recorded as
    the ``profile`` section, with its digest; the runtime refuses a certificate without
    one, so every certificate meant for a run must be given it.
    """
    settings = asdict(options or VerifyOptions())
    settings.pop("progress", None)
    profile: dict[str, object] = {}
    if profile_content is not None:
        # Through JSON, so the section is exactly what a reader of the file gets back.
        content = json.loads(json.dumps(dict(profile_content)))
        content["digest"] = profile_digest(content)
        profile["profile"] = content
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
        **profile,
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
    profile_digest: str | None = None
    """The digest of the certificate's ``profile`` section, when the check compared
    it with the mission's profile (None: checked without profile content)."""


def check_certificate(
    net: Net, path: str | Path, *, profile_content: Mapping[str, object] | None = None
) -> CertificateCheck:
    """Accept the certificate at ``path`` for ``net``, or explain why not.

    ``profile_content`` is what the mission's vehicle profile says now
    (`coral_lang.mission.Mission.profile_content`). Given it, the certificate must have
    a ``profile`` section equal to it; the runtime always gives it. Callers that check
    a net with no profile behind it (a PNML model) leave it out, and the section, if
    any, is not looked at.

    Raises:
        CertificateError: the file is missing or not a certificate, it was issued for
            another net (the mission changed since it was verified) or, with
            ``profile_content``, against a profile that has changed since (the message
            names each changed field) or before certificates covered the profile; some
            required property was not proven, or it lacks a property this version
            requires (it was issued by an older version). The message says which, and
            how to get a valid one.
    """
    path = Path(path)
    how = _how(path, profile_content)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CertificateError(f"{path}: no certificate; {how}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CertificateError(f"{path}: not a readable certificate ({exc}); {how}") from None
    if not isinstance(data, dict) or data.get("format") != CERTIFICATE_FORMAT:
        raise CertificateError(f"{path}: not a coral certificate (format 1); {how}")
    recorded = data.get("profile")
    accepted_profile: str | None = None
    if profile_content is not None and isinstance(recorded, dict):
        # Before the net digest: a changed reply kind changes the net too, and naming
        # the profile field that changed says more than "the net changed".
        accepted_profile = _check_profile(path, recorded, profile_content, how)
    digest = net.digest()
    if data.get("net_digest") != digest:
        raise CertificateError(
            f"{path}: issued for net {data.get('net_digest')!s}, but this mission compiles to "
            f"{digest}: it changed since it was verified; {how}"
        )
    if profile_content is not None and accepted_profile is None:
        version = data.get("tool_version", "an unknown version")
        raise CertificateError(
            f"{path}: the certificate predates profile coverage: coral {version} did not "
            "record the vehicle profile it verified against, so a profile edited since "
            f"would go unnoticed; {how} with this version to get a new one"
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
        profile_digest=accepted_profile,
    )


def _how(path: Path, profile_content: Mapping[str, object] | None) -> str:
    """How to get a valid certificate; names the profile file unless it is bundled
    (``coral-check`` finds those by the vehicle's name)."""
    option = ""
    if profile_content is not None:
        vehicle, file = profile_content.get("vehicle"), profile_content.get("file")
        if isinstance(vehicle, str) and isinstance(file, str):
            bundled = bundled_profile_path(vehicle)
            if bundled is None or bundled.resolve() != Path(file).resolve():
                option = f" --profile {file}"
    return f"run 'coral-check verify MISSION{option} --certificate {path}' and fix what it reports"


def _check_profile(
    path: Path, recorded: dict[str, object], current: Mapping[str, object], how: str
) -> str:
    """The digest of the recorded profile section if it matches ``current``; else
    `CertificateError` naming what changed."""
    now = json.loads(json.dumps(dict(current)))  # tuples to lists, as in the file
    digest = profile_digest(now)
    if recorded.get("digest") == digest and profile_digest(recorded) == digest:
        return digest
    vehicle = now.get("vehicle") or recorded.get("vehicle") or "of the vehicle"
    if recorded.get("vehicle") != now.get("vehicle"):
        changes = [f"vehicle {_show(recorded.get('vehicle'))} -> {_show(now.get('vehicle'))}"]
    else:
        changes = _command_changes(recorded.get("commands"), now.get("commands"))
    if not changes:
        changes = ["its recorded digest does not match its recorded commands"]
    if len(changes) > MAX_LISTED_CHANGES:
        more = len(changes) - MAX_LISTED_CHANGES + 1
        changes = [*changes[: MAX_LISTED_CHANGES - 1], f"and {more} more"]
    raise CertificateError(
        f"{path}: profile {vehicle} changed since certification: {'; '.join(changes)}; {how}"
    )


def _command_changes(before: object, after: object) -> list[str]:
    """Each difference between two ``commands`` sections, e.g.
    ``DEPTH?.duration_s 60 -> 90`` or ``command SURFACE? removed``."""
    old = before if isinstance(before, dict) else {}
    new = after if isinstance(after, dict) else {}
    changes: list[str] = []
    for name in sorted(old.keys() | new.keys()):
        if name not in new:
            changes.append(f"command {name} removed")
        elif name not in old:
            changes.append(f"command {name} added")
        else:
            changes += _changes(name, old[name], new[name])
    return changes


def _changes(where: str, before: object, after: object) -> list[str]:
    """The fields that differ between ``before`` and ``after`` under ``where``: mappings
    field by field, parameter lists by parameter name, anything else as a whole."""
    if isinstance(before, list) and isinstance(after, list):
        old_named, new_named = _by_name(before), _by_name(after)
        if old_named is not None and new_named is not None and (before or after):
            if old_named == new_named and before != after:
                return [f"{where} order {_show(list(old_named))} -> {_show(list(new_named))}"]
            before, after = old_named, new_named
    if isinstance(before, dict) and isinstance(after, dict):
        changes: list[str] = []
        for key in [*before, *(k for k in after if k not in before)]:
            if key not in after:
                changes.append(f"{where}.{key} removed")
            elif key not in before:
                changes.append(f"{where}.{key} added")
            else:
                changes += _changes(f"{where}.{key}", before[key], after[key])
        return changes
    if before == after:
        return []
    return [f"{where} {_show(before)} -> {_show(after)}"]


def _by_name(items: list[object]) -> dict[str, object] | None:
    """``items`` keyed by their ``name`` field, when they all have distinct ones."""
    named: dict[str, object] = {}
    for item in items:
        if not isinstance(item, dict) or not isinstance(item.get("name"), str):
            return None
        named[item["name"]] = {k: v for k, v in item.items() if k != "name"}
    return named if len(named) == len(items) else None


def _show(value: object) -> str:
    """A value as a person reads it: ``60``, ``[done, timeout]``, ``none``."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() and abs(value) < 1e15 else repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_show(v)}" for k, v in value.items()) + "}"
    return str(value)
