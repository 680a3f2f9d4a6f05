"""What verification found: one verdict per property, with the evidence and the method.

A verdict is one of three words and nothing else:

* ``proven``: the property holds in every reachable marking; ``method`` says how it
  was shown (the complete explicit state space, the state equation, coverability...);
* ``violated``: a counterexample exists and is attached as evidence (a firing
  sequence from the initial marking that anyone can replay);
* ``inconclusive``: neither could be shown within the budgets; ``detail`` says why.

The JSON form (`Report.to_dict`) is the ``report`` member of a file in coral-check's
one JSON document (``docs/json.md``) and is stable: keys are only ever added.

Every finding of a property that is not proven is located in the source
(`located_findings`): the text report prints each as ``file:line:col: message``, as
compilers and SARIF do, and every trace as numbered steps with their lines.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from coral_lang.diagnostics import Span
from coral_lang.net import Net, TransitionKind, format_tokens

if TYPE_CHECKING:
    from analysis.statespace import StateSpace
    from analysis.timed.results import TimedReport
    from analysis.timed.schedule import ScheduledCommand, TimedSchedule

REPORT_FORMAT_VERSION = 1
MAX_TRACE_STEPS = 50
"""Steps of one trace a text or HTML report prints; the JSON document holds them all."""
MAX_FINDINGS_SHOWN = 50
"""Located findings of one property a text report prints (a net with hundreds of dead
transitions would bury the rest); the JSON document lists them all."""


class Verdict(enum.Enum):
    """The three possible answers for a property."""

    PROVEN = "proven"
    VIOLATED = "violated"
    INCONCLUSIVE = "inconclusive"


_SEVERITY = {Verdict.PROVEN: 0, Verdict.INCONCLUSIVE: 1, Verdict.VIOLATED: 2}


@dataclass(frozen=True)
class Step:
    """One firing in a trace: which transition, what it means, where it was written."""

    number: int
    transition: str
    kind: str
    description: str
    span: Span | None = None
    command: str | None = None
    reply: str | None = None

    def to_dict(self) -> dict[str, object]:
        """JSON form."""
        return {
            "step": self.number,
            "transition": self.transition,
            "kind": self.kind,
            "description": self.description,
            "command": self.command,
            "reply": self.reply,
            "location": self.span.to_dict() if self.span else None,
        }

    def render(self) -> str:
        """E.g. ``  3. check_depth: DEPTH? replied timeout   (phase1.coral:30)``."""
        where = f"   ({self.span.file}:{self.span.line})" if self.span else ""
        return f"{self.number:4d}. {self.description}{where}"


def make_trace(net: Net, transitions: Sequence[int], start: int = 1) -> tuple[Step, ...]:
    """Steps for a sequence of transition indices of ``net``."""
    steps = []
    for offset, index in enumerate(transitions):
        tr = net.transitions[index]
        command = None
        if tr.kind is TransitionKind.COMMAND and tr.command is not None:
            command = tr.command.name
        elif tr.kind is TransitionKind.REPLY:
            command = tr.label or None
        steps.append(
            Step(
                number=start + offset,
                transition=tr.name,
                kind=tr.kind.value,
                description=tr.describe(),
                span=tr.span,
                command=command,
                reply=tr.reply,
            )
        )
    return tuple(steps)


def witness(space: StateSpace, state: int, note: str = "") -> Evidence:
    """The trace ``space`` found to ``state`` (shortest unless reduced), and its marking."""
    net = space.net
    return Evidence(
        trace=make_trace(net, space.trace_to(state)),
        marking=net.marking_dict(space.marking(state)),
        note=note,
    )


@dataclass(frozen=True)
class Evidence:
    """Why a verdict holds: a trace to a marking, or a pumping loop, or an explanation."""

    trace: tuple[Step, ...] = ()
    marking: dict[str, int] | None = None
    loop: tuple[Step, ...] = ()
    note: str = ""

    def to_dict(self) -> dict[str, object]:
        """JSON form."""
        return {
            "trace": [s.to_dict() for s in self.trace],
            "marking": self.marking,
            "loop": [s.to_dict() for s in self.loop],
            "note": self.note,
        }


@dataclass(frozen=True)
class PropertyResult:
    """The verdict on one property.

    Attributes:
        key: Stable identifier: ``deadlock``, ``bounded``, ``final_reachable``,
            ``dead_transitions``, ``never_marked_places``, ``resource_conflicts``,
            ``no_engine_cycle``, ``final_always_reachable``, ``terminates`` (see
            `analysis.termination`), or ``assert:N`` for the N-th assertion of the
            mission (from 1).
        title: What the property says, for people.
        verdict: proven, violated or inconclusive.
        method: What decided it.
        detail: One or two sentences: the figure, the reason, the limit that was hit.
        evidence: Trace or loop when violated (or a witness when a reachability
            property is proven).
        span: Where the property was written (assertions).
        items: Names involved (unbounded places, dead transitions, ...).
        more_evidence: Further counterexamples after ``evidence``, each on its own
            (``deadlock``: every other dead non-final marking with its shortest trace,
            up to ``VerifyOptions.max_deadlocks`` in all).
        omitted: How many more counterexamples were found but not listed.
        required: Whether the property counts towards the report's verdict, exit code
            and certificate. A property that is not required (``terminates`` without
            ``require termination``) and not proven is a *warning*.
    """

    key: str
    title: str
    verdict: Verdict
    method: str
    detail: str
    evidence: Evidence | None = None
    span: Span | None = None
    items: tuple[str, ...] = ()
    more_evidence: tuple[Evidence, ...] = ()
    omitted: int = 0
    required: bool = True

    @property
    def warning(self) -> bool:
        """Not proven, but not required either: shown, never failing."""
        return not self.required and self.verdict is not Verdict.PROVEN

    def to_dict(self) -> dict[str, object]:
        """JSON form."""
        return {
            "key": self.key,
            "title": self.title,
            "verdict": self.verdict.value,
            "method": self.method,
            "detail": self.detail,
            "items": list(self.items),
            "location": self.span.to_dict() if self.span else None,
            "evidence": self.evidence.to_dict() if self.evidence else None,
            "more_evidence": [e.to_dict() for e in self.more_evidence],
            "omitted": self.omitted,
            "required": self.required,
        }


@dataclass(frozen=True)
class Finding:
    """One thing a property found, where it is written: a dead transition, an
    unbounded place, the transition that reaches a deadlock...

    Attributes:
        message: What is wrong there, e.g. ``transition 'surface' can never fire``.
        span: Where in the source; None when the net has no position for it (a PNML
            model, a deadlock in the initial marking).
    """

    message: str
    span: Span | None = None

    def render(self) -> str:
        """``file:line:col: message``, as compilers and SARIF locate findings."""
        return f"{self.span}: {self.message}" if self.span is not None else self.message

    def to_dict(self) -> dict[str, object]:
        """JSON form."""
        return {"message": self.message, "location": self.span.to_dict() if self.span else None}


def element_span(net: Net | None, name: str) -> Span | None:
    """Where the place or transition ``name`` of ``net`` is written, if known."""
    if net is None:
        return None
    # by the net's name indexes: `Net.place_names` builds a tuple of all names, and a
    # report on an incomplete search of a wide net locates thousands of elements
    # (9,000 of 10,000: 28 s)
    for element in (net.place, net.transition):
        try:
            return element(name).span
        except KeyError:
            continue
    return None


def _last_span(evidence: Evidence) -> Span | None:
    steps = [*evidence.trace, *evidence.loop]
    return next((s.span for s in reversed(steps) if s.span is not None), None)


def _reached(evidence: Evidence) -> str:
    steps = len(evidence.trace)
    marking = _format_marking(evidence.marking) if evidence.marking is not None else "it"
    return f"{marking} reached here, after {steps} step{'' if steps == 1 else 's'}"


def located_findings(prop: PropertyResult, net: Net | None) -> list[Finding]:
    """The findings of a property that is not proven, each located in the source
    (one per dead transition, unbounded place, dead marking...; none when proven).

    The locations are SARIF's (`analysis.sarif`): the property's own text (an
    assertion), else the net elements it names, else the last step of its trace.
    Without the ``net`` the elements a property names have no location.
    """
    if prop.verdict is Verdict.PROVEN:
        return []
    sure = prop.verdict is Verdict.VIOLATED
    key = prop.key.split(":", 1)[0]
    found: list[Finding] = []
    if key == "dead_transitions":
        text = "can never fire" if sure else "was not seen firing (search incomplete)"
        found = [Finding(f"transition '{n}' {text}", element_span(net, n)) for n in prop.items]
    elif key == "never_marked_places":
        text = "never holds a token" if sure else "was not seen marked (search incomplete)"
        found = [Finding(f"place '{n}' {text}", element_span(net, n)) for n in prop.items]
    elif key == "bounded":
        text = "is unbounded" if sure else "may be unbounded"
        found = [Finding(f"place '{n}' {text}", element_span(net, n)) for n in prop.items]
    elif key == "resource_conflicts" and prop.items:
        for name in prop.items:
            others = ", ".join(f"'{o}'" for o in prop.items if o != name) or "itself"
            found.append(
                Finding(
                    f"command of transition '{name}' in flight together with {others}, "
                    "on one vehicle resource",
                    element_span(net, name),
                )
            )
    elif key == "deadlock":
        for evidence in (prop.evidence, *prop.more_evidence):
            if evidence is not None and evidence.marking is not None:
                found.append(Finding(f"dead marking {_reached(evidence)}", _last_span(evidence)))
    elif key == "final_reachable" and sure and net is not None:
        found = [
            Finding(f"final marking {_format_marking(dict(f.tokens))} is never reached", f.span)
            for f in net.finals
        ]
    if found:
        return found
    span = prop.span
    if span is None and prop.evidence is not None:
        span = _last_span(prop.evidence)
    word = prop.verdict.value if prop.required else f"{prop.verdict.value}, not required"
    return [Finding(f"{word}: {prop.title}", span)]


@dataclass(frozen=True)
class StateSpaceFigures:
    """Size of the explored state space (of the reduced graph when ``reduced``)."""

    states: int
    edges: int
    max_tokens_place: int
    max_tokens_marking: int
    place_bounds: dict[str, int]
    complete: bool
    stopped_reason: str | None
    reduced: bool
    seconds: float
    bytes_per_state: float
    """What a stored state really cost: the growth of the process's peak resident
    memory over the search (peak RSS after it minus RSS before it), per state."""
    stored_bytes_per_state: float = 0.0
    """What the explorer's own tables (keys, hash table, arriving transitions) take, per
    state: less than `bytes_per_state`, which also counts temporaries and the
    allocator's slack."""
    reduction_note: str | None = None
    method: str = "explicit"
    """Which method produced these figures: "explicit" (the explicit search, reduced
    when `reduced`) or "symbolic" (a decision diagram: `edges` and the bytes per state
    are then 0)."""

    def to_dict(self) -> dict[str, object]:
        """JSON form."""
        return {
            "method": self.method,
            "states": self.states,
            "edges": self.edges,
            "max_tokens_place": self.max_tokens_place,
            "max_tokens_marking": self.max_tokens_marking,
            "place_bounds": self.place_bounds,
            "complete": self.complete,
            "stopped_reason": self.stopped_reason,
            "reduced": self.reduced,
            "reduction_note": self.reduction_note,
            "seconds": round(self.seconds, 6),
            "bytes_per_state": round(self.bytes_per_state, 2),
            "stored_bytes_per_state": round(self.stored_bytes_per_state, 2),
        }


