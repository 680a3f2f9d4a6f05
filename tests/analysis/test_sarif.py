"""SARIF output: valid against the official 2.1.0 schema, and saying the right things."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from analysis.cli import main
from analysis.lint import RULES
from analysis.outcome import FileOutcome
from analysis.sarif import PROPERTY_RULES, SRCROOT, property_rule_id, to_sarif
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_mission
from coral_lang.codes import CODES
from tests.conftest import EXAMPLES, REPO

SCHEMA = Path(__file__).parent / "data" / "sarif-2.1.0.json"
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAULTY = sorted((EXAMPLES / "faulty").glob("*.coral"))


@cache
def _validator() -> jsonschema.Draft4Validator:
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft4Validator.check_schema(schema)
    return jsonschema.Draft4Validator(schema)


def _assert_valid(log: dict[str, Any]) -> None:
    errors = sorted(_validator().iter_errors(log), key=lambda e: list(e.path))
    assert not errors, "\n".join(f"{list(e.path)}: {e.message}" for e in errors[:10])


def _sarif(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, *files: str, code: int
) -> dict[str, Any]:
    """Run ``coral-check --format sarif`` from the repository root; the parsed log."""
    monkeypatch.chdir(REPO)
    out = tmp_path / "out.sarif"
    assert main([*files, "--format", "sarif", "-o", str(out)]) == code
    log: dict[str, Any] = json.loads(out.read_text())
    return log


def _results(log: dict[str, Any]) -> list[dict[str, Any]]:
    results: list[dict[str, Any]] = log["runs"][0]["results"]
    return results


def _region(result_or_location: dict[str, Any]) -> tuple[str, int, int]:
    location = result_or_location.get("locations", [result_or_location])[0]
    physical = location["physicalLocation"]
    region = physical["region"]
    return physical["artifactLocation"]["uri"], region["startLine"], region["startColumn"]


def test_the_vendored_schema_is_the_official_one() -> None:
    schema = json.loads(SCHEMA.read_text())
    assert schema["$schema"] == "http://json-schema.org/draft-04/schema#"
    assert "2.1.0" in schema["title"] and schema["properties"]["version"]["enum"] == ["2.1.0"]
    assert (SCHEMA.parent / "README.md").read_text().count("sarif-2.1.0-rtm.5.json") >= 1


@pytest.mark.slow
@pytest.mark.parametrize("path", [POOL, *FAULTY], ids=lambda p: p.name)
def test_every_example_gives_a_valid_log(
    path: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    relative = str(path.relative_to(REPO))
    log = _sarif(monkeypatch, tmp_path, relative, code=0 if path == POOL else 1)
    _assert_valid(log)
    assert log["version"] == "2.1.0" and len(log["runs"]) == 1
    run = log["runs"][0]
    assert run["originalUriBaseIds"][SRCROOT]["uri"] == REPO.as_uri() + "/"
    for result in _results(log):
        uri, line, col = _region(result)
        assert uri.startswith("examples/") and line >= 1 and col >= 1
        assert result["level"] in ("error", "warning", "note")
    if path == POOL:
        assert _results(log) == [] and run["invocations"][0]["exitCode"] == 0


@pytest.mark.slow
def test_driver_lists_every_rule_once_and_results_point_at_theirs(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    log = _sarif(monkeypatch, tmp_path, *(str(p.relative_to(REPO)) for p in FAULTY), code=1)
    driver = log["runs"][0]["tool"]["driver"]
    assert driver["name"] == "coral-check" and driver["version"]
    assert ":" in driver["informationUri"]
    ids = [rule["id"] for rule in driver["rules"]]
    expected = [*CODES, *RULES, *(rule_id for rule_id, _ in PROPERTY_RULES.values())]
    assert ids == expected and len(set(ids)) == len(ids)
    assert "CORAL-V-deadlock" in ids and "CORAL-V-assert" in ids
    levels = {rule["id"]: rule["defaultConfiguration"]["level"] for rule in driver["rules"]}
    assert levels["CORAL106"] == "error" and levels["CORAL204"] == "warning"
    rule_ids = {result["ruleId"] for result in _results(log)}
    assert {"CORAL106", "CORAL204", "CORAL-V-deadlock", "CORAL-V-bounded"} <= rule_ids
    for result in _results(log):
        assert driver["rules"][result["ruleIndex"]]["id"] == result["ruleId"]
    assert property_rule_id("assert:3") == "CORAL-V-assert"


def test_diagnostics_keep_file_line_and_column(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    files = ["examples/faulty/dead_transition.coral", "examples/faulty/unhandled_reply.coral"]
    log = _sarif(monkeypatch, tmp_path, *files, code=1)
    by_rule = {r["ruleId"]: r for r in _results(log)}
    assert _region(by_rule["CORAL204"]) == ("examples/faulty/dead_transition.coral", 10, 14)
    assert by_rule["CORAL204"]["level"] == "warning"
    assert _region(by_rule["CORAL106"]) == ("examples/faulty/unhandled_reply.coral", 20, 20)
    assert by_rule["CORAL106"]["level"] == "error"
    assert "note: map the reply kind" in by_rule["CORAL106"]["message"]["text"]
    location = by_rule["CORAL106"]["locations"][0]["physicalLocation"]
    assert location["artifactLocation"]["uriBaseId"] == SRCROOT
    assert location["region"]["endColumn"] == 26  # exclusive, as in SARIF
    dead = by_rule["CORAL-V-dead-transitions"]
    assert dead["level"] == "error" and dead["properties"]["verdict"] == "violated"
    assert "record_dock" in dead["message"]["text"]


def test_a_deadlock_trace_is_a_code_flow_over_the_source(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    log = _sarif(monkeypatch, tmp_path, "examples/faulty/deadlock.coral", code=1)
    result, *others = [r for r in _results(log) if r["ruleId"] == "CORAL-V-deadlock"]
    steps = result["codeFlows"][0]["threadFlows"][0]["locations"]
    net = compile_mission(EXAMPLES / "faulty" / "deadlock.coral")
    deadlock = verify(net, VerifyOptions(structural=False)).property("deadlock")
    assert len(others) == len(deadlock.more_evidence)  # one result per dead marking
    evidence = deadlock.evidence
    assert evidence is not None and len(evidence.trace) == 5
    lines = [s.span.line for s in evidence.trace if s.span]
    assert [_region(step["location"])[1] for step in steps] == lines
    assert sorted(lines) == [19, 23, 25, 31, 33]  # begin, both commands, both errors
    assert [step["executionOrder"] for step in steps] == [1, 2, 3, 4, 5]
    assert [step["location"]["message"]["text"] for step in steps] == [
        f"{s.number}. {s.description}" for s in evidence.trace
    ]
    assert result["codeFlows"][0]["message"]["text"] == "reaches { abort*2 }"
    assert _region(result)[1] == lines[-1]  # where the deadlock is reached: the last step


@pytest.mark.slow
def test_an_unbounded_place_shows_its_pumping_loop(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    log = _sarif(monkeypatch, tmp_path, "examples/faulty/unbounded.coral", code=1)
    (result,) = [r for r in _results(log) if r["ruleId"] == "CORAL-V-bounded"]
    texts = [
        step["location"]["message"]["text"]
        for step in result["codeFlows"][0]["threadFlows"][0]["locations"]
    ]
    assert any("then repeat:" in text for text in texts)
    assert "lap_logged" in result["message"]["text"]


def test_unreadable_files_are_notifications_and_outside_files_absolute(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    outside = tmp_path / "elsewhere.coral"
    outside.write_text((EXAMPLES / "faulty" / "deadlock.coral").read_text())
    missing = str(tmp_path / "missing.coral")
    log = _sarif(monkeypatch, tmp_path, str(outside), missing, code=2)
    _assert_valid(log)
    invocation = log["runs"][0]["invocations"][0]
    assert invocation["executionSuccessful"] is False and invocation["exitCode"] == 2
    (notice,) = invocation["toolExecutionNotifications"]
    assert notice["level"] == "error" and "no such file" in notice["message"]["text"]
    uri, _, _ = _region(_results(log)[0])
    assert uri == outside.resolve().as_uri()


def test_to_sarif_without_results_is_valid() -> None:
    log: dict[str, Any] = to_sarif(
        [FileOutcome("x.coral", input_error="no such file")], tool_version="0+unknown"
    )
    _assert_valid(log)
    assert _results(log) == []


def test_the_schema_refuses_a_broken_log(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    log = _sarif(monkeypatch, tmp_path, "examples/faulty/deadlock.coral", code=1)
    result = _results(log)[0]
    result["level"] = "fatal"
    result["locations"][0]["physicalLocation"]["region"]["startColumn"] = 0
    messages = [e.message for e in _validator().iter_errors(log)]
    assert any("'fatal' is not one of" in m for m in messages)
    assert any("0 is less than the minimum of 1" in m for m in messages)
