"""Regressions for small red-team findings: weighted ``bound`` asserts, non-ASCII
digits, the profile ``version`` field, ``coral-run --resume`` on a bad log, and
coverability on counts near the int64 limit."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from analysis.coverability import coverability
from analysis.report import Verdict
from analysis.verify import VerifyOptions, verify
from coral_lang.compiler import compile_file, compile_source
from coral_lang.diagnostics import ProfileError
from coral_lang.net import AssertKind, Net
from coral_lang.profile import parse_profile
from runtime.cli import main as run_main
from runtime.eventlog import EventLog, EventLogError
from tests.runtime.helpers import POOL_MISSION

HEADER = "mission m\nvehicle ROMEO\n"

# p holds 2 tokens at most; q at most 1, and never both at once beyond p=2,q=0.
WEIGHTED = HEADER + (
    "place p = 2, q\n"
    "transition move wait { p } signal { q }\n"
    "transition back wait { q } signal { p }\n"
)


def test_bound_assert_keeps_its_weight_in_the_compiled_net() -> None:
    net = compile_source(WEIGHTED + "assert bound {p*2} <= 3\n", "m.coral").raise_for_errors()
    (assertion,) = net.assertions
    assert assertion.kind is AssertKind.BOUND
    assert assertion.places == (("p", 2),) and assertion.bound == 3
    assert assertion.describe() == "assert bound p*2 <= 3"


def test_weighted_bound_is_violated_where_the_unweighted_one_holds() -> None:
    # p starts with 2 tokens: 2*M(p) = 4 > 3, so the weighted bound is violated
    # (it was reported proven when the weight was dropped: M(p) = 2 <= 3).
    text = WEIGHTED + "assert bound {p*2} <= 3\nassert bound {p} <= 3\nassert bound {p*2, q} <= 4\n"
    report = verify(compile_source(text, "m.coral").raise_for_errors(), VerifyOptions())
    assert report.property("assert:1").verdict is Verdict.VIOLATED
    assert report.property("assert:2").verdict is Verdict.PROVEN
    assert report.property("assert:3").verdict is Verdict.PROVEN


def test_weighted_bound_uses_the_weight_in_the_state_equation_too() -> None:
    # A search cut short at the initial marking leaves the verdict to the state
    # equation: it must bound 3*M(q) (q reaches 1 token: 3 > 2), not M(q).
    text = HEADER + (
        "place p = 1, q\n"
        "transition move wait { p } signal { q }\n"
        "assert bound {q*3} <= 2\n"
        "assert bound {p*2, q*2} <= 2\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    report = verify(net, VerifyOptions(max_states=1, structural=False))
    assert not report.statespace.complete
    assert report.property("assert:1").verdict is Verdict.VIOLATED
    assert report.property("assert:2").verdict is Verdict.PROVEN


@pytest.mark.parametrize(
    ("source", "line", "col", "digit"),
    [
        ("place p = \u0663\n", 3, 11, "U+0663"),  # Arabic-Indic three
        ("place p = 1\ntransition t wait { p*\uff13 } signal { }\n", 4, 23, "U+FF13"),
        ("const k = 1\u0663\n", 3, 11, "U+0663"),  # mixed with an ASCII digit
        (
            "place p = 1\ntransition t wait {p} action { ROMEO(DEPTH, \u0661.5) -> {ack: p} }\n",
            4,
            45,
            "U+0661",  # a float() path
        ),
    ],
)
def test_non_ascii_digits_are_refused_at_the_token(
    source: str, line: int, col: int, digit: str
) -> None:
    result = compile_source(HEADER + source, "m.coral")
    assert result.net is None
    (error,) = result.errors
    assert error.code == "CORAL001" and digit in error.message and "0-9" in error.message
    assert error.span is not None
    assert (error.span.file, error.span.line, error.span.col) == ("m.coral", line, col)


def test_non_ascii_digits_in_a_name_are_still_a_name() -> None:
    # only numbers are restricted: a place may be called p\u0663 like any Unicode name
    net = compile_source(HEADER + "place p\u0663 = 1\n", "m.coral").raise_for_errors()
    assert [p.name for p in net.places] == ["p\u0663"]


COMMANDS = "commands:\n  GO: {kind: action, replies: {done: ok}}\n"


def _profile(version: str | None) -> str:
    """A minimal valid profile, with ``version: VERSION`` on line 2 when given."""
    line = "" if version is None else f"version: {version}\n"
    return f"vehicle: V\n{line}{COMMANDS}"


@pytest.mark.parametrize(
    ("version", "got"),
    [
        ('"1"', "text ('1')"),
        ("1.5", "a number (1.5)"),
        ("true", "a boolean (true)"),
        ("[1]", "a list"),
        ("{a: 1}", "a mapping"),
        ("~", "nothing"),
        ("0", "0"),
        ("-3", "-3"),
    ],
)
def test_profile_version_must_be_a_positive_whole_number(version: str, got: str) -> None:
    with pytest.raises(ProfileError) as caught:
        parse_profile(_profile(version), "v.yaml")
    error = caught.value
    assert error.file == "v.yaml:2:10" and error.path == "version"
    assert "positive whole number" in error.detail and got in error.detail
    assert str(error).startswith("v.yaml:2:10: version: ")


def test_profile_version_accepts_a_positive_integer_or_no_version() -> None:
    assert parse_profile(_profile("2"), "v.yaml").name == "V"
    assert parse_profile(_profile(None), "v.yaml").name == "V"


# -- coral-run --resume on a log it cannot resume: exit 2, the log named, no traceback --


def _resume_log(tmp_path: Path, digest: str) -> Path:
    """A controller log of ``digest``'s net whose run stopped before its first checkpoint.

    Written without a key, as a simulated run without ``--key-file`` writes it, and
    resumed the same way (`_resume` gives no key): such a log is not authenticated, so
    the checks below the MAC chain are what refuses its edits. With a key, the chain
    refuses them first (tests/runtime/test_logauth.py).
    """
    path = tmp_path / "run" / "controller.sqlite"
    path.parent.mkdir()
    with EventLog.create(
        path,
        role="controller",
        mission="pool",
        meta={"mission_path": str(POOL_MISSION), "profiles": []},
        net_digest=digest,
    ):
        pass
    return path


def _pool_digest() -> str:
    return compile_file(POOL_MISSION).raise_for_errors().digest()


def _resume(
    log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], *mission: str
) -> tuple[int, str]:
    cert = tmp_path / "cert.json"
    code = run_main(
        [*mission, "--resume", str(log), "--verify", "--certificate", str(cert), "--no-plots", "-q"]
    )
    return code, capsys.readouterr().err


def test_resume_with_another_mission_than_the_logs_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _resume_log(tmp_path, "0" * 64)
    code, err = _resume(log, tmp_path, capsys, str(POOL_MISSION))
    assert code == 2 and "Traceback" not in err
    assert str(log) in err and "resume with the mission that was running" in err


def test_resume_from_a_log_without_checkpoint_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _resume_log(tmp_path, _pool_digest())
    code, err = _resume(log, tmp_path, capsys)
    assert code == 2 and "Traceback" not in err
    assert str(log) in err and "no committed state" in err
    with EventLog.open(log) as reread:  # refused before anything was written to it
        assert reread.count() == 0


@pytest.mark.parametrize(
    ("state", "said"),
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "not a JSON object"),
        ('{"engine": 1, "mission_id": 1, "consumed": 0}', "no engine state"),
        ('{"engine": {}, "mission_id": "x", "consumed": 0}', "'mission_id' is not a whole number"),
    ],
)
def test_resume_from_a_damaged_checkpoint_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], state: str, said: str
) -> None:
    log = _resume_log(tmp_path, _pool_digest())
    with EventLog.open(log, writable=True) as writer:
        writer.commit({"engine": {}, "mission_id": 1, "consumed": 0})
    db = sqlite3.connect(log)
    with db:
        db.execute("UPDATE checkpoint SET state = ? WHERE id = 1", (state,))
    db.close()
    code, err = _resume(log, tmp_path, capsys)
    assert code == 2 and "Traceback" not in err
    assert str(log) in err and said in err


def test_checkpoint_that_is_not_json_raises_an_event_log_error(tmp_path: Path) -> None:
    log = _resume_log(tmp_path, "0" * 64)
    with EventLog.open(log, writable=True) as writer:
        writer.commit({"a": 1})
    db = sqlite3.connect(log)
    with db:
        db.execute("UPDATE checkpoint SET state = '{' WHERE id = 1")
    db.close()
    with EventLog.open(log) as reread, pytest.raises(EventLogError, match="not valid JSON"):
        reread.checkpoint()


# -- coverability near the int64 limit: undecided with the reason, never wrong or a crash --

B59 = 2**59


def _net(body: str) -> Net:
    return compile_source(HEADER + body, "m.coral").raise_for_errors()


def test_coverability_past_its_exact_range_is_undecided_with_the_reason() -> None:
    # Four places of 2**59 poured into one: 'e' holds 2**61, past what the tree holds
    # apart from ω. Bounded (tokens only move), so "unbounded" would be wrong.
    net = _net(
        f"place a = {B59}, b = {B59}, c = {B59}, d = {B59}, e\n"
        f"transition pour wait {{ a*{B59}, b*{B59}, c*{B59}, d*{B59} }} signal {{ e*{4 * B59} }}\n"
        f"transition back wait {{ e*{4 * B59} }} signal {{ a*{B59}, b*{B59}, c*{B59}, d*{B59} }}\n"
    )
    result = coverability(net)
    assert result.bounded is None and not result.complete and result.unbounded == ()
    assert "'e' reaches 2305843009213693952 tokens" in result.reason
    assert "represents exactly" in result.explain()
    report = verify(net, VerifyOptions(max_states=1, structural=False))
    assert report.property("bounded").verdict is not Verdict.VIOLATED


def test_coverability_does_not_take_a_large_bounded_count_for_omega() -> None:
    # 'g' doubles (really unbounded) while 'e' is bounded at 2**61: 'e' must never be
    # listed unbounded (it was, and the pump search then raised StopIteration).
    net = _net(
        f"place a = {B59}, g = 1, e\n"
        f"transition pour wait {{ a*{B59} }} signal {{ e*{4 * B59} }}\n"
        f"transition back wait {{ e*{4 * B59} }} signal {{ a*{B59} }}\n"
        "transition grow wait { g } signal { g*2 }\n"
    )
    result = coverability(net)
    assert "e" not in result.unbounded and result.bounded is not True


@pytest.mark.parametrize("start", [2**61, 2**62, 2**63 - 1])
def test_coverability_of_an_initial_count_past_its_range_does_not_raise(start: int) -> None:
    net = _net(f"place a = {start}, e\ntransition t wait {{ a }} signal {{ e }}\n")
    result = coverability(net)
    assert result.bounded is None and "'a' reaches" in result.reason


def test_coverability_still_decides_large_counts_within_its_range() -> None:
    net = _net(
        f"place p = {B59}, q\ntransition t wait {{ p*{B59} }} signal {{ q*{B59} }}\n"
        f"transition u wait {{ q*{B59} }} signal {{ p*{B59} }}\n"
    )
    result = coverability(net)
    assert result.bounded is True and result.bounds == {"p": B59, "q": B59}


# --------------------------------------------------------------------------- 64-bit wrap


def test_weights_too_large_to_count_exactly_are_never_called_bounded() -> None:
    """'e' gains 2**62 tokens a firing: really unbounded. 64-bit sums wrapped and the
    explorer called it bounded with 4 states; now it does not explore such a net."""
    big = 2**62
    text = (
        "mission wrap\nvehicle ROMEO\n"
        f"place a = {big}\nplace b = {big}\nplace e\n"
        f"transition t\n    wait {{ a*{big}, b*{big} }}\n"
        f"    signal {{ e*{big}, a*{big}, b*{big} }}\n"
    )
    net = compile_source(text, "wrap.coral").raise_for_errors()
    report = verify(net, VerifyOptions(structural=False))
    bounded = report.property("bounded")
    assert bounded.verdict is Verdict.INCONCLUSIVE, bounded
    assert "too large to count exactly" in str(report.to_dict())
    # Counts at the limit itself are still explored exactly.
    small = text.replace(str(big), str(2**59))
    assert (
        verify(compile_source(small, "w.coral").raise_for_errors()).property("bounded").verdict
        is not Verdict.PROVEN
    )


def test_a_port_in_non_ascii_digits_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_main([str(POOL_MISSION), "--vehicle", "127.0.0.1:\u0668\u0660"]) == 2
    assert "expected HOST:PORT" in capsys.readouterr().err


@pytest.mark.parametrize("reader", ["fault plan", "key file", "generic settings", "certificate"])
def test_every_file_coral_reads_refuses_a_fifo(tmp_path: Path, reader: str) -> None:
    """Each reader goes through coral_lang.safefile: a FIFO is refused, never waited on."""
    import os

    from analysis.certificate import CertificateError, read_certificate
    from coral_lang.profile import load_bundled_profile
    from runtime.faultplan import FaultPlanError, load_fault_plan
    from runtime.keys import KeyProblem, load_psk
    from runtime.vehicle.generic import SIMULATOR as GENERIC
    from runtime.vehicle.registry import SimulatorError, SimulatorRequest

    fifo = tmp_path / "input"
    os.mkfifo(fifo)
    with pytest.raises((FaultPlanError, KeyProblem, SimulatorError, CertificateError)) as exc:
        if reader == "fault plan":
            load_fault_plan(fifo)
        elif reader == "key file":
            load_psk(fifo, None)
        elif reader == "generic settings":
            GENERIC.create(SimulatorRequest(load_bundled_profile("ROMEO"), config=fifo))
        else:
            read_certificate(fifo)
    assert "not a regular file" in str(exc.value)


@pytest.mark.parametrize(
    ("meta", "says"),
    [
        (
            {"mission_path": "/nonexistent/mission.coral", "profiles": []},
            "names the mission '/nonexistent/mission.coral', which is not a readable file",
        ),
        (
            {"mission_path": str(POOL_MISSION), "profiles": ["p" * 5000], "include_path": [7]},
            "no committed state to resume from",
        ),
    ],
    ids=["missing-mission", "overlong-profile-path"],
)
def test_resume_reads_the_paths_a_log_records_as_data_not_promises(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], meta: dict[str, object], says: str
) -> None:
    """bench/redteam.py: an edited ``mission_path`` gave "file not found" without naming
    the log; a 5,000-character profile path gave an OSError traceback."""
    log = tmp_path / "run" / "controller.sqlite"
    log.parent.mkdir()
    with EventLog.create(log, role="controller", mission="pool", meta=meta):
        pass
    code, err = _resume(log, tmp_path, capsys)
    assert code == 2 and says in err and str(log) in err and "Traceback" not in err
