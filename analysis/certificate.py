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

A certificate says nothing by itself: anyone can edit a JSON file. So the verifier
signs it (`analysis.signing`: Ed25519 over its canonical JSON, in a ``signature``
field), and the runtime passes the public keys it trusts (``trusted``): an unsigned
certificate, one signed by an unknown key, or one edited after signing is refused, and
so is one past its ``expires`` date, or signed by a key the store revokes
(`analysis.signing`). Given ``trusted``, every field the check reads is
validated first (types, the integer format 1), and every property's own verdict is read:
the top-level ``verdict`` is a summary, never trusted alone. Without ``trusted`` (checks
of a net by ``coral-check`` or by tests) the signature is not looked at.

A signature vouches for what the checker said, not that the checker was right: each
certificate records the ``checker_revision`` that wrote it, and one whose proven
properties were decided by a method with a known soundness bug at that revision
(`analysis.soundness`) is refused, naming the bug; one without a revision counts as
the oldest.

A certificate is JSON (format documented in ``docs/verify.md``)::

    {"format": 1, "tool": "coral", "tool_version": "0.1.0", "checker_revision": 2,
     "net": "pool_mission",
     "net_digest": "sha256:...", "verdict": "proven", "issued": "2026-11-21T07:00:00Z",
     "properties": [{"key": "deadlock", "verdict": "proven", "method": "...",
                     "required": true}, ...],
     "options": {"max_states": 2000000, ...},
     "profile": {"vehicle": "ROMEO", "file": ".../romeo.yaml", "digest": "sha256:...",
                 "commands": {"DEPTH?": {"kind": "query", "params": [...],
                                         "replies": ["done", "timeout"], ...}}},
     "timed": {"link": {"name": "genoa-lisbon", "min_delay_s": 0.045, ...},
               "profiles": [{"vehicle": "ROMEO", "tolerance": 0.2, ...}],
               "complete": true, "best_s": 160.2, "worst_s": 402.7, ...},
     "expires": "2026-12-21T07:00:00Z",
     "signature": {"algorithm": "ed25519", "key_id": "3f2a...", "value": "base64..."}}
