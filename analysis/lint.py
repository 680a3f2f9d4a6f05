"""Lint: mistakes a mission can compile with, found from its text and its net alone.

The compiler already refuses what cannot run (CORAL0xx, CORAL1xx). The rules here
(CORAL2xx) flag what runs but is probably wrong: a place nothing ever marks, a query
whose time-out the Internet link can eat, two transitions racing for one token with
nothing to decide between them. Each rule has a stable code, a severity, and a page in
``docs/rules.md`` (bad example, why it matters at sea, the fix).

A finding is silenced on one line with a comment that gives the reason, at the end of
the line itself or alone on the line above::

    transition retry    # coral: allow CORAL207 -- either order is fine here

A comment after code applies to that line only, never to the next: which findings a
comment silences then depends on the lines it is written beside, not on how far the
next statement is, so `coral-check fmt` can lay statements out without changing it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from analysis.budget import Budget
from analysis.statespace import StateSpace, explore
from coral_lang import ast
from coral_lang.compiler import CompileResult
from coral_lang.diagnostics import Diagnostic, Severity, Span
from coral_lang.formula import places_of
from coral_lang.lexer import Token, tokenize
from coral_lang.net import Net, PlaceKind, TransitionKind
from coral_lang.profile import VehicleProfile

DEFAULT_LINK_RTT_S = 14.0
"""Worst round trip assumed for the link: the paper saw commands delayed about 7 s on
the Internet, each way."""


@dataclass(frozen=True)
class Rule:
    """A lint rule: stable code, default severity, one-line summary."""

    code: str
    severity: Severity
    summary: str


RULES: dict[str, Rule] = {
    rule.code: rule
    for rule in (
        Rule("CORAL201", Severity.WARNING, "no final marking declared"),
        Rule("CORAL202", Severity.WARNING, "constant declared but never used"),
        Rule("CORAL203", Severity.WARNING, "place declared but never used"),
        Rule("CORAL204", Severity.WARNING, "place waited on but never marked"),
        Rule("CORAL205", Severity.WARNING, "place marked but never consumed"),
        Rule(
            "CORAL206",
            Severity.WARNING,
            "query time-out shorter than link round trip plus duration",
        ),
        Rule("CORAL207", Severity.WARNING, "transitions in conflict with no priority between them"),
        Rule(
            "CORAL208",
            Severity.WARNING,
            "suppression comment without a reason or for an unknown rule",
        ),
        Rule("CORAL209", Severity.WARNING, "operator input no transition waits on"),
    )
}

_ALLOW = re.compile(
    r"#\s*coral:\s*allow\s+(?P<codes>[A-Z0-9_, ]+?)(?:\s*--\s*(?P<reason>.*\S))?\s*$"
)


@dataclass(frozen=True)
class LintOptions:
    """Settings of the lint rules.

    Attributes:
        link_rtt_s: Worst round trip of the link to the vehicle, seconds (CORAL206).
        max_states: State budget for finding racing transitions (CORAL207); races
            beyond it are not reported.
        time_limit: Seconds for that search (a slice of the caller's `Budget`).
        max_pairs_per_place: Candidate pairs examined per shared input place (CORAL207);
            a place with more consumers than that allows gets a note saying how many
            pairs were skipped.
    """

    link_rtt_s: float = DEFAULT_LINK_RTT_S
    max_states: int = 200_000
    time_limit: float = 10.0
    max_pairs_per_place: int = 1_000


def lint(
    result: CompileResult,
    options: LintOptions | None = None,
    space: StateSpace | None = None,
    *,
    budget: Budget | None = None,
) -> list[Diagnostic]:
    """The lint findings of a compiled mission, suppressions applied, in source order.

    Args:
        result: The compiled mission.
        options: Rule settings.
        space: The reachable state space of ``result.net`` if the caller has already
            explored it (``coral-check`` verifies first). CORAL207 reads it instead of
            exploring again when it is unreduced and holds every state its own search
            would reach (it is complete, or has ``options.max_states`` states or more):
            both searches are breadth-first in one fixed order, so nothing is missed.
        budget: The caller's budget (clock, deadline); CORAL207's own search takes a
            slice of ``options.time_limit`` of it. None: a fresh one on the real clock.

    Returns:
        The findings; an empty list for a mission that did not compile (its errors come
        first).
    """
    options = options or LintOptions()
    if result.net is None or not result.missions:
        return []  # nothing compiled, or a PNML import: the rules are about mission text
    findings = [
        *_no_final(result),
        *_unused_constants(result),
        *_place_usage(result.net),
        *_short_time_outs(result.net, result.profile, options),
        *_unprioritised_conflicts(result.net, options, space, budget or Budget()),
    ]
    kept, suppression_findings = _apply_suppressions(findings, result.sources)
    return sorted([*kept, *suppression_findings], key=_order)


def _order(d: Diagnostic) -> tuple[str, int, int, str]:
    if d.span is None:
        return ("", 0, 0, d.code)
    return (d.span.file, d.span.line, d.span.col, d.code)


def _finding(code: str, message: str, span: Span | None, *notes: str) -> Diagnostic:
    return Diagnostic(RULES[code].severity, code, message, span, tuple(notes))


# -- rules -------------------------------------------------------------------------------


def _no_final(result: CompileResult) -> Iterator[Diagnostic]:
    net = result.net
    assert net is not None
    if not net.finals and result.missions:
        root = result.missions[0]
        yield _finding(
            "CORAL201",
            f"mission '{net.name}' declares no final marking: analysis cannot tell a proper "
            "end from a deadlock",
            root.name_span,
            "add 'final { PLACE }' for each way the mission may end",
        )


def _declarations(result: CompileResult) -> Iterator[ast.Declaration]:
    for mission in result.missions:
        yield from mission.declarations


def _names_used(result: CompileResult) -> set[str]:
    used: set[str] = set()

    def value(v: object) -> None:
        if isinstance(v, ast.Name):
            used.add(v.name)

    def tokens(refs: tuple[ast.TokenRef, ...] | None) -> None:
        for ref in refs or ():
            value(ref.weight)

    for decl in _declarations(result):
        if isinstance(decl, ast.Places):
            for place in decl.places:
                value(place.initial)
                value(place.capacity)
        elif isinstance(decl, ast.Final):
            tokens(decl.tokens)
        elif isinstance(decl, ast.AssertDecl):
            tokens(decl.tokens)
            value(decl.bound)
            value(decl.deadline)  # 'assert within T_MISSION { ... }'
        elif isinstance(decl, ast.TransitionDecl):
            value(decl.priority)
            tokens(decl.wait)
            tokens(decl.signal)
            if decl.action is not None:
                for arg in decl.action.args:
                    value(arg.value)
                for reply in decl.action.replies:
                    tokens(reply.targets)
    return used


def _unused_constants(result: CompileResult) -> Iterator[Diagnostic]:
    used = _names_used(result)
    for decl in _declarations(result):
        if isinstance(decl, ast.Const) and decl.name not in used:
            yield _finding(
                "CORAL202",
                f"constant '{decl.name}' is never used",
                decl.span,
                "remove it, or use it where its value is written out",
            )


def _place_usage(net: Net) -> Iterator[Diagnostic]:
    consumers: dict[str, list[str]] = {}  # place -> transitions that wait on it
    produced: set[str] = set()
    for tr in net.transitions:
        for p, _ in tr.inputs:
            consumers.setdefault(p, []).append(tr.name)
        produced.update(p for p, _ in tr.outputs)
    consumed = consumers.keys()
    in_finals = {p for f in net.finals for p, _ in f.tokens}
    in_asserts = {p for a in net.assertions for p, _ in a.places}
    in_asserts.update(p for a in net.assertions if a.formula for p in places_of(a.formula))
    inputs = set(net.inputs)
    for place in net.places:
        if place.kind is not PlaceKind.MISSION:
            continue
        name = place.name
        if name in inputs:
            # Only the operator marks it: CORAL203-205 do not fit, CORAL209 does.
            if name not in consumed:
                yield _finding(
                    "CORAL209",
                    f"operator input '{name}' is declared but no transition waits on it: "
                    "the operator's action would have no effect",
                    place.span,
                    f"add a transition that waits on '{name}' (e.g. to take the abort "
                    "path), or remove the input",
                )
            continue
        marked = place.initial > 0 or name in produced
        if name not in consumed and name not in produced and name not in in_finals | in_asserts:
            if place.initial == 0:
                yield _finding(
                    "CORAL203",
                    f"place '{name}' is declared but no transition, final "
                    "marking or assertion uses it",
                    place.span,
                    "remove it, or wire it in",
                )
            continue
        if name in consumed and not marked:
            waiting = sorted(set(consumers[name]))
            yield _finding(
                "CORAL204",
                f"place '{name}' is waited on ({', '.join(waiting)}) but nothing ever marks "
                "it: those transitions can never fire",
                place.span,
                "signal it from a transition or a reply, or give it initial tokens",
            )
        if marked and name not in consumed and name not in in_finals and net.finals:
            # without any final marking CORAL201 already says what is missing
            yield _finding(
                "CORAL205",
                f"place '{name}' is marked but nothing consumes it and no final marking "
                "includes it: its tokens are left behind",
                place.span,
                "consume it, or include it in the final marking where the mission ends",
            )


def _short_time_outs(
    net: Net, profile: VehicleProfile | None, options: LintOptions
) -> Iterator[Diagnostic]:
    durations = {c.name: c.duration_s for c in profile.commands} if profile else {}
    for tr in net.transitions:
        if tr.kind is not TransitionKind.COMMAND or tr.command is None:
            continue
        time_out = dict(tr.command.params).get("time_out")
        if not isinstance(time_out, int | float):
            continue
        duration = durations.get(tr.command.name, 0.0)
        needed = options.link_rtt_s + duration
        if float(time_out) < needed:
            yield _finding(
                "CORAL206",
                f"{tr.command.name} time-out {float(time_out):g} s is shorter than the link's "
                f"worst round trip ({options.link_rtt_s:g} s) plus the command's nominal "
                f"duration ({duration:g} s): a slow link makes it time out although the "
                "vehicle did its job",
                tr.span,
                f"raise time_out to at least {needed:g} s",
            )


def _unprioritised_conflicts(
    net: Net, options: LintOptions, given: StateSpace | None, budget: Budget
) -> Iterator[Diagnostic]:
    """Pairs of engine transitions (not vehicle replies) with equal priority that are both
    enabled in some reachable marking while their shared input places cannot feed both:
    the engine's choice between them then rests on source order alone."""
    candidates, skipped = _conflict_candidates(net, options.max_pairs_per_place)
    for place, (consumers, count) in skipped.items():
        yield Diagnostic(
            Severity.NOTE,
            "CORAL207",
            f"place '{place}' is waited on by {consumers} transitions: only the first "
            f"{options.max_pairs_per_place} pairs of equal priority were checked for races "
            f"(skipped: {count} pairs)",
            net.places[net.place_index(place)].span,
            ("give the transitions priorities, or split the place",),
        )
    pairs = []
    for a, b in sorted(candidates):
        inputs_a = dict(net.transitions[a].inputs)
        shared = [(p, w, inputs_a[p]) for p, w in net.transitions[b].inputs if p in inputs_a]
        pairs.append((a, b, shared))
    if not pairs:
        return
    space = given
    if space is None or space.reduced or not (space.complete or space.states >= options.max_states):
        search = budget.child(seconds=options.time_limit)
        space = explore(net, max_states=options.max_states, budget=search)
    found: dict[int, int] = {}  # pair number -> first state where the two race
    # One pass over the stored markings, all pairs per block: unpacking markings is the
    # expensive part, so it must not be repeated per pair.
    for first, block in space.iter_markings():
        for number, (a, b, shared) in enumerate(pairs):
            if number in found:
                continue
            hit = np.ones(len(block), dtype=bool)
            for place, weight in (*net.transitions[a].inputs, *net.transitions[b].inputs):
                hit &= block[:, net.place_index(place)] >= weight
            scarce = np.zeros(len(block), dtype=bool)
            for place, weight_b, weight_a in shared:
                scarce |= block[:, net.place_index(place)] < weight_a + weight_b
            states = np.flatnonzero(hit & scarce)
            if states.size:
                found[number] = first + int(states[0])
        if len(found) == len(pairs):
            break
    for number in sorted(found):
        a, b, shared = pairs[number]
        ta, tb = net.transitions[a], net.transitions[b]
        yield _finding(
            "CORAL207",
            f"transitions '{ta.name}' and '{tb.name}' can both fire on '{shared[0][0]}' "
            f"(after {space.depth_of(found[number])} step(s)) and have the same priority: "
            "which one fires depends on source order alone",
            tb.span,
            f"give one a priority ('transition {tb.name} priority 1'), or allow it here "
            "with a reason if either order is intended",
        )


def _conflict_candidates(
    net: Net, per_place: int
) -> tuple[set[tuple[int, int]], dict[str, tuple[int, int]]]:
    """Pairs (a, b), a < b, of engine transitions with equal priority that share an input
    place, found from each place's consumers (never all pairs of transitions); and, per
    place with more such pairs than ``per_place``, (its consumers, pairs skipped)."""
    by_place: dict[str, list[int]] = {}
    for i, t in enumerate(net.transitions):
        if t.kind is not TransitionKind.REPLY:
            for p, _ in t.inputs:
                by_place.setdefault(p, []).append(i)
    pairs: set[tuple[int, int]] = set()
    skipped: dict[str, tuple[int, int]] = {}
    for place, consumers in by_place.items():
        if len(consumers) < 2:
            continue
        groups: dict[int, list[int]] = {}
        for i in consumers:
            groups.setdefault(net.transitions[i].priority, []).append(i)
        budget, left_out = per_place, 0
        for group in groups.values():
            for x, a in enumerate(group):
                if budget <= 0:
                    left_out += len(group) - 1 - x
                    continue
                for b in group[x + 1 :]:
                    pair = (a, b) if a < b else (b, a)
                    if pair in pairs:
                        continue
                    if budget <= 0:
                        left_out += 1
                        continue
                    pairs.add(pair)
                    budget -= 1
        if left_out:
            skipped[place] = (len(consumers), left_out)
    return pairs, skipped


# -- suppressions ------------------------------------------------------------------------


def _apply_suppressions(
    findings: list[Diagnostic], sources: dict[str, str]
) -> tuple[list[Diagnostic], list[Diagnostic]]:
    """The findings no ``# coral: allow`` silences, and the problems with the
    suppressions themselves (CORAL208). `coral_lang.formatting` relies on the rule
    (after code: its own line; alone: the next line) to keep a file's findings."""
    allowed: dict[tuple[str, int], set[str]] = {}
    problems: list[Diagnostic] = []
    for file, comment, match, alone in _allow_comments(sources):
        number = comment.line
        span = Span(file, number, comment.col + match.start(), number, comment.end_col)
        codes = {c.strip() for c in match.group("codes").replace(",", " ").split()}
        unknown = sorted(c for c in codes if c not in RULES)
        if unknown:
            problems.append(
                _finding(
                    "CORAL208",
                    f"unknown rule {', '.join(unknown)} in suppression",
                    span,
                    f"rules: {', '.join(RULES)}",
                )
            )
        if not match.group("reason"):
            problems.append(
                _finding(
                    "CORAL208",
                    "suppression without a reason",
                    span,
                    "write '# coral: allow CODE -- why this is intended'",
                )
            )
            continue
        # after code: that line; alone on its line: the next one
        allowed.setdefault((file, number + 1 if alone else number), set()).update(codes)
    kept = [
        d
        for d in findings
        if d.span is None or d.code not in allowed.get((d.span.file, d.span.line), set())
    ]
    return kept, problems


def _allow_comments(
    sources: dict[str, str],
) -> Iterator[tuple[str, Token, re.Match[str], bool]]:
    """Every ``# coral: allow`` comment of ``sources``: its file, the comment, the match
    and whether it is alone on its line. Read from the lexer's comment tokens, so lines
    are counted as every finding counts them (on "\n" only, where ``str.splitlines``
    also breaks at a form feed or U+2028) and a ``#`` inside a string is no comment."""
    for file, text in sources.items():
        if "coral:" not in text:
            continue  # the common case: no suppression, no lexing
        comments: list[Token] = []
        tokenize(text, file, comments)
        lines = text.split("\n")
        for comment in comments:
            match = _ALLOW.search(comment.text)
            if match is not None:
                alone = not lines[comment.line - 1][: comment.col - 1].strip()
                yield file, comment, match, alone
