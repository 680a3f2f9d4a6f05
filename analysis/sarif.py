"""SARIF 2.1.0 output of ``coral-check`` (``--format sarif``), for code-scanning services.

One run, one tool. Its rules are every diagnostic code (CORAL0xx and CORAL1xx from the
compiler, CORAL2xx from lint) and one rule per verified property, ``CORAL-V-<property>``
(`PROPERTY_RULES`; all of a mission's assertions share ``CORAL-V-assert``). Results:

* each diagnostic, at its file, line and column, with its severity as the level;
* each property that is not proven: ``error`` when violated, ``warning`` when
  inconclusive, located where the property is written (assertions) or where it fails
  (the transition that reaches the deadlock, the dead transitions, the unbounded
  places...). A counterexample is a code flow: one thread flow whose locations are the
  trace's steps, each pointing at the source line of the transition fired; the loop of
  an infinite run (a lasso) follows at ``nestingLevel`` 1, each step's ``properties``
  saying ``"loop": true``. A property the mission does not require (``terminates``
  without ``require termination``) is a ``warning`` when violated, a ``note`` when
  inconclusive. The ``deadlock`` property gives one result per dead marking listed.

Paths are relative to the current directory under ``uriBaseId`` ``%SRCROOT%``, as
GitHub code scanning expects; files outside it get absolute ``file:`` URIs. Columns
count Unicode code points (``columnKind``), as coral's positions do.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import quote

from analysis.lint import RULES
from analysis.outcome import FileOutcome, worst_exit_code
from analysis.report import Evidence, PropertyResult, Step, Verdict, element_span
from coral_lang.codes import CODES
from coral_lang.diagnostics import Diagnostic, Severity, Span
from coral_lang.net import Net, format_tokens

SARIF_VERSION = "2.1.0"
SARIF_SCHEMA_URI = "https://json.schemastore.org/sarif-2.1.0.json"
SRCROOT = "%SRCROOT%"
FALLBACK_INFORMATION_URI = "urn:coral:coral-check"
"""Used when the installed package declares no project URL (``[project.urls]``)."""

PROPERTY_RULES: dict[str, tuple[str, str]] = {
    "bounded": ("CORAL-V-bounded", "every place has a finite bound"),
    "deadlock": (
        "CORAL-V-deadlock",
        "every reachable dead marking is a declared final marking",
    ),
    "final_reachable": (
        "CORAL-V-final-reachable",
        "some declared final marking is reachable",
    ),
    "dead_transitions": (
        "CORAL-V-dead-transitions",
        "every transition fires in some reachable marking",
    ),
    "never_marked_places": (
        "CORAL-V-never-marked-places",
        "every mission place holds a token in some reachable marking",
    ),
    "resource_conflicts": (
        "CORAL-V-resource-conflicts",
        "no two commands in flight drive one vehicle resource",
    ),
    "no_engine_cycle": (
        "CORAL-V-no-engine-cycle",
        "no cycle of reachable markings is made only of engine transitions",
    ),
    "final_always_reachable": (
        "CORAL-V-final-always-reachable",
        "some declared final marking is reachable from every reachable marking",
    ),
    "terminates": (
        "CORAL-V-terminates",
        "every weakly fair run ends in a declared final marking",
    ),
    "require": ("CORAL-V-require", "the mission's requirement can be verified"),
    "assert": ("CORAL-V-assert", "the mission's own assertion holds"),
    "timed": (
        "CORAL-V-timed",
        "the mission's time is bounded and its query time-outs are adequate (verify --timed)",
    ),
}
"""Property key (``assert:N`` -> ``assert``, ``timed:timeout:T`` -> ``timed``) -> (rule
id, what the property says)."""

_LEVELS = {Severity.ERROR: "error", Severity.WARNING: "warning", Severity.NOTE: "note"}
_VERDICT_LEVELS = {Verdict.VIOLATED: "error", Verdict.INCONCLUSIVE: "warning"}
_WARNING_LEVELS = {Verdict.VIOLATED: "warning", Verdict.INCONCLUSIVE: "note"}

Json = dict[str, object]


def property_rule_id(key: str) -> str:
    """The SARIF rule id of a property key, e.g. ``assert:2`` -> ``CORAL-V-assert``."""
    return PROPERTY_RULES[key.split(":", 1)[0]][0]


def information_uri() -> str:
    """The project's documentation or home page from the installed package's metadata,
    or `FALLBACK_INFORMATION_URI` when it declares none."""
    from importlib import metadata

    try:
        entries = metadata.metadata("coral").get_all("Project-URL") or []
    except metadata.PackageNotFoundError:
        entries = []
    urls: dict[str, str] = {}
    for entry in entries:
        label, _, url = str(entry).partition(",")
        urls[label.strip().lower()] = url.strip()
    for label in ("documentation", "homepage", "source", "repository"):
        if label in urls:
            return urls[label]
    return FALLBACK_INFORMATION_URI


def rules() -> list[Json]:
    """Every rule coral-check can report, in a fixed order (compile, lint, properties)."""
    described: list[Json] = []
    for code, summary in CODES.items():
        described.append(_rule(code, summary, "error", "compile"))
    for rule in RULES.values():
        described.append(_rule(rule.code, rule.summary, _LEVELS[rule.severity], "lint"))
    for key, (rule_id, summary) in PROPERTY_RULES.items():
        described.append(_rule(rule_id, summary, "error", "verification", key))
    return described


def _rule(rule_id: str, summary: str, level: str, kind: str, key: str = "") -> Json:
    rule: Json = {
        "id": rule_id,
        "shortDescription": {"text": summary},
        "defaultConfiguration": {"level": level},
        "properties": {"tags": ["coral", kind]},
    }
    if key:
        rule["fullDescription"] = {
            "text": f"coral-check verify decides the property '{key}': {summary}. "
            "Violated: a counterexample exists (the code flow replays it). "
            "Inconclusive: the budgets ran out before it was decided."
        }
    return rule


class _Locator:
    """Turns file names and spans into SARIF locations relative to ``base``."""

    def __init__(self, base: Path) -> None:
        self.base = base.resolve()

    def artifact(self, file: str) -> Json:
        absolute = Path(file).resolve()  # relative names are relative to the cwd
        try:
            relative = absolute.relative_to(self.base)
        except ValueError:
            return {"uri": absolute.as_uri()}
        return {"uri": quote(relative.as_posix()), "uriBaseId": SRCROOT}

    def location(self, span: Span | None, file: str, message: str = "") -> Json:
        region: Json = {"startLine": 1, "startColumn": 1}
        if span is not None:
            file = span.file
            region = {"startLine": span.line, "startColumn": span.col}
            if span.end_line > span.line or (
                span.end_line == span.line and span.end_col > span.col
            ):
                region["endLine"] = span.end_line
                region["endColumn"] = span.end_col
        location: Json = {
            "physicalLocation": {"artifactLocation": self.artifact(file), "region": region}
        }
        if message:
            location["message"] = {"text": message}
        return location


def _diagnostic_result(d: Diagnostic, outcome: FileOutcome, locator: _Locator) -> Json:
    text = d.message + "".join(f"\nnote: {note}" for note in d.notes)
    return {
        "ruleId": d.code,
        "level": _LEVELS[d.severity],
        "message": {"text": text},
        "locations": [locator.location(d.span, outcome.path)],
    }


def _spans_of(names: Iterable[str], net: Net) -> list[Span]:
    return [span for name in names if (span := element_span(net, name)) is not None]


def _where(prop: PropertyResult, net: Net | None) -> list[Span]:
    """Where a failed property shows: its own text, else the elements it names, else
    the last step of its counterexample."""
    if prop.span is not None:
        return [prop.span]
    spans: list[Span] = []
    if net is not None:
        if prop.key == "final_reachable":
            spans = [f.span for f in net.finals if f.span is not None]
        else:  # unbounded places, dead transitions, commands in conflict...
            spans = _spans_of(prop.items, net)
    if not spans and prop.evidence is not None:
        steps = [*prop.evidence.trace, *prop.evidence.loop]
        spans = [s.span for s in reversed(steps) if s.span is not None][:1]
    unique: list[Span] = []
    for span in spans:
        if span not in unique:
            unique.append(span)
    return unique


def _code_flow(evidence: Evidence, outcome: FileOutcome, locator: _Locator) -> Json | None:
    steps: list[tuple[Step, str]] = [(s, "") for s in evidence.trace]
    steps += [(s, "then repeat: ") for s in evidence.loop]
    if not steps:
        return None
    locations = []
    for step, prefix in steps:
        text = f"{step.number}. {prefix}{step.description}"
        if step.span is not None:
            location = locator.location(step.span, outcome.path, text)
        else:
            location = {"message": {"text": text}}
        entry: Json = {"location": location, "executionOrder": step.number}
        if prefix:  # the loop of a lasso (or of a pumping sequence)
            entry["nestingLevel"] = 1
            entry["properties"] = {"loop": True}
        locations.append(entry)
    flow: Json = {"threadFlows": [{"locations": locations}]}
    summary = evidence.note
    if evidence.marking is not None:
        reached = format_tokens(evidence.marking.items())
        if evidence.loop:
            first, last = evidence.loop[0].number, evidence.loop[-1].number
            reached = f"steps {first}-{last} repeat forever from {reached}"
        else:
            reached = f"reaches {reached}"
        summary = reached + (f"; {summary}" if summary else "")
    if summary:
        flow["message"] = {"text": summary}
    return flow


def _property_results(prop: PropertyResult, outcome: FileOutcome, locator: _Locator) -> list[Json]:
    """One result for a failed property, and one more per further counterexample
    (every other dead marking of ``deadlock``), each with its code flow."""
    text = f"{prop.title}: {prop.verdict.value} [{prop.method}]. {prop.detail}".rstrip(". ")
    if prop.warning:
        text += " (not required: a warning)"
    spans = _where(prop, outcome.net)
    locations = [locator.location(s, outcome.path) for s in spans] or [
        locator.location(None, outcome.path)
    ]
    level = (_WARNING_LEVELS if prop.warning else _VERDICT_LEVELS)[prop.verdict]
    properties: Json = {"property": prop.key, "verdict": prop.verdict.value}
    if not prop.required:
        properties["required"] = False
    result: Json = {
        "ruleId": property_rule_id(prop.key),
        "level": level,
        "message": {"text": text},
        "locations": locations,
        "properties": properties,
    }
    if prop.evidence is not None:
        flow = _code_flow(prop.evidence, outcome, locator)
        if flow is not None:
            result["codeFlows"] = [flow]
    results = [result]
    total = 1 + len(prop.more_evidence) + prop.omitted
    for number, evidence in enumerate(prop.more_evidence, start=2):
        reached = format_tokens((evidence.marking or {}).items())
        steps = [s.span for s in evidence.trace if s.span is not None]
        more: Json = {
            "ruleId": property_rule_id(prop.key),
            "level": level,
            "message": {
                "text": f"{prop.title}: {prop.verdict.value} [{prop.method}]. "
                f"Counterexample {number} of {total}: {reached} is reachable in "
                f"{len(evidence.trace)} step(s)"
            },
            "locations": [locator.location(steps[-1] if steps else None, outcome.path)],
            "properties": {**properties, "counterexample": number},
        }
        flow = _code_flow(evidence, outcome, locator)
        if flow is not None:
            more["codeFlows"] = [flow]
        results.append(more)
    return results


def to_sarif(
    outcomes: Sequence[FileOutcome],
    *,
    tool_version: str,
    info_uri: str | None = None,
    base_dir: Path | None = None,
) -> Json:
    """The SARIF log of a run (a JSON-ready dict).

    Args:
        outcomes: The files checked, in order.
        tool_version: Goes to ``tool.driver.version``.
        info_uri: ``tool.driver.informationUri``; default `information_uri()`.
        base_dir: What ``%SRCROOT%`` stands for; default the current directory.
    """
    locator = _Locator(base_dir or Path.cwd())
    all_rules = rules()
    index = {str(rule["id"]): i for i, rule in enumerate(all_rules)}
    results: list[Json] = []
    notifications: list[Json] = []
    for outcome in outcomes:
        if outcome.input_error is not None:
            notifications.append(
                {
                    "level": "error",
                    "message": {"text": f"cannot read {outcome.path}: {outcome.input_error}"},
                    "locations": [
                        {"physicalLocation": {"artifactLocation": locator.artifact(outcome.path)}}
                    ],
                }
            )
            continue
        results.extend(_diagnostic_result(d, outcome, locator) for d in outcome.diagnostics)
        if outcome.report is not None:
            for p in outcome.report.properties:
                if p.verdict is not Verdict.PROVEN:
                    results.extend(_property_results(p, outcome, locator))
    for result in results:
        rule_id = str(result["ruleId"])
        if rule_id in index:
            result["ruleIndex"] = index[rule_id]
    run: Json = {
        "tool": {
            "driver": {
                "name": "coral-check",
                "version": tool_version,
                "informationUri": info_uri or information_uri(),
                "rules": all_rules,
            }
        },
        "originalUriBaseIds": {SRCROOT: {"uri": locator.base.as_uri() + "/"}},
        "invocations": [
            {
                "executionSuccessful": not notifications,
                "exitCode": worst_exit_code(o.exit_code() for o in outcomes),
                "toolExecutionNotifications": notifications,
            }
        ],
        "columnKind": "unicodeCodePoints",
        "results": results,
        "properties": {
            "files": [
                {
                    "file": o.path,
                    "status": o.status(),
                    "digest": o.net.digest() if o.net is not None else None,
                }
                for o in outcomes
            ]
        },
    }
    return {"$schema": SARIF_SCHEMA_URI, "version": SARIF_VERSION, "runs": [run]}