def _reduction_text(space: StateSpaceFigures) -> str:
    """How the state space was reduced, for the text report's first line."""
    if space.reduction_note:
        return f" (partial-order reduction: {space.reduction_note})"
    return " (partial-order reduced)" if space.reduced else ""


@dataclass
class Report:
    """Everything `analysis.verify` found about one net."""

    net_name: str
    digest: str
    sources: tuple[str, ...]
    statespace: StateSpaceFigures
    properties: list[PropertyResult]
    structure: dict[str, object] = field(default_factory=dict)
    seconds: float = 0.0
    timed: TimedReport | None = None
    """What timed analysis found (``verify --timed``), figures and schedules whole; its
    verdicts are also among `properties`. None when the verification was untimed."""

    @property
    def verdict(self) -> Verdict:
        """The worst verdict over the required properties (violated > inconclusive >
        proven); a property that is not required is a warning at most."""
        return max(
            (p.verdict for p in self.properties if p.required),
            key=_SEVERITY.__getitem__,
            default=Verdict.PROVEN,
        )

    def property(self, key: str) -> PropertyResult:
        """The result for ``key``; KeyError if it was not checked."""
        for result in self.properties:
            if result.key == key:
                return result
        raise KeyError(key)

    def exit_code(self) -> int:
        """0 all proven, 1 some violated, 3 some inconclusive (and none violated)."""
        return {Verdict.PROVEN: 0, Verdict.VIOLATED: 1, Verdict.INCONCLUSIVE: 3}[self.verdict]

    def to_dict(self, net: Net | None = None) -> dict[str, object]:
        """The stable JSON form (see ``docs/json.md``).

        Each property lists its ``findings`` (`located_findings`), located in the
        source when the ``net`` the report is about is given.
        """
        deadlock = self.property("deadlock")
        bounded = self.property("bounded")
        properties = []
        for prop in self.properties:
            entry = prop.to_dict()
            entry["findings"] = [f.to_dict() for f in located_findings(prop, net)]
            properties.append(entry)
        document: dict[str, object] = {
            "format": REPORT_FORMAT_VERSION,
            "net": {"name": self.net_name, "digest": self.digest, "sources": list(self.sources)},
            "verdict": self.verdict.value,
            "statespace": self.statespace.to_dict(),
            "deadlock": {
                "verdict": deadlock.verdict.value,
                "method": deadlock.method,
                "trace": [s.to_dict() for s in deadlock.evidence.trace]
                if deadlock.evidence
                else [],
                "marking": deadlock.evidence.marking if deadlock.evidence else None,
            },
            "bounded": {
                "verdict": bounded.verdict.value,
                "method": bounded.method,
                "unbounded_places": list(bounded.items),
            },
            "properties": properties,
            "structure": self.structure,
            "seconds": round(self.seconds, 6),
        }
        if self.timed is not None:
            document["timed"] = self.timed.to_json()
        return document

    def render_text(
        self, color: bool = False, net: Net | None = None, max_steps: int = MAX_TRACE_STEPS
    ) -> str:
        """A report for a terminal; ``color`` adds ANSI colours to the verdicts.

        With the ``net`` the report is about, every finding of a property that is not
        proven gets a line of its own located in the source, ``file:line:col: message``
        (as compilers and SARIF locate them). Each counterexample, and the witness of a
        proven reachability property, is printed as numbered steps, the first
        ``max_steps`` of them (the JSON document holds them all).
        """
        paint = _Paint(color)
        space = self.statespace
        lines = [
            f"net '{self.net_name}'  {self.digest}",
            (
                f"state space: {space.states} states, {space.edges} edges"
                if space.method == "explicit"
                else f"state space ({space.method}): {space.states} states"
            )
            + ("" if space.complete else f" (incomplete: {space.stopped_reason})")
            + _reduction_text(space)
            + f"; at most {space.max_tokens_place} token(s) in a place, "
            f"{space.max_tokens_marking} in a marking; {space.seconds:.3f} s",
        ]
        width = max((len(p.title) for p in self.properties), default=10)
        for result in self.properties:
            word = paint.warning(result.verdict) if result.warning else paint(result.verdict)
            lines.append(f"  {word}  {result.title.ljust(width)}  [{result.method}]")
            if result.warning:
                lines.append(
                    f"      {result.verdict.value}, but not required: a warning, not a failure"
                )
            if result.detail:
                lines.append(f"      {result.detail}")
            if net is not None:
                lines.extend(_render_findings(located_findings(result, net)))
            if result.evidence and result.verdict is not Verdict.PROVEN:
                lines.extend(_render_evidence(result.evidence, max_steps))
                for number, more in enumerate(result.more_evidence, start=2):
                    lines.append(f"      counterexample {number}:")
                    lines.extend(_render_evidence(more, max_steps))
                if result.omitted:
                    lines.append(f"      ... and {result.omitted} more not listed")
            elif result.evidence and (result.evidence.trace or result.evidence.loop):
                lines.append("      witness:")
                lines.extend(_render_evidence(result.evidence, max_steps))
        if self.timed is not None:
            lines.extend(render_timing(self.timed))
        counts = {
            v: sum(1 for p in self.properties if p.verdict is v and not p.warning) for v in Verdict
        }
        warnings = sum(1 for p in self.properties if p.warning)
        lines.append(
            f"{paint(self.verdict)}: {counts[Verdict.PROVEN]} proven, "
            f"{counts[Verdict.VIOLATED]} violated, {counts[Verdict.INCONCLUSIVE]} inconclusive"
            + (f", {warnings} warning{'' if warnings == 1 else 's'}" if warnings else "")
        )
        return "\n".join(lines)