"""

from __future__ import annotations

import base64
import binascii
import datetime as dt
import json
import shlex
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.report import Report, Verdict
from analysis.signing import ALGORITHM, SigningKey, TrustStore, canonical_bytes, sign_certificate
from analysis.soundness import CHECKER_REVISION, OLDEST_REVISION, implicated
from analysis.termination import certificate_gaps, required_keys
from analysis.verify import VerifyOptions
from coral_lang.diagnostics import CoralError
from coral_lang.mission import profile_digest
from coral_lang.net import Net
from coral_lang.profile import bundled_profile_path
from coral_lang.safefile import UnreadableFile, read_text_file

if TYPE_CHECKING:
    from analysis.timed.results import TimedReport
    from coral_lang.profile import VehicleProfile

CERTIFICATE_FORMAT = 1
Clock = Callable[[], dt.datetime]
MAX_LISTED_CHANGES = 6
"""How many profile changes a refusal names before it says "and N more"."""
MAX_CERTIFICATE_BYTES = 16 * 1024 * 1024
"""A file larger than this is not a certificate (the largest profile sections are a
few kilobytes): refused unread rather than parsed into memory."""
DIGEST_SHOWN = 19
"""How much of a certificate's own net digest a refusal shows (``sha256:`` and 12 hex
digits): enough to tell certificates apart. The digest the net *should* have is never
shown: a forger would copy it."""
TIME_FORMAT = "%Y-%m-%dT%H:%M:%SZ"


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
    expires: dt.datetime | None = None,
    profiles: Sequence[VehicleProfile] = (),
) -> dict[str, object]:
    """The certificate for ``report``: its digest, verdicts and the date of issue.

    The top-level ``verdict`` is computed here from the listed properties (the worst
    verdict of the required ones), not copied from anywhere: a search cut short by its
    budgets leaves properties inconclusive, and then the certificate cannot say
    ``proven``. ``expires`` (optional) is the moment after which the runtime refuses it.

    A certificate is made for any report; only one whose verdict is ``proven`` lets the
    runtime run the net (see `check_certificate`). Every property is listed with its
    verdict, its method and whether it was required: one that is not (``terminates``
    without ``require termination``) may be violated in a passing certificate.

    ``profile_content`` (`coral_lang.mission.Mission.profile_content`) is recorded as
    the ``profile`` section, with its digest; the runtime refuses a certificate without
    one, so every certificate meant for a run must be given it.

    A timed verification (``report.timed``) adds a ``timed`` section (`timed_section`):
    what was proven about time and under which assumptions (the link bounds, the timing
    of ``profiles``, the profiles the mission was compiled against). An untimed
    certificate has no such section, and its options no ``timed``: it says nothing
    about time.
    """
    settings = asdict(options or VerifyOptions())
    settings.pop("progress", None)
    if settings.get("timed") is None:
        settings.pop("timed", None)
    profile: dict[str, object] = {}
    if profile_content is not None:
        # Through JSON, so the section is exactly what a reader of the file gets back.
        content = json.loads(json.dumps(dict(profile_content)))
        content["digest"] = profile_digest(content)
        profile["profile"] = content
    properties: list[dict[str, object]] = [
        {
            "key": p.key,
            "title": p.title,
            "verdict": p.verdict.value,
            "method": p.method,
            "required": p.required,
        }
        for p in report.properties
    ]
    space = report.statespace
    certificate: dict[str, object] = {
        "format": CERTIFICATE_FORMAT,
        "tool": "coral",
        "tool_version": tool_version(),
        "checker_revision": CHECKER_REVISION,
        "net": report.net_name,
        "net_digest": report.digest,
        "sources": list(report.sources),
        "verdict": overall_verdict(properties),
        "issued": clock().astimezone(dt.UTC).strftime(TIME_FORMAT),
        "properties": properties,
        "options": settings,
        "search": {
            "states": space.states,
            "complete": space.complete,
            "stopped_reason": space.stopped_reason,
        },
        **profile,
    }
    if report.timed is not None:
        certificate["timed"] = timed_section(report.timed, profiles)
    if expires is not None:
        certificate["expires"] = expires.astimezone(dt.UTC).strftime(TIME_FORMAT)
    return certificate


def timed_section(timed: TimedReport, profiles: Sequence[VehicleProfile]) -> dict[str, object]:
    """What a certificate records of timed analysis: the assumptions (link bounds, each
    profile's timing) and only what was proven under them. Figures of an incomplete or
    unbounded exploration are left out (None), since nothing about them was proven; a
    query or deadline keeps its verdict, with its margin only when proven."""
    proven = timed.complete and not timed.unbounded
    return {
        "link": timed.link.to_json(),
        "profiles": [
            {
                "vehicle": p.name,
                "tolerance": p.timing.tolerance,
                "reply_latency_s": p.timing.reply_latency_s,
            }
            for p in profiles
        ],
        "complete": timed.complete,
        "reason": timed.reason,
        "best_s": timed.best_s if proven else None,
        "worst_s": timed.worst_s if proven else None,
        "finals": [
            {"final": f.final, "best_s": f.best_s, "worst_s": f.worst_s}
            for f in (timed.finals if proven else ())
        ],
        "queries": [
            {
                "transition": q.transition,
                "command": q.command,
                "time_out_s": q.time_out_s,
                "verdict": q.verdict.value,
                "margin_s": q.margin_s if q.verdict is Verdict.PROVEN else None,
            }
            for q in timed.queries
        ],
        "deadlines": [
            {
                "index": d.index,
                "deadline_s": d.deadline_s,
                "verdict": d.verdict.value,
                "latest_s": d.latest_s if d.verdict is Verdict.PROVEN else None,
            }
            for d in timed.deadlines
        ],
    }


def overall_verdict(properties: list[dict[str, object]]) -> str:
    """The worst verdict among the required ``properties`` (violated > inconclusive >
    proven; a property with any other verdict counts as violated)."""
    order = [Verdict.PROVEN.value, Verdict.INCONCLUSIVE.value, Verdict.VIOLATED.value]
    worst = 0
    for p in properties:
        if p.get("required", True) is not False:
            verdict = p.get("verdict")
            worst = max(worst, order.index(verdict) if verdict in order else 2)
    return order[worst]


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
    signer: str | None = None
    """The key id of the trusted key that signed it (None: checked without a trust
    store, so the signature was not looked at)."""
    expires: str | None = None
    """When it stops being accepted (None: no expiry recorded)."""
    checker_revision: int = OLDEST_REVISION
    """The checker revision that wrote it (`analysis.soundness`)."""
    mission: str | None = None
    """The mission file the check was for, when the caller named it: later refusals
    (the engine's) name it in the command that gets a new certificate."""


def check_certificate(
    net: Net,
    path: str | Path,
    *,
    profile_content: Mapping[str, object] | None = None,
    trusted: TrustStore | None = None,
    clock: Clock = _utc_now,
    mission: str | Path | None = None,
) -> CertificateCheck:
    """Accept the certificate at ``path`` for ``net``, or explain why not.

    ``profile_content`` is what the mission's vehicle profile says now
    (`coral_lang.mission.Mission.profile_content`). Given it, the certificate must have
    a ``profile`` section equal to it; the runtime always gives it. Callers that check
    a net with no profile behind it (a PNML model) leave it out, and the section, if
    any, is not looked at.

    ``trusted`` is the set of public keys whose signatures are accepted; the runtime
    always gives one (perhaps empty). Without it the signature is not checked: that is
    for tools that only want to know what a certificate claims, never for a run.
    ``clock`` decides expiry. ``mission`` is the file ``net`` was compiled from, when
    the caller knows it: a refusal's way out then names it (``coral-check verify
    pool.coral --certificate ...``) instead of ``MISSION``.

    Raises:
        CertificateError: the file is missing, not a certificate or malformed (the
            message names the field); with ``trusted``: unsigned, signed by a key not
            in it (named by key id), signed by a key it revokes, or edited after
            signing; expired; issued for
            another net (the mission changed since it was verified) or, with
            ``profile_content``, against a profile that has changed since (the message
            names each changed field) or before certificates covered the profile; some
            required property missing or not proven, or it lacks a property this
            version requires (it was issued by an older version); a proven property
            decided by a method with a known soundness bug at the certificate's checker
            revision (`analysis.soundness`). The message says which, and how to get a
            valid one.
    """
    path = Path(path)
    how = _how(path, profile_content, mission)
    data = read_certificate(path, how)
    return check_certificate_data(
        net,
        data,
        str(path),
        profile_content=profile_content,
        trusted=trusted,
        clock=clock,
        how=how,
        mission=mission,
    )


def read_certificate(path: Path, how: str = "") -> dict[str, object]:
    """The JSON object in ``path``; `CertificateError` if it cannot be one.

    Duplicate keys, NaN and nesting too deep for the parser are refused here: each
    would make the content a reader sees differ from what was signed, or crash it.
    """
    how = how or _how(path, None)
    try:  # a regular file of bounded size: never a FIFO or /dev/zero
        text = read_text_file(path, MAX_CERTIFICATE_BYTES)
    except UnreadableFile as exc:
        if exc.kind == "missing":
            raise CertificateError(f"{path}: no certificate; {how}") from None
        if exc.kind == "large":
            raise CertificateError(
                f"{path}: too large for a certificate ({exc.reason}); {how}"
            ) from None
        raise CertificateError(
            f"{path}: not a readable certificate ({exc.reason}); {how}"
        ) from None
    try:
        data = json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_no_constant)
    except ValueError as exc:
        raise CertificateError(f"{path}: not a readable certificate ({exc}); {how}") from None
    except RecursionError:
        raise CertificateError(
            f"{path}: not a readable certificate (nested too deeply); {how}"
        ) from None
    if not isinstance(data, dict):
        raise CertificateError(f"{path}: not a coral certificate (not a JSON object); {how}")
    return data


def _no_duplicates(pairs: list[tuple[str, object]]) -> dict[str, object]:
    result: dict[str, object] = {}
    for key, value in pairs:
        if key in result:
            raise ValueError(f"duplicate key {key!r}")
        result[key] = value
    return result


def _no_constant(name: str) -> object:
    raise ValueError(f"{name} is not JSON")


def check_certificate_data(
    net: Net,
    data: Mapping[str, object],
    source: str,
    *,
    profile_content: Mapping[str, object] | None = None,
    trusted: TrustStore | None = None,
    clock: Clock = _utc_now,
    how: str = "",
    mission: str | Path | None = None,
) -> CertificateCheck:
    """`check_certificate` on content already read (``source`` names it in messages);
    ``coral-run --verify`` checks the certificate it just made this way, in memory."""
    path = Path(source)
    how = how or _how(path, profile_content, mission)
    try:
        return _check(net, data, path, profile_content, trusted, clock, how, mission)
    except RecursionError:  # canonical JSON of absurdly nested content
        raise CertificateError(
            f"{path}: malformed certificate (nested too deeply); {how}"
        ) from None


def _check(
    net: Net,
    data: Mapping[str, object],
    path: Path,
    profile_content: Mapping[str, object] | None,
    trusted: TrustStore | None,
    clock: Clock,
    how: str,
    mission: str | Path | None = None,
) -> CertificateCheck:
    fmt = data.get("format")
    if type(fmt) is not int or fmt != CERTIFICATE_FORMAT:
        raise CertificateError(
            f"{path}: not a coral certificate (format must be the integer 1, found "
            f"{json.dumps(fmt)[:40]}); {how}"
        )
    _validate(path, data, how)
    signer = None if trusted is None else _check_signature(path, data, trusted, how, mission)
    expires = data.get("expires")
    if isinstance(expires, str) and clock().astimezone(dt.UTC) >= _parse_time(expires):
        raise CertificateError(f"{path}: the certificate expired at {expires}; {how}")
    recorded = data.get("profile")
    accepted_profile: str | None = None
    if profile_content is not None and isinstance(recorded, dict):
        # Before the net digest: a changed reply kind changes the net too, and naming
        # the profile field that changed says more than "the net changed".
        accepted_profile = _check_profile(path, recorded, profile_content, how)
    digest = net.digest()
    claimed = str(data.get("net_digest"))
    if claimed != digest:
        raise CertificateError(
            f"{path}: the certificate is for another net (its digest begins "
            f"{claimed[:DIGEST_SHOWN]}), not this mission as it compiles now: it changed "
            f"since it was verified, or the certificate is another mission's; {how}"
        )
    version = data.get("tool_version", "an unknown version")
    if profile_content is not None and accepted_profile is None:
        raise CertificateError(
            f"{path}: the certificate predates profile coverage: coral {version} did not "
            "record the vehicle profile it verified against, so a profile edited since "
            f"would go unnoticed; {how} with this version to get a new one"
        )
    listed = _properties(data)
    # Every property's own verdict: the top-level one is a summary, and a certificate
    # whose summary disagrees with its properties is refused whichever way it leans.
    must = {"bounded", "deadlock", *(f"assert:{n}" for n in range(1, len(net.assertions) + 1))}
    failing = [
        f"{p['key']} {p['verdict']}"
        for p in listed
        if p["verdict"] != Verdict.PROVEN.value
        and (p.get("required", True) is not False or p["key"] in must)
    ]
    shown = {str(p["key"]) for p in listed}
    termination = set(required_keys(net))
    failing += [f"{key} missing" for key in sorted(must - shown)]
    if failing or data.get("verdict") != Verdict.PROVEN.value:
        raise CertificateError(
            f"{path}: verification did not pass ({', '.join(failing) or data.get('verdict')}); "
            f"{how}"
        )
    gaps = certificate_gaps(net, listed)
    if gaps:
        what = (
            "which did not check termination (no engine cycle, a final marking always "
            "reachable, 'require termination')"
            if termination - shown
            else "which cannot verify every 'require' of this mission"
        )
        raise CertificateError(
            f"{path}: the certificate does not show what this coral requires of the mission "
            f"({', '.join(gaps)}): it was issued by coral {version}, {what}; {how} with this "
            "version to get a new one"
        )
    revision = _revision(data)
    bugs = implicated(revision, listed, net)
    if bugs:
        raise CertificateError(
            f"{path}: issued by coral {version} (checker revision {revision}), whose proofs "
            f"rest on a known soundness bug: {'; '.join(b.describe() for b in bugs)}; "
            f"re-verify with this version (checker revision {CHECKER_REVISION}): {how}"
        )
    return CertificateCheck(
        path=str(path),
        net_digest=digest,
        issued=str(data.get("issued", "")),
        tool_version=str(data.get("tool_version", "")),
        profile_digest=accepted_profile,
        signer=signer,
        expires=expires if isinstance(expires, str) else None,
        checker_revision=revision,
        mission=None if mission is None else str(mission),
    )


def _revision(data: Mapping[str, object]) -> int:
    """The certificate's checker revision (validated), the oldest when it records none."""
    revision = data.get("checker_revision")
    return revision if isinstance(revision, int) else OLDEST_REVISION


def resign_certificate(path: str | Path, key: SigningKey, trusted: TrustStore) -> dict[str, object]:
    """The certificate at ``path`` signed by ``key`` instead: key rotation without
    verifying again.

    Re-signing vouches for content someone else signed, so it is done only for a
    certificate whose present signature is by a key ``trusted`` holds and does not
    revoke, and which was not edited since; never with a key ``trusted`` revokes. The
    content is kept byte for byte (only ``signature`` changes), so everything else the
    runtime checks (net digest, profile, expiry, checker revision) is checked at run
    time exactly as before: re-signing never revives an expired or known-unsound
    certificate. A certificate whose signer is revoked must be verified again.

    Raises:
        CertificateError: unreadable, malformed, unsigned, signed by an unknown or
            revoked key, edited after signing, or ``key`` itself is revoked.
    """
    path = Path(path)
    how = _how(path, None)
    data = read_certificate(path, how)
    fmt = data.get("format")
    if type(fmt) is not int or fmt != CERTIFICATE_FORMAT:
        raise CertificateError(f"{path}: not a coral certificate (format must be the integer 1)")
    _validate(path, data, how)
    try:
        _check_signature(path, data, trusted, how)
    except RecursionError:
        raise CertificateError(f"{path}: malformed certificate (nested too deeply)") from None
    revoked = trusted.revocation(key.public.key_id)
    if revoked is not None:
        raise CertificateError(
            f"the new signing key {key.public.key_id} is revoked ({revoked.reason}, "
            f"{revoked.date}); create a new one with 'coral-check keygen --out FILE'"
        )
    return sign_certificate(data, key)


def _validate(path: Path, data: Mapping[str, object], how: str) -> None:
    """Refuse a certificate whose fields have the wrong shape, naming the field."""

    def bad(field: str, want: str) -> CertificateError:
        found = type(data.get(field)).__name__ if field in data else "missing"
        return CertificateError(
            f"{path}: malformed certificate: '{field}' must be {want} (found {found}); {how}"
        )

    for field in ("net_digest", "verdict", "issued"):
        if not isinstance(data.get(field), str):
            raise bad(field, "a string")
    for field in ("tool_version", "net"):
        if field in data and not isinstance(data[field], str):
            raise bad(field, "a string")
    if "checker_revision" in data:
        revision = data["checker_revision"]
        if type(revision) is not int or revision < 1:
            raise bad("checker_revision", "a whole number of 1 or more")
    for field in ("options", "profile", "signature"):
        if field in data and not isinstance(data[field], dict):
            raise bad(field, "an object")
    if "expires" in data and data["expires"] is not None:
        expires = data["expires"]
        if not isinstance(expires, str) or _try_time(expires) is None:
            raise bad("expires", "a UTC time such as 2026-12-31T23:59:59Z")
    properties = data.get("properties")
    if not isinstance(properties, list):
        raise bad("properties", "a list")
    for number, p in enumerate(properties, start=1):
        where = f"properties[{number}]"
        if not isinstance(p, dict):
            raise CertificateError(
                f"{path}: malformed certificate: {where} is not an object; {how}"
            )
        for field in ("key", "verdict"):
            if not isinstance(p.get(field), str):
                raise CertificateError(
                    f"{path}: malformed certificate: {where}.{field} must be a string; {how}"
                )
        if "required" in p and not isinstance(p["required"], bool):
            raise CertificateError(
                f"{path}: malformed certificate: {where}.required must be true or false; {how}"
            )


def _properties(data: Mapping[str, object]) -> list[dict[str, object]]:
    listed = data.get("properties")
    assert isinstance(listed, list)  # checked by _validate
    return [p for p in listed if isinstance(p, dict)]


def _check_signature(
    path: Path,
    data: Mapping[str, object],
    trusted: TrustStore,
    how: str,
    mission: str | Path | None = None,
) -> str:
    """The key id of the trusted key whose signature covers ``data``, else a refusal:
    unsigned, unknown signer, or content edited after signing."""
    signature = data.get("signature")
    if signature is None:
        shown = _shown_mission(mission)
        raise CertificateError(
            f"{path}: the certificate is not signed, and a run accepts only certificates "
            f"signed by a trusted key ({trusted.describe()}); sign it with 'coral-check "
            f"verify {shown} --certificate {shlex.quote(str(path))} --signing-key KEY' and "
            "trust KEY.pub with --trusted-keys, or, on a development machine, verify and run "
            f"in one step with 'coral-run {shown} --verify'"
        )
    assert isinstance(signature, dict)  # checked by _validate
    algorithm, kid, value = (signature.get(k) for k in ("algorithm", "key_id", "value"))
    if algorithm != ALGORITHM or not isinstance(kid, str) or not isinstance(value, str):
        raise CertificateError(
            f"{path}: malformed certificate: 'signature' must have algorithm \"{ALGORITHM}\" "
            f"and string key_id and value; {how}"
        )
    # The signature block is outside what is signed: anything else in it is an edit
    # nobody can vouch for (bench/redteam.py added a field and the run went ahead).
    extra = sorted(set(signature) - {"algorithm", "key_id", "value"})
    if extra:
        raise CertificateError(
            f"{path}: malformed certificate: 'signature' has fields no signer writes "
            f"({', '.join(repr(k)[:40] for k in extra[:5])}); {how}"
        )
    revoked = trusted.revocation(kid)
    if revoked is not None:
        raise CertificateError(
            f"{path}: signed by key {kid[:32]}, which was revoked on {revoked.date} "
            f"({revoked.reason}; {revoked.source or trusted.describe()}): its signatures "
            "are refused even if the key is also listed as trusted; get the mission "
            "verified again and signed with a current key"
        )
    key = trusted.get(kid)
    if key is None:
        raise CertificateError(
            f"{path}: signed by key {kid[:32]}, which is not trusted here "
            f"({trusted.describe()}); if you trust whoever holds that key, add its .pub "
            "line to the trust store (--trusted-keys), else get a certificate from your "
            "verifier"
        )
    try:
        raw = base64.b64decode(value, validate=True)
        message = canonical_bytes(data)
    except (binascii.Error, ValueError):
        raw, message = b"", b""
    if not key.verifies(raw, message):
        raise CertificateError(
            f"{path}: the signature by key {kid} does not match the content: the "
            f"certificate was edited after it was signed; {how}"
        )
    return kid


def _try_time(text: str) -> dt.datetime | None:
    try:
        moment = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return None
    return moment if moment.tzinfo is not None else None


def _parse_time(text: str) -> dt.datetime:
    moment = _try_time(text)
    if moment is None:
        raise ValueError(f"not a UTC time: {text}")
    return moment


def parse_expires(text: str, now: dt.datetime) -> dt.datetime:
    """``--expires``: a number of days from ``now``, or an ISO date (valid through the
    end of that day, UTC) or time. ValueError, saying what is expected, otherwise or
    when the moment is not after ``now``."""
    text = text.strip()
    moment: dt.datetime | None
    if text.isdigit():
        moment = now + dt.timedelta(days=int(text))
    else:
        try:
            day = dt.date.fromisoformat(text)
        except ValueError:
            moment = _try_time(text)
        else:
            moment = dt.datetime.combine(day, dt.time(23, 59, 59), tzinfo=dt.UTC)
    if moment is None:
        raise ValueError(
            f"expected a number of days or an ISO date (2026-12-31) or UTC time, got {text!r}"
        )
    if moment <= now:
        raise ValueError(f"{text} is not in the future")
    return moment


def _shown_mission(mission: str | Path | None) -> str:
    """``mission`` as a shell word for a command to copy, or ``MISSION`` when unknown."""
    return "MISSION" if mission is None else shlex.quote(str(mission))


def _how(
    path: Path, profile_content: Mapping[str, object] | None, mission: str | Path | None = None
) -> str:
    """How to get a valid certificate: a command to copy, naming the mission (when
    known), the certificate and the profile file unless it is bundled (``coral-check``
    finds those by the vehicle's name)."""
    option = ""
    if profile_content is not None:
        vehicle, file = profile_content.get("vehicle"), profile_content.get("file")
        if isinstance(vehicle, str) and isinstance(file, str):
            bundled = bundled_profile_path(vehicle)
            if bundled is None or bundled.resolve() != Path(file).resolve():
                option = f" --profile {shlex.quote(file)}"
    return (
        f"run 'coral-check verify {_shown_mission(mission)}{option} --certificate "
        f"{shlex.quote(str(path))} --signing-key KEY' and fix what it reports"
    )


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
        changes += _changes("timing", recorded.get("timing"), now.get("timing"))
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
