"""Known-unsound checker revisions: a certificate is refused when its proofs rest on a
method with a known soundness bug at the revision that wrote it, and only then."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.certificate import CertificateError, make_certificate, write_certificate
from analysis.signing import sign_certificate
from analysis.soundness import (
    CHECKER_REVISION,
    KNOWN_UNSOUND,
    OLDEST_REVISION,
    UnsoundCheck,
    implicated,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import Mission, load_mission
from runtime.gate import check_mission_certificate
from tests.conftest import EXAMPLES, TestKey

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAST = VerifyOptions(structural=False)
POOL_NET = load_mission(POOL).net

# The red team's net of commit 29d4413: 't' adds 2**62 tokens to 'b' a firing, and the
# explorer of revision 1 proved it bounded in 4 states (its 64-bit sums wrapped).
PUMP = """mission pump
vehicle ROMEO
place a = 1, b
final { b }
transition t wait { a } signal { a, b*4611686018427387904 }
"""
WEIGHTED = """mission weighted
vehicle ROMEO
place a = 1, b
final { b*2 }
transition t wait { a } signal { b*2 }
assert bound { b*2 } <= 5
"""


def _mission(tmp_path: Path, text: str, name: str) -> Mission:
    path = tmp_path / f"{name}.coral"
    path.write_text(text)
    return load_mission(path)


def _certificate(mission: Mission, **changes: object) -> dict[str, object]:
    report = verify(mission.net, FAST)
    certificate = make_certificate(report, FAST, profile_content=mission.profile_content())
    certificate.update(changes)
    return {k: v for k, v in certificate.items() if v is not None}


def _as_old_explorer_wrote_it(certificate: dict[str, object]) -> dict[str, object]:
    """What revision 1 wrote for PUMP: everything proven by the explicit state space."""
    properties = certificate["properties"]
    assert isinstance(properties, list)
    return {
        **certificate,
        "verdict": "proven",
        "properties": [
            {**p, "verdict": "proven", "method": "explicit state space"} for p in properties
        ],
    }


def _signed(path: Path, certificate: dict[str, object], key: TestKey) -> Path:
    write_certificate(sign_certificate(certificate, key.key), path)
    return path


def test_every_certificate_records_the_checker_revision(tmp_path: Path) -> None:
    mission = load_mission(POOL)
    certificate = make_certificate(verify(mission.net, FAST))
    assert certificate["checker_revision"] == CHECKER_REVISION
    # Every bug in the table was fixed by this revision or an earlier one.
    assert all(bug.last < bug.fixed_in <= CHECKER_REVISION for bug in KNOWN_UNSOUND)
    assert len({bug.name for bug in KNOWN_UNSOUND}) == len(KNOWN_UNSOUND)


def test_the_table_holds_the_explorer_wrap_fixed_in_29d4413() -> None:
    bug = next(b for b in KNOWN_UNSOUND if b.name == "explorer-64-bit-wrap")
    assert bug.fixed_by == "commit 29d4413" and "2**62" in bug.what
    assert bug.affects(OLDEST_REVISION, "explicit state space")
    assert bug.affects(OLDEST_REVISION, "explicit state space (stubborn-set reduced)")
    assert bug.affects(OLDEST_REVISION, "reachability graph, weak fairness of the runtime")
    assert not bug.affects(OLDEST_REVISION, "state equation + traps")
    assert not bug.affects(OLDEST_REVISION, "Karp-Miller coverability tree")
    assert not bug.affects(bug.fixed_in, "explicit state space")


def test_implicated_reads_revision_method_verdict_and_net(tmp_path: Path) -> None:
    pump = _mission(tmp_path, PUMP, "pump").net
    pool = load_mission(POOL).net
    explicit = {"key": "bounded", "verdict": "proven", "method": "explicit state space"}
    [found] = implicated(1, [explicit], pump)
    assert found.bug.name == "explorer-64-bit-wrap"
    assert found.properties == (("bounded", "explicit state space"),)
    assert "bounded by explicit state space" in found.describe()
    assert implicated(2, [explicit], pump) == []  # the fixed revision
    assert implicated(1, [explicit], pool) == []  # counts far below 2**60: cannot wrap
    assert implicated(1, [{**explicit, "verdict": "violated"}], pump) == []  # never relied on
    assert implicated(1, [{**explicit, "method": "state equation"}], pump) == []
    # A table entry without methods implicates every method.
    everything = UnsoundCheck("all", 1, 3, 4, "test", "everything was wrong")
    assert implicated(3, [{**explicit, "method": "z"}], pool, [everything])


def test_a_signed_pre_fix_certificate_resting_on_the_explorer_is_refused(
    tmp_path: Path, signing_key: TestKey
) -> None:
    mission = _mission(tmp_path, PUMP, "pump")
    old = _as_old_explorer_wrote_it(_certificate(mission, checker_revision=None))
    assert "checker_revision" not in old  # written before revisions were recorded
    cert = _signed(tmp_path / "pump.cert.json", old, signing_key)
    with pytest.raises(CertificateError) as refused:
        check_mission_certificate(mission, cert, trusted=signing_key.trusted)
    message = str(refused.value)
    assert "checker revision 1" in message and "explorer-64-bit-wrap" in message
    assert "commit 29d4413" in message and "bounded by explicit state space" in message
    assert f"re-verify with this version (checker revision {CHECKER_REVISION})" in message
    # The way out names the files, not placeholders.
    assert f"coral-check verify {tmp_path / 'pump.coral'} --certificate {cert}" in message
    # The same claims from a revision without the bug pass: the table decides.
    fixed = _signed(tmp_path / "fixed.cert.json", {**old, "checker_revision": 2}, signing_key)
    check = check_mission_certificate(mission, fixed, trusted=signing_key.trusted)
    assert check.checker_revision == 2


def test_a_pre_fix_certificate_the_bug_cannot_touch_stays_valid(
    tmp_path: Path, signing_key: TestKey
) -> None:
    mission = load_mission(POOL)
    certificate = _certificate(mission, checker_revision=None)
    methods = {p["method"] for p in certificate["properties"]}  # type: ignore[attr-defined]
    assert "explicit state space" in methods  # the method, but not a net it could wrap on
    cert = _signed(tmp_path / "pool.cert.json", certificate, signing_key)
    check = check_mission_certificate(mission, cert, trusted=signing_key.trusted)
    assert check.checker_revision == OLDEST_REVISION


def test_a_weighted_bound_proven_before_the_fix_is_refused(
    tmp_path: Path, signing_key: TestKey
) -> None:
    mission = _mission(tmp_path, WEIGHTED, "weighted")
    current = _certificate(mission)
    assert current["verdict"] == "proven"
    cert = _signed(tmp_path / "now.cert.json", current, signing_key)
    assert check_mission_certificate(mission, cert, trusted=signing_key.trusted)
    old = _signed(tmp_path / "old.cert.json", {**current, "checker_revision": 1}, signing_key)
    with pytest.raises(CertificateError, match=r"bound-assert-weights: .*assert:1 by"):
        check_mission_certificate(mission, old, trusted=signing_key.trusted)


@pytest.mark.parametrize("value", ["2", 0, -1, True, 2.0])
def test_a_malformed_revision_is_refused_naming_the_field(
    tmp_path: Path, signing_key: TestKey, value: object
) -> None:
    mission = load_mission(POOL)
    cert = _signed(
        tmp_path / "bad.cert.json", _certificate(mission, checker_revision=value), signing_key
    )
    with pytest.raises(CertificateError, match="'checker_revision' must be a whole number"):
        check_mission_certificate(mission, cert, trusted=signing_key.trusted)


METHODS = [
    "explicit state space",
    "explicit state space (stubborn-set reduced)",
    "explicit state space; state equation",
    "state equation",
    "state equation + traps",
    "Karp-Miller coverability tree",
    "reachability graph",
    "none",
]


@given(
    first=st.integers(1, 5),
    span=st.integers(0, 3),
    revision=st.integers(1, 12),
    methods=st.lists(st.sampled_from(METHODS[:3] + METHODS[5:6]), max_size=2, unique=True),
    method=st.sampled_from(METHODS),
    verdict=st.sampled_from(["proven", "violated", "inconclusive"]),
)
def test_a_property_is_implicated_exactly_when_revision_method_and_verdict_match(
    first: int, span: int, revision: int, methods: list[str], method: str, verdict: str
) -> None:
    bug = UnsoundCheck("b", first, first + span, first + span + 1, "test", "wrong", tuple(methods))
    found = implicated(
        revision, [{"key": "k", "verdict": verdict, "method": method}], POOL_NET, [bug]
    )
    expected = (
        verdict == "proven"
        and first <= revision <= first + span
        and (not methods or any(m in method for m in methods))
    )
    assert bool(found) == expected
