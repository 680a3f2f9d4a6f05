"""One file's outcome: its status, its exit code, its JSON form."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from analysis.outcome import (
    EXIT_ERRORS,
    EXIT_INCONCLUSIVE,
    EXIT_OK,
    EXIT_USAGE,
    JSON_COMMANDS,
    JSON_SCHEMA_VERSION,
    FileOutcome,
    diagnostic_to_dict,
    make_outcome,
    to_json_document,
)
from analysis.pipeline import CheckOptions, check_file
from analysis.report import PropertyResult, Report, StateSpaceFigures, Verdict
from analysis.verify import VerifyOptions
from coral_lang.diagnostics import Diagnostic, Severity, Span
from tests.analysis.nets import mutex
from tests.conftest import EXAMPLES, REPO

NET = mutex()


def _report(*verdicts: Verdict) -> Report:
    figures = StateSpaceFigures(1, 0, 1, 1, {}, True, None, False, 0.0, 0.0)
    properties = [
        PropertyResult(key, "t", Verdict.PROVEN, "m", "d") for key in ("bounded", "deadlock")
    ]
    properties += [PropertyResult(f"assert:{i}", "t", v, "m", "d") for i, v in enumerate(verdicts)]
    return Report("n", "sha256:x", (), figures, properties)


def _diag(severity: Severity, line: int = 1) -> Diagnostic:
    return Diagnostic(severity, "CORAL202", "m", Span("a.coral", line, 2, line, 3))


def test_status_and_exit_code_of_each_kind_of_outcome() -> None:
    cases = [
        (FileOutcome("a", input_error="no such file"), "unreadable", EXIT_USAGE),
        (FileOutcome("a", (_diag(Severity.ERROR),)), "errors", EXIT_ERRORS),
        (FileOutcome("a"), "errors", EXIT_ERRORS),  # no net and no report
        (FileOutcome("a", (_diag(Severity.WARNING),), net=NET), "clean", EXIT_OK),
        (FileOutcome("a", net=NET, report=_report(Verdict.PROVEN)), "proven", EXIT_OK),
        (
            FileOutcome("a", net=NET, report=_report(Verdict.PROVEN, Verdict.INCONCLUSIVE)),
            "inconclusive",
            EXIT_INCONCLUSIVE,
        ),
        (
            FileOutcome("a", net=NET, report=_report(Verdict.INCONCLUSIVE, Verdict.VIOLATED)),
            "violated",
            EXIT_ERRORS,
        ),
        (
            FileOutcome("a", (_diag(Severity.ERROR),), net=NET, report=_report(Verdict.PROVEN)),
            "errors",
            EXIT_ERRORS,
        ),
    ]
    for outcome, status, code in cases:
        assert (outcome.status(), outcome.exit_code()) == (status, code), outcome


def test_diagnostics_are_sorted_and_flattened() -> None:
    outcome = make_outcome("a.coral", [_diag(Severity.WARNING, 9), _diag(Severity.NOTE, 2)])
    assert [d.span.line for d in outcome.diagnostics if d.span] == [2, 9]
    positionless = Diagnostic(Severity.ERROR, "CORAL004", "cannot read", None)
    assert diagnostic_to_dict(positionless, "a.coral") == {
        "code": "CORAL004",
        "severity": "error",
        "file": "a.coral",
        "line": None,
        "col": None,
        "end_line": None,
        "end_col": None,
        "message": "cannot read",
        "notes": [],
    }


def test_json_document_takes_the_worst_exit_code() -> None:
    outcomes = [
        FileOutcome("a", net=NET, report=_report(Verdict.INCONCLUSIVE)),
        FileOutcome("b", net=NET, report=_report(Verdict.PROVEN)),
    ]
    document = to_json_document(outcomes, "check", "1.2.3")
    assert document["exit_code"] == EXIT_INCONCLUSIVE
    assert document["tool"] == {"name": "coral-check", "version": "1.2.3"}
    files = document["files"]
    assert isinstance(files, list) and [f["status"] for f in files] == ["inconclusive", "proven"]


# -- the one JSON document, against its schema ------------------------------------------

SCHEMA_FILE = REPO / "docs" / "schema" / "coral-check.schema.json"
FAST = VerifyOptions(structural=False)


def _validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _valid(document: dict[str, object]) -> dict[str, object]:
    """``document`` after a JSON round trip, once the schema accepts it."""
    data: dict[str, object] = json.loads(json.dumps(document))
    errors = sorted(_validator().iter_errors(data), key=lambda e: list(e.path))
    assert not errors, [f"{list(e.path)}: {e.message}" for e in errors[:5]]
    return data


def _files(document: dict[str, object]) -> list[dict[str, Any]]:
    files = document["files"]
    assert isinstance(files, list)
    return files


def test_schema_version_2_names_every_command() -> None:
    assert JSON_SCHEMA_VERSION == 2 and JSON_COMMANDS == ("check", "lint", "verify")
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    assert schema["properties"]["schema_version"]["const"] == JSON_SCHEMA_VERSION
    assert schema["properties"]["command"]["enum"] == list(JSON_COMMANDS)
    with pytest.raises(ValueError, match="expected one of check, lint, verify"):
        to_json_document([], "query", "1")


@pytest.mark.slow
def test_real_outputs_of_every_command_validate(tmp_path: Path) -> None:
    pool = EXAMPLES / "pool_mission" / "pool_mission.coral"
    broken = tmp_path / "broken.coral"
    broken.write_text("mission m\nvehicle ROMEO\nplace start = 1 done\n")
    files = [pool, EXAMPLES / "faulty" / "deadlock.coral", broken, tmp_path / "gone.coral"]
    checked = [check_file(f, CheckOptions(verify=FAST)) for f in files]
    data = _valid(to_json_document(checked, "check", "0"))
    entries = _files(data)
    assert [f["status"] for f in entries] == ["proven", "violated", "errors", "unreadable"]
    assert data["exit_code"] == EXIT_USAGE and data["schema_version"] == 2
    # A violated property: its trace, its located findings.
    deadlock = next(p for p in entries[1]["report"]["properties"] if p["key"] == "deadlock")
    assert deadlock["evidence"]["trace"] and deadlock["findings"]
    assert all(f["location"]["file"].endswith("deadlock.coral") for f in deadlock["findings"])
    assert entries[2]["diagnostics"][0]["code"].startswith("CORAL")
    assert entries[3]["error"] == "no such file" and entries[3]["report"] is None
    # lint: no reports; verify: one file, the same shape.
    linted = _valid(to_json_document([check_file(pool, CheckOptions())], "lint", "0"))
    assert _files(linted)[0]["status"] == "clean" and _files(linted)[0]["report"] is None
    verified = _valid(to_json_document(checked[1:2], "verify", "0"))
    assert verified["command"] == "verify" and _files(verified)[0]["exit_code"] == EXIT_ERRORS


def test_inconclusive_and_part_outcomes_validate(tmp_path: Path) -> None:
    retry = EXAMPLES / "faulty" / "retry_forever.coral"
    cut = check_file(retry, CheckOptions(verify=VerifyOptions(structural=False, max_states=3)))
    part = check_file(EXAMPLES / "pool_mission" / "abort.coral", CheckOptions())
    data = _valid(to_json_document([cut, part], "check", "0"))
    first, second = _files(data)
    assert first["status"] == "inconclusive" and first["exit_code"] == EXIT_INCONCLUSIVE
    assert second["status"] == "part" and second["part_of"].endswith("pool_mission.coral")


def test_the_schema_refuses_what_it_must() -> None:
    good = to_json_document([FileOutcome("a", input_error="no such file")], "lint", "0")
    _valid(good)
    validator = _validator()
    for broken in (
        {**good, "schema_version": 1},
        {**good, "command": "query"},
        {**good, "files": [{**_files(good)[0], "status": "fine"}]},
        {**good, "files": [{**_files(good)[0], "error": None}]},  # unreadable needs a reason
        {k: v for k, v in good.items() if k != "exit_code"},
    ):
        assert not validator.is_valid(json.loads(json.dumps(broken))), broken


def test_every_member_of_the_schema_is_documented() -> None:
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    doc = (REPO / "docs" / "json.md").read_text(encoding="utf-8")
    members: set[str] = set()

    def walk(node: object) -> None:
        """Collect the member names of a schema node and of every schema inside it."""
        if isinstance(node, list):
            for value in node:
                walk(value)
            return
        if not isinstance(node, dict):
            return
        named = node.get("properties", {})
        members.update(named)
        for value in named.values():
            walk(value)
        for key in ("items", "additionalProperties", "if", "then", "else"):
            walk(node.get(key))
        for key in ("oneOf", "anyOf", "allOf"):
            walk(node.get(key, []))
        for value in node.get("$defs", {}).values():
            walk(value)

    walk(schema)
    assert {"files", "part_of", "findings", "more_evidence"} <= members
    missing = sorted(m for m in members if f"`{m}`" not in doc and f'"{m}"' not in doc)
    assert not missing, f"docs/json.md does not document {missing}"