def describe_command(command: ScheduledCommand) -> str:
    """One scheduled command and the delays that made its reply late or early, e.g.
    ``DEPTH? (check_depth #1) sent at 40.0 s: up 2.0 s, work 30.0 s, latency 0.1 s,
    down 2.0 s; replied timeout, back at 74.1 s``."""
    return (
        f"{command.command} ({command.transition} #{command.occurrence}) sent at "
        f"{command.sent_at:.1f} s: up {command.up_delay_s:.1f} s, work {command.work_s:.1f} s, "
        f"latency {command.latency_s:.1f} s, down {command.down_delay_s:.1f} s; "
        f"replied {command.reply}, back at {command.arrived_at:.1f} s"
    )


def schedule_summary(schedule: TimedSchedule, transition: str | None = None) -> str:
    """What a counterexample schedule shows, in one line: the command of ``transition``
    that replied last in it (the one that timed out), or the run's length."""
    shown = [c for c in schedule.commands if transition is None or c.transition == transition]
    timed_out = [c for c in shown if c.reply == "timeout"]
    if timed_out or (transition is not None and shown):
        return f"{schedule.reason}: {describe_command((timed_out or shown)[-1])}"
    ends = "" if schedule.final is None else f", ending in {_format_marking(schedule.final)}"
    return (
        f"{schedule.reason}: {len(schedule.commands)} command(s) over "
        f"{schedule.duration_s:.1f} s{ends}"
    )


