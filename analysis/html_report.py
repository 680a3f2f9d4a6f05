"""``coral-check --format html``: one self-contained page per run.

For each file: the diagnostics, the verdict table (property, verdict, method, evidence,
and each finding located as ``file:line:col``, as in the text report and SARIF), a
drawing of the net (`analysis.netdraw`), every counterexample step by step (and the
witness of each proven reachability property), the state-space figures and the
structural facts (class, P- and T-invariants...). A trace shows its first
`analysis.report.MAX_TRACE_STEPS` steps and says how many more the JSON document holds.

A counterexample is shown twice. As a list that needs no script: each step with the
transition fired, its source lines (the step's line marked) and the marking after it.
And as a player (a small inline script): previous/next buttons move through the steps,
the drawing highlights the transition fired and shows the tokens after it (places whose
count changed are marked), and the mission source beside it highlights the step's
line. ``#step=N`` in the address opens every player at step N, ``#cx=ID&step=N`` one
of them (ID is the counterexample's section id, e.g. ``f0-cx-deadlock``); the buttons
keep the address up to date, so a step can be linked to.

The page loads nothing: styles, script and drawings are inline, and every text that
comes from a mission (names, comments, messages) is escaped.
"""

from __future__ import annotations

import html
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from analysis.netdraw import Layout, NetDrawing, draw_net
from analysis.outcome import FileOutcome, worst_exit_code
from analysis.report import (
    MAX_TRACE_STEPS,
    Evidence,
    PropertyResult,
    Report,
    Step,
    Verdict,
    located_findings,
    schedule_summary,
)
from coral_lang.diagnostics import Span
from coral_lang.net import Net, format_tokens

if TYPE_CHECKING:
    from analysis.timed.results import TimedReport

EXCERPT_CONTEXT = 1  # source lines shown above and below a step's line in the list
MAX_INVARIANTS_SHOWN = 50


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _badge(word: str) -> str:
    return f'<span class="badge v-{_e(word)}">{_e(word)}</span>'


