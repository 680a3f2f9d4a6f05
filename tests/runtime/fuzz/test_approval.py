"""The gate of fuzzing: a certificate checked as a run checks it, or ``--unverified``."""

from __future__ import annotations

from pathlib import Path

from analysis.signing import TrustStore
from coral_lang.mission import load_mission
from runtime import fuzz as fuzz_module
from runtime.fuzz import (
    UNVERIFIED,
    approval_for,
)
from tests.conftest import session_signing_key
from tests.runtime.fuzz.common import POOL, RACY
from tests.runtime.test_properties import mission


def test_the_unverified_approval_is_marked_and_only_ever_simulated() -> None:
    racy = mission("racy")
    approval, reason = approval_for(
        load_mission(Path(RACY)), Path("/nonexistent.json"), unverified=True
    )
    assert approval.path == UNVERIFIED and reason is not None
    assert approval.net_digest == racy.net.digest()
    # There is no way to point fuzz at a vehicle: no such option (not even as an
    # abbreviation of --vehicle-config), no socket link, no run_mission anywhere in it.
    assert fuzz_module.main([RACY, "--vehicle", "10.0.0.1:5000"]) == 2
    for source in Path(fuzz_module.__file__).parent.glob("*.py"):
        text = source.read_text(encoding="utf-8")
        assert "SocketLink" not in text and "run_mission" not in text, source


def test_a_verified_mission_keeps_its_certificate(pool_certificate: Path) -> None:
    pool = mission("pool")
    del pool
    approval, reason = approval_for(
        load_mission(Path(POOL)),
        pool_certificate,
        unverified=True,
        trusted=session_signing_key().trusted,
    )
    assert reason is None and approval.path == str(pool_certificate)
    # Not trusted: refused as a run refuses it, so only --unverified fuzzes it.
    refused, reason = approval_for(
        load_mission(Path(POOL)), pool_certificate, unverified=True, trusted=TrustStore()
    )
    assert refused.path == UNVERIFIED and reason is not None and "not trusted" in reason