def render_timing(timed: TimedReport) -> list[str]:
    """The text report's "Timing" section: the link assumed, each final marking's best
    and worst time, each query's time-out and each ``within`` deadline."""
    link = timed.link
    lines = [
        "Timing (timed analysis):",
        f"  link '{link.name}': one-way delay {link.min_delay_s:g} s to {link.max_delay_s:g} s; "
        f"{timed.states} symbolic states, {timed.seconds:.3f} s",
    ]
    if not timed.complete:
        lines.append(f"  incomplete: {timed.reason}; no bound below is proven")
    if timed.unbounded:
        lines.append(f"  unbounded: {timed.unbounded}")
    for final in timed.finals:
        lines.append(f"  {final.describe()}")
    if not timed.finals:
        lines.append("  no declared final marking is reached")
    for query in timed.queries:
        head = f"  time-out of {query.transition} ({query.command}, {query.time_out_s:g} s): "
        if query.verdict is Verdict.PROVEN:
            margin = "" if query.margin_s is None else f", margin {query.margin_s:.1f} s"
            lines.append(head + f"adequate{margin}")
        elif query.verdict is Verdict.VIOLATED:
            lines.append(head + "can time out")
            if query.counterexample is not None:
                lines.append("      " + schedule_summary(query.counterexample, query.transition))
        else:
            lines.append(head + f"inconclusive: {query.detail}")
    for deadline in timed.deadlines:
        head = (
            f"  assert:{deadline.index} within {deadline.deadline_s:g} s "
            f"{_format_marking(deadline.places)}: "
        )
        if deadline.verdict is Verdict.PROVEN:
            latest = "" if deadline.latest_s is None else f", latest at {deadline.latest_s:.1f} s"
            lines.append(head + f"met{latest}")
        elif deadline.verdict is Verdict.VIOLATED:
            lines.append(head + "missed")
            if deadline.counterexample is not None:
                lines.append("      " + schedule_summary(deadline.counterexample))
        else:
            lines.append(head + f"inconclusive: {deadline.detail}")
    return lines