def _anchor(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-") or "x"


def _script_json(data: object) -> str:
    """JSON safe inside ``<script type="application/json">`` (no ``</script>``)."""
    text = json.dumps(data, separators=(",", ":"), ensure_ascii=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


# -- counterexamples ----------------------------------------------------------------------


@dataclass(frozen=True)
class _Frame:
    """One position of a counterexample: after ``step`` (None: the initial marking)."""

    step: Step | None
    repeat: bool
    marking: tuple[int, ...]


def _frames(net: Net, evidence: Evidence) -> tuple[list[_Frame], str]:
    """The markings along a trace (then its loop once), replayed on the net; and a
    problem when a step does not replay (the evidence is then cut there)."""
    marking = net.initial_marking()
    frames = [_Frame(None, False, marking)]
    steps = [(s, False) for s in evidence.trace] + [(s, True) for s in evidence.loop]
    for step, repeat in steps:
        try:
            transition = net.transition(step.transition)
        except KeyError:
            return frames, f"step {step.number} names an unknown transition"
        if not net.enabled(marking, transition):
            return frames, f"step {step.number} is not enabled on this net"
        marking = net.fire(marking, transition)
        frames.append(_Frame(step, repeat, marking))
    return frames, ""


def _excerpt(sources: Mapping[str, str], span: Span) -> str:
    text = sources.get(span.file)
    if text is None:
        return ""
    lines = text.splitlines()
    first = max(1, span.line - EXCERPT_CONTEXT)
    last = min(len(lines), span.line + EXCERPT_CONTEXT)
    rows = []
    for number in range(first, last + 1):
        content = f'<span class="no">{number}</span>{_e(lines[number - 1])}'
        tag = "mark" if number == span.line else "span"
        rows.append(f'<{tag} class="ln">{content}</{tag}>')
    return f'<pre class="excerpt">{"".join(rows)}</pre>'


def _source_pane(file: str, text: str, index: int) -> str:
    rows = [
        f'<span class="ln" data-line="{n}"><span class="no">{n}</span>{_e(line)}</span>'
        for n, line in enumerate(text.splitlines(), start=1)
    ]
    return (
        f'<div class="src" data-file="{index}"><div class="src-name">{_e(file)}</div>'
        f"<pre>{''.join(rows)}</pre></div>"
    )


def _counterexample(
    prop: PropertyResult, outcome: FileOutcome, drawing: NetDrawing, section_id: str
) -> str:
    net = outcome.net
    evidence = prop.evidence
    assert net is not None and evidence is not None
    frames, problem = _frames(net, evidence)
    hidden = len(frames) - 1 - MAX_TRACE_STEPS
    frames = frames[: MAX_TRACE_STEPS + 1]  # the initial marking, then the steps shown
    files = []
    for frame in frames:
        span = frame.step.span if frame.step else None
        if span is not None and span.file in outcome.sources and span.file not in files:
            files.append(span.file)
    data_steps: list[dict[str, object]] = []
    items = []
    for k, frame in enumerate(frames):
        step = frame.step
        marked = {f"p{i}": n for i, n in enumerate(frame.marking) if n}
        shown = format_tokens(net.marking_dict(frame.marking).items())
        if step is None:
            label = "initial marking"
            body = f'<span class="what">initial marking</span> <code class="mk">{_e(shown)}</code>'
            data_steps.append({"t": None, "m": marked, "f": None, "l": None, "label": label})
        else:
            span = step.span
            where = f"{span.file}:{span.line}" if span else "no source position"
            label = ("repeat: " if frame.repeat else "") + step.description
            body = (
                f'<span class="what">{"<em>repeat</em> " if frame.repeat else ""}'
                f"{_e(step.description)}</span> "
                f'<span class="loc">{_e(where)}</span>'
                f"{_excerpt(outcome.sources, span) if span else ''}"
                f'<span class="after">marking after: <code class="mk">{_e(shown)}</code></span>'
            )
            data_steps.append(
                {
                    "t": f"t{net.transition_index(step.transition)}",
                    "m": marked,
                    "f": files.index(span.file) if span and span.file in files else None,
                    "l": span.line if span else None,
                    "label": label,
                }
            )
        items.append(f'<li data-step="{k}">{body}</li>')
    note = f'<p class="note">{_e(evidence.note)}</p>' if evidence.note else ""
    if evidence.loop and evidence.marking is not None:
        first, last = evidence.loop[0].number, evidence.loop[-1].number
        back = format_tokens(evidence.marking.items())
        note += (
            f'<p class="note loop">Steps {first} to {last} (marked <em>repeat</em>) '
            f"repeat forever: they lead back to <code>{_e(back)}</code>.</p>"
        )
    if problem:
        note += f'<p class="note warn">Replay stopped: {_e(problem)}.</p>'
    if hidden > 0:
        note += (
            f'<p class="note more-steps">The first {MAX_TRACE_STEPS} steps are shown; '
            f"... {hidden} more step{'' if hidden == 1 else 's'} (full trace in --format json)."
            "</p>"
        )
    panes = "".join(_source_pane(f, outcome.sources[f], i) for i, f in enumerate(files))
    picture = _drawing_box(drawing.svg) if drawing.svg else ""
    kind = "cx" if prop.verdict is not Verdict.PROVEN else "cx witness"
    return (
        f'<section class="{kind}" id="{_e(section_id)}">'
        f"<h4>{_e(prop.title)} {_verdict_badge(prop)}</h4>"
        f'<p class="detail">{_e(prop.detail)}</p>{note}'
        '<div class="controls" hidden>'
        '<button type="button" data-go="first">&#xAB; first</button>'
        '<button type="button" data-go="prev">&#x25C0; previous</button>'
        '<output class="pos"></output>'
        '<button type="button" data-go="next">next &#x25B6;</button>'
        '<button type="button" data-go="last">last &#xBB;</button>'
        "</div>"
        f'{picture}<div class="cx-body"><ol class="steps" start="0">{"".join(items)}</ol>'
        f'<div class="sources">{panes}</div></div>'
        f'<script type="application/json" class="cx-data">'
        f"{_script_json({'steps': data_steps})}</script>{_more_counterexamples(prop)}</section>"
    )


def _verdict_badge(prop: PropertyResult) -> str:
    """The verdict, or ``warning`` for a property that is not required and not proven."""
    if prop.warning:
        return (
            _badge("warning")
            + f' <span class="muted">({_e(prop.verdict.value)}, not required)</span>'
        )
    return _badge(prop.verdict.value)


def _more_counterexamples(prop: PropertyResult) -> str:
    """Every further counterexample (the other dead markings) as a list of steps."""
    if not prop.more_evidence:
        return ""
    total = 1 + len(prop.more_evidence) + prop.omitted
    blocks = []
    for number, evidence in enumerate(prop.more_evidence, start=2):
        steps = "".join(
            f'<li>{_e(step.description)} <span class="loc">'
            f"{_e(f'{step.span.file}:{step.span.line}' if step.span else 'no source position')}"
            "</span></li>"
            for step in evidence.trace[:MAX_TRACE_STEPS]
        )
        hidden = len(evidence.trace) - MAX_TRACE_STEPS
        if hidden > 0:
            steps += (
                f'<li class="more-steps">... {hidden} more step{"" if hidden == 1 else "s"} '
                "(full trace in --format json)</li>"
            )
        reached = format_tokens((evidence.marking or {}).items())
        blocks.append(
            f'<li class="more-cx"><p>Counterexample {number} of {total}: reaches '
            f"<code>{_e(reached)}</code> in {len(evidence.trace)} step(s)</p>"
            f'<ol class="trace">{steps}</ol></li>'
        )
    rest = (
        f'<p class="muted">{prop.omitted} more not listed (raise --max-deadlocks).</p>'
        if prop.omitted
        else ""
    )
    return (
        f"<details open><summary>{len(prop.more_evidence)} more counterexample(s)</summary>"
        f'<ol class="more">{"".join(blocks)}</ol>{rest}</details>'
    )


# -- one file ---------------------------------------------------------------------------


def _diagnostics_table(outcome: FileOutcome) -> str:
    if not outcome.diagnostics:
        return '<p class="muted">No diagnostics.</p>'
    rows = []
    for d in outcome.diagnostics:
        where = str(d.span) if d.span else outcome.path
        notes = "".join(f'<div class="muted">note: {_e(n)}</div>' for n in d.notes)
        rows.append(
            f"<tr><td><code>{_e(where)}</code></td><td>{_badge(d.severity.value)}</td>"
            f"<td><code>{_e(d.code)}</code></td><td>{_e(d.message)}{notes}</td></tr>"
        )
    return (
        '<table class="diagnostics"><thead><tr><th>where</th><th>severity</th><th>code</th>'
        f"<th>message</th></tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def _has_counterexample(prop: PropertyResult) -> bool:
    evidence = prop.evidence
    return (
        prop.verdict is not Verdict.PROVEN
        and evidence is not None
        and (bool(evidence.trace or evidence.loop) or evidence.marking is not None)
    )


def _has_witness(prop: PropertyResult) -> bool:
    """A proven property that comes with a run showing it (a reachable final marking)."""
    evidence = prop.evidence
    return (
        prop.verdict is Verdict.PROVEN
        and evidence is not None
        and bool(evidence.trace or evidence.loop)
    )


def _findings(prop: PropertyResult, net: Net | None) -> str:
    """Each located finding of a property that is not proven, ``file:line:col``
    first, as the text report and SARIF locate them."""
    rows = [
        f'<li><code class="at">{_e(f.span)}</code> {_e(f.message)}</li>'
        for f in located_findings(prop, net)
        if f.span is not None
    ]
    return f'<ul class="findings">{"".join(rows)}</ul>' if rows else ""


def _verdict_table(report: Report, prefix: str, net: Net | None = None) -> str:
    rows = []
    for prop in report.properties:
        evidence = ""
        if _has_counterexample(prop) or _has_witness(prop):
            assert prop.evidence is not None
            count = len(prop.evidence.trace) + len(prop.evidence.loop)
            what, tag = (
                ("counterexample", "cx") if _has_counterexample(prop) else ("witness", "wit")
            )
            evidence = (
                f' <a href="#{prefix}-{tag}-{_anchor(prop.key)}">{what}, '
                f"{count} step{'' if count == 1 else 's'}</a>"
            )
        evidence += _findings(prop, net)
        where = f' <span class="muted">({_e(prop.span)})</span>' if prop.span else ""
        rows.append(
            f'<tr class="prop" data-key="{_e(prop.key)}"><td>{_e(prop.title)}{where}</td>'
            f"<td>{_verdict_badge(prop)}</td><td>{_e(prop.method)}</td>"
            f"<td>{_e(prop.detail)}{evidence}</td></tr>"
        )
    return (
        '<table class="verdicts"><thead><tr><th>property</th><th>verdict</th><th>method</th>'
        f"<th>evidence</th></tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def _statespace(report: Report) -> str:
    space = report.statespace
    rows = [
        ("states", f"{space.states:,}"),
        ("edges", f"{space.edges:,}"),
        ("complete", "yes" if space.complete else f"no: {space.stopped_reason}"),
        ("partial-order reduced", "yes" if space.reduced else "no"),
        ("most tokens in one place", str(space.max_tokens_place)),
        ("most tokens in one marking", str(space.max_tokens_marking)),
        ("search time", f"{space.seconds:.3f} s"),
        ("verification time", f"{report.seconds:.3f} s"),
    ]
    table = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    bounds = "".join(
        f"<tr><td><code>{_e(p)}</code></td><td>{b}</td></tr>" for p, b in space.place_bounds.items()
    )
    details = (
        f"<details><summary>Bound of each place ({len(space.place_bounds)})</summary>"
        f'<table class="bounds"><tbody>{bounds}</tbody></table></details>'
        if bounds
        else ""
    )
    return f'<table class="figures"><tbody>{table}</tbody></table>{details}'


def _timing(timed: TimedReport) -> str:
    """Timed analysis's figures: the link assumed, each final marking's best and worst
    time, each query's time-out and each deadline (verdicts also in the table above)."""
    link = timed.link
    rows = [
        (
            "link assumed",
            f"{link.name}: one-way delay {link.min_delay_s:g} s to {link.max_delay_s:g} s",
        ),
        (
            "exploration",
            f"{timed.states:,} symbolic states, {timed.seconds:.3f} s"
            + ("" if timed.complete else f"; incomplete: {timed.reason}"),
        ),
    ]
    if timed.unbounded:
        rows.append(("unbounded", timed.unbounded))
    rows += [("best to worst", f.describe()) for f in timed.finals]
    for q in timed.queries:
        if q.verdict is Verdict.PROVEN:
            text = "adequate" + ("" if q.margin_s is None else f", margin {q.margin_s:.1f} s")
        elif q.verdict is Verdict.VIOLATED and q.counterexample is not None:
            text = "can time out: " + schedule_summary(q.counterexample, q.transition)
        else:
            text = f"{q.verdict.value}: {q.detail}"
        rows.append((f"time-out of {q.transition} ({q.command}, {q.time_out_s:g} s)", text))
    for d in timed.deadlines:
        if d.verdict is Verdict.VIOLATED and d.counterexample is not None:
            text = "missed: " + schedule_summary(d.counterexample)
        elif d.verdict is Verdict.PROVEN and d.latest_s is not None:
            text = f"met, latest at {d.latest_s:.1f} s"
        else:
            text = f"{d.verdict.value}: {d.detail}"
        rows.append((f"assert:{d.index} within {d.deadline_s:g} s", text))
    table = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    return f'<table class="figures timing"><tbody>{table}</tbody></table>'


def _mapping(value: object) -> Mapping[str, object]:
    return value if isinstance(value, Mapping) else {}


def _strings(value: object) -> list[str]:
    return [str(v) for v in value] if isinstance(value, list | tuple) else []


def _structure(report: Report) -> str:
    facts = report.structure
    if not facts:
        return '<p class="muted">Not computed (--no-structure, or the net is too large).</p>'
    invariants = _mapping(facts.get("invariants"))
    out = [
        '<table class="figures"><tbody>',
        f"<tr><th>places, transitions, arcs</th><td>{_e(facts.get('places'))}, "
        f"{_e(facts.get('transitions'))}, {_e(facts.get('arcs'))}</td></tr>",
        f"<tr><th>net class</th><td>{_e(', '.join(_strings(facts.get('class'))) or '-')}</td></tr>",
        f"<tr><th>invariants</th><td>{_e(invariants.get('summary', '-'))}</td></tr>",
        "<tr><th>structural boundedness</th><td>"
        f"{_e(_mapping(facts.get('structural_boundedness')).get('summary', '-'))}</td></tr>",
        "<tr><th>siphons and traps</th><td>"
        f"{_e(_mapping(facts.get('siphons_traps')).get('summary', '-'))}</td></tr>",
        "</tbody></table>",
    ]
    for kind, key in (("P", "p_invariants"), ("T", "t_invariants")):
        found = _strings(invariants.get(key))
        shown = "".join(f"<li><code>{_e(inv)}</code></li>" for inv in found)
        more = (
            f'<p class="muted">The first {MAX_INVARIANTS_SHOWN} are listed.</p>'
            if len(found) >= MAX_INVARIANTS_SHOWN
            else ""
        )
        body = f'<ol class="invariants">{shown}</ol>{more}' if found else "<p>none</p>"
        out.append(f'<h4>{kind}-invariants ({len(found)})</h4><div class="{kind}-inv">{body}</div>')
    return "".join(out)


def _file_section(outcome: FileOutcome, index: int, layout: Layout) -> str:
    prefix = f"f{index}"
    status = outcome.status()
    head = (
        f'<section class="file" id="{prefix}">'
        f"<h2><code>{_e(outcome.path)}</code> {_badge(status)}</h2>"
    )
    if outcome.input_error is not None:
        return (
            head
            + f'<p class="error">Cannot read this file: {_e(outcome.input_error)}</p></section>'
        )
    parts = [head]
    net, report = outcome.net, outcome.report
    if net is not None:
        parts.append(
            f'<p class="muted">{_e(net.summary())}; digest <code>{_e(net.digest())}</code></p>'
        )
    parts.append(f"<h3>Diagnostics</h3>{_diagnostics_table(outcome)}")
    if report is None:
        if status == "errors":
            parts.append("<p>Not verified: fix the errors first.</p>")
        elif status == "part":
            parts.append(
                f"<p>A part of <code>{_e(outcome.part_of)}</code>: compiled and linted "
                "with it, and verified when that mission is checked.</p>"
            )
        parts.append("</section>")
        return "".join(parts)
    parts.append(f"<h3>Verdicts</h3>{_verdict_table(report, prefix, net)}")
    drawing = draw_net(net, layout) if net is not None else NetDrawing("", "none")
    parts.append(_net_figure(drawing))
    shown = [p for p in report.properties if _has_counterexample(p)]
    if shown:
        parts.append("<h3>Counterexamples</h3>")
        parts.extend(
            _counterexample(p, outcome, drawing, f"{prefix}-cx-{_anchor(p.key)}") for p in shown
        )
    witnesses = [p for p in report.properties if _has_witness(p)]
    if witnesses:
        parts.append("<h3>Witnesses</h3>")
        parts.extend(
            _counterexample(p, outcome, drawing, f"{prefix}-wit-{_anchor(p.key)}")
            for p in witnesses
        )
    if report.timed is not None:
        parts.append(f"<h3>Timing</h3>{_timing(report.timed)}")
    parts.append(f"<h3>State space</h3>{_statespace(report)}")
    parts.append(f"<h3>Structure</h3>{_structure(report)}")
    parts.append("</section>")
    return "".join(parts)


def _drawing_box(svg: str) -> str:
    """A drawing in a scrolling box, with a "fit to width" switch that needs no script."""
    return (
        '<div class="drawing-box"><label class="fit"><input type="checkbox"> fit to width'
        f'</label><div class="drawing">{svg}</div></div>'
    )


def _net_figure(drawing: NetDrawing) -> str:
    how = {
        "graphviz": "laid out by Graphviz",
        "builtin": "laid out by coral (layers by distance from the initial marking)",
    }.get(drawing.layout, "")
    note = f" {_e(drawing.note)}" if drawing.note else ""
    if not drawing.svg:
        return f'<h3>Net</h3><p class="muted">{_e(drawing.note or "not drawn")}</p>'
    return (
        f'<h3>Net</h3><figure class="net-figure" data-layout="{_e(drawing.layout)}">'
        f"{_drawing_box(drawing.svg)}<figcaption>Initial marking, {_e(how)}.{note} "
        "Circles are places (dashed: a command in flight, dotted: free room of a bounded "
        "place), dots or numbers their tokens; boxes are transitions (rounded: a reply of "
        "the vehicle).</figcaption></figure>"
    )


# -- the page -----------------------------------------------------------------------------


def render_html(
    outcomes: Sequence[FileOutcome], *, layout: Layout = "auto", tool_version: str = ""
) -> str:
    """The HTML report of a run, as one self-contained page.

    Args:
        outcomes: The files checked, in order.
        layout: How nets are drawn (`analysis.netdraw.draw_net`).
        tool_version: The coral version, shown in the page's header.
    """
    overall = {0: "proven", 1: "violated", 2: "unreadable", 3: "inconclusive"}
    code = worst_exit_code(o.exit_code() for o in outcomes)
    verdict = overall[code]
    if code == 1 and not any(o.status() == "violated" for o in outcomes):
        verdict = "errors"
    rows = "".join(
        f'<tr><td><a href="#f{i}"><code>{_e(o.path)}</code></a></td><td>{_badge(o.status())}</td>'
        f"<td>{len(o.errors)}</td><td>{len(o.warnings)}</td></tr>"
        for i, o in enumerate(outcomes)
    )
    title = outcomes[0].path if len(outcomes) == 1 else f"{len(outcomes)} files"
    sections = "".join(_file_section(o, i, layout) for i, o in enumerate(outcomes))
    version = f" {_e(tool_version)}" if tool_version else ""
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>coral-check: {_e(title)}</title><style>{_CSS}</style></head><body>"
        f"<header><h1>coral-check report {_badge(verdict)}</h1>"
        f'<p class="muted">coral{version}; exit code {code}</p></header>'
        '<table class="overview"><thead><tr><th>file</th><th>status</th><th>errors</th>'
        f"<th>warnings</th></tr></thead><tbody>{rows}</tbody></table>"
        f"{sections}<script>{_JS}</script></body></html>\n"
    )


_CSS = """
:root{--ok:#1a7f37;--bad:#cf222e;--maybe:#9a6700;--fg:#1f2328;--muted:#59636e;
--line:#d1d9e0;--hl:#fff1a8;--changed:#0969da}
*{box-sizing:border-box}
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;
color:var(--fg);margin:0 auto;max-width:1280px;padding:1rem 1.5rem 4rem}
h1{font-size:1.5rem}h2{font-size:1.25rem;margin-top:2.5rem;border-bottom:2px solid var(--line);
padding-bottom:.3rem}h3{font-size:1.05rem;margin-top:1.6rem}h4{margin:1rem 0 .3rem}
code,pre{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;font-size:12.5px}
table{border-collapse:collapse;width:100%;margin:.4rem 0}
th,td{border-bottom:1px solid var(--line);padding:.3rem .5rem;text-align:left;vertical-align:top}
table.figures{width:auto}table.figures th{font-weight:500;color:var(--muted)}
.muted{color:var(--muted)}.error,.warn{color:var(--bad)}
.badge{display:inline-block;padding:0 .55em;border-radius:1em;font-weight:600;font-size:.78rem;
text-transform:uppercase;letter-spacing:.03em;vertical-align:middle}
.v-proven,.v-clean,.v-part,.v-note{background:#dafbe1;color:var(--ok)}
.v-violated,.v-errors,.v-unreadable,.v-error{background:#ffebe9;color:var(--bad)}
.v-inconclusive,.v-warning{background:#fff8c5;color:var(--maybe)}
.drawing{overflow:auto;border:1px solid var(--line);border-radius:6px;background:#fff;
max-height:75vh;margin:.4rem 0}
.drawing svg{display:block}
.drawing-box:has(.fit input:checked) .drawing svg{width:100%;height:auto}
.fit{font-size:.85em;color:var(--muted);user-select:none}
figcaption{color:var(--muted);font-size:.9em}
svg.net text.tokens{font-weight:700}
svg.net g.transition.fired polygon,svg.net g.transition.fired rect,
svg.net g.transition.fired path{stroke:var(--bad);stroke-width:3;fill:#ffebe9}
svg.net g.transition.fired text{font-weight:700}
svg.net g.arc.fired path{stroke:var(--bad);stroke-width:2.5}
svg.net g.arc.fired polygon{stroke:var(--bad);fill:var(--bad)}
svg.net g.place.changed ellipse,svg.net g.place.changed circle{stroke:var(--changed);
stroke-width:3;fill:#ddf4ff}
section.cx{border:1px solid var(--line);border-radius:8px;padding:.2rem 1rem 1rem;margin:1rem 0}
.controls{display:flex;gap:.5rem;align-items:center;margin:.5rem 0;flex-wrap:wrap}
.controls button{font:inherit;padding:.2rem .7rem;border:1px solid var(--line);
border-radius:6px;background:#f6f8fa;cursor:pointer}
.controls button:disabled{opacity:.45;cursor:default}
.controls output{font-weight:600;min-width:18rem}
.cx-body{display:grid;grid-template-columns:minmax(0,1fr) minmax(0,1fr);gap:1rem}
@media (max-width:900px){.cx-body{grid-template-columns:1fr}}
ol.steps{margin:.3rem 0;padding-left:2.2rem}
ol.steps li{padding:.25rem .4rem;border-radius:4px}
ol.steps li.current{background:var(--hl)}
ol.trace{margin:.2rem 0 .6rem;padding-left:2.2rem}
.loc{color:var(--muted);font-size:.9em}.after{display:block;color:var(--muted);font-size:.9em}
pre{margin:.2rem 0;background:#f6f8fa;border-radius:4px;padding:.3rem 0;overflow:auto}
pre .ln{display:block;padding:0 .6rem;white-space:pre}
pre .no{display:inline-block;min-width:2.6em;color:var(--muted);user-select:none}
pre mark.ln{background:var(--hl)}
.src{margin-bottom:.6rem}.src-name{font-weight:600;font-size:.9em}
.src pre{max-height:26rem}
.src .ln.hit{background:var(--hl);box-shadow:inset 3px 0 var(--maybe)}
ol.invariants li{margin:.15rem 0}
ul.findings{margin:.3rem 0 0;padding-left:1.2rem}ul.findings code.at{color:var(--muted)}
@media print{.controls{display:none}.drawing{max-height:none}}
"""

_JS = """
(function(){
"use strict";
function tokens(n){return n<=0?"":n<=3?"\\u2022".repeat(n):String(n);}
function Player(root){
  var data=JSON.parse(root.querySelector("script.cx-data").textContent);
  var steps=data.steps,current=0;
  var controls=root.querySelector(".controls");
  var pos=root.querySelector("output.pos");
  var places={},transitions={},arcs=[];
  root.querySelectorAll("svg.net g.place").forEach(function(g){places[g.dataset.node]=g;});
  root.querySelectorAll("svg.net g.transition").forEach(function(g){
    transitions[g.dataset.node]=g;});
  root.querySelectorAll("svg.net g.arc").forEach(function(g){arcs.push(g);});
  var items=root.querySelectorAll("ol.steps > li");
  var panes=root.querySelectorAll(".src");
  var drawing=root.querySelector(".drawing");
  function show(k,record){
    current=Math.max(0,Math.min(steps.length-1,k|0));
    var step=steps[current],before=current>0?steps[current-1]:null;
    Object.keys(places).forEach(function(key){
      var g=places[key],n=step.m[key]||0,text=g.querySelector("text.tokens");
      if(text){text.textContent=tokens(n);}
      g.classList.toggle("changed",before!==null&&(before.m[key]||0)!==n);
    });
    Object.keys(transitions).forEach(function(key){
      transitions[key].classList.toggle("fired",step.t===key);});
    if(step.t&&transitions[step.t]&&drawing){
      var r=transitions[step.t].getBoundingClientRect(),c=drawing.getBoundingClientRect();
      drawing.scrollLeft+=(r.left+r.width/2)-(c.left+c.width/2);
      drawing.scrollTop+=(r.top+r.height/2)-(c.top+c.height/2);
    }
    arcs.forEach(function(g){g.classList.toggle("fired",g.dataset.t===step.t);});
    items.forEach(function(li){
      li.classList.toggle("current",Number(li.dataset.step)===current);});
    panes.forEach(function(pane,i){
      var mine=step.f===null?i===0:Number(pane.dataset.file)===step.f;
      pane.hidden=!mine;
      pane.querySelectorAll(".ln.hit").forEach(function(l){l.classList.remove("hit");});
      if(mine&&step.l!==null){
        var line=pane.querySelector('.ln[data-line="'+step.l+'"]');
        if(line){line.classList.add("hit");var box=pane.querySelector("pre");
          box.scrollTop=Math.max(0,line.offsetTop-box.offsetTop-box.clientHeight/2);}
      }
    });
    pos.textContent="step "+current+" of "+(steps.length-1)+": "+step.label;
    controls.querySelector('[data-go="prev"]').disabled=current===0;
    controls.querySelector('[data-go="first"]').disabled=current===0;
    controls.querySelector('[data-go="next"]').disabled=current===steps.length-1;
    controls.querySelector('[data-go="last"]').disabled=current===steps.length-1;
    if(record&&history.replaceState){
      history.replaceState(null,"","#cx="+root.id+"&step="+current);}
  }
  controls.addEventListener("click",function(event){
    var go=event.target.closest("button");
    if(!go){return;}
    var to={first:0,prev:current-1,next:current+1,last:steps.length-1}[go.dataset.go];
    show(to,true);
  });
  items.forEach(function(li){li.addEventListener("click",function(){
    show(Number(li.dataset.step),true);});});
  controls.hidden=false;
  root.classList.add("playing");
  show(0,false);
  return {id:root.id,show:show};
}
var players=Array.prototype.map.call(document.querySelectorAll("section.cx"),Player);
function fromAddress(){
  var params=new URLSearchParams(location.hash.slice(1));
  var step=parseInt(params.get("step"),10);
  if(isNaN(step)){return;}
  var only=params.get("cx");
  players.forEach(function(p){if(!only||only===p.id){p.show(step,false);}});
}
window.addEventListener("hashchange",fromAddress);
fromAddress();
})();
"""