def _render_findings(findings: list[Finding]) -> list[str]:
    """The located findings, one ``file:line:col: message`` line each, at most
    `MAX_FINDINGS_SHOWN`, then how many more (the JSON document lists them all)."""
    located = [f.render() for f in findings if f.span is not None]
    hidden = len(located) - MAX_FINDINGS_SHOWN
    if hidden > 0:
        located = located[:MAX_FINDINGS_SHOWN]
        located.append(f"      ... {hidden} more located (all in --format json)")
    return located


def _render_evidence(evidence: Evidence, max_steps: int = MAX_TRACE_STEPS) -> list[str]:
    """A trace (then its loop, for an infinite run), the marking, the note; at most
    ``max_steps`` steps, then how many more there are."""
    lines = ["      " + step.render() for step in evidence.trace[:max_steps]]
    room = max(0, max_steps - len(evidence.trace))
    if evidence.loop and room:
        lines.append("      then repeat forever:" if evidence.marking else "      then repeat:")
        lines.extend("      " + step.render() for step in evidence.loop[:room])
    hidden = len(evidence.trace) + len(evidence.loop) - max_steps
    if hidden > 0:
        lines.append(
            f"      ... {hidden} more step{'' if hidden == 1 else 's'} "
            "(full trace in --format json)"
        )
    if evidence.marking is not None:
        where = "back at" if evidence.loop else "reaching"
        lines.append(f"      {where} {_format_marking(evidence.marking)}")
    if evidence.note:
        lines.append(f"      {evidence.note}")
    return lines


def _format_marking(marking: dict[str, int]) -> str:
    return format_tokens(marking.items()) if marking else "the empty marking"


_COLOURS = {Verdict.PROVEN: "32", Verdict.VIOLATED: "31", Verdict.INCONCLUSIVE: "33"}


class _Paint:
    """Verdict words, padded, in ANSI colour when asked (terminals only, never pipes)."""

    def __init__(self, color: bool) -> None:
        self.color = color

    def __call__(self, verdict: Verdict) -> str:
        word = verdict.value.upper().ljust(12)
        if not self.color:
            return word
        return f"\033[{_COLOURS[verdict]}m{word}\033[0m"

    def warning(self, verdict: Verdict) -> str:
        """``WARNING`` in place of the verdict of a property that is not required."""
        word = "WARNING".ljust(12)
        return f"\033[33m{word}\033[0m" if self.color else word
