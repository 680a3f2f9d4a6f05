"""Fault plans: force a vehicle's reply kinds to rehearse what can go wrong.

A verified mission says what it does for every reply kind its vehicle can give; a fuzz
campaign against a simulator, though, only ever sees the replies that simulator happens
to give (a healthy simulated ROMEO never refuses a DEPTH), so the mission's error and
timeout branches go untried. A fault plan makes the vehicle give them: it is a list of
rules, each forcing some uses of a command to reply a given kind.

Rule grammar (one rule per ``--fault`` option, or one per line of a plan file)::

    rule    := target '=' kind [ '@' rate ]
    target  := command [ '#' N ]
    command := '*' | NAME            NAME as in the profile: DEPTH, DEPTH?, GOTO ...
    kind    := REPLY | 'any'         REPLY one of the command's reply kinds
    N       := a whole number >= 1   the N-th use of the command (1 = first)
    rate    := a number in (0, 1]    the chance that a matching use is forced

Examples: ``DEPTH?=timeout`` (every DEPTH? times out), ``GOTO#2=error`` (the second GOTO
is refused), ``DIVE=error@0.1`` (each DIVE is refused with probability 0.1),
``*=any@0.05`` (reply fuzzing: each use of any command, with probability 0.05, gets one
of its unexpected reply kinds).

Meaning:

* Uses are counted per command name, in the order the vehicle receives them; ``*#3``
  is the third use of *each* command.
* ``any`` is drawn uniformly from the command's reply kinds other than its first one
  (the profile lists the expected kind first: ``ack`` for a task, ``done`` otherwise), so
  it only ever forces an unexpected reply.
* The first rule that matches a use decides it, and later rules are not consulted,
  even when the deciding rule's rate draw says "not this time". So
  ``DIVE=error@0.1 *=any@0.05`` faults DIVE with 0.1 and everything else with 0.05.
  Put specific rules before general ones.
* A ``*`` rule only matches the commands it can apply to: ``*=timeout`` the commands
  that can reply ``timeout``, ``*=any`` the commands with more than one reply kind.
  A rule naming a command must name a kind that command has; `FaultPlan.check` says so
  before anything runs.

In a plan file, blank lines are skipped and ``#`` starts a comment when it begins a
line or follows a blank (``GOTO#2=error  # the second GOTO is refused``): the ``#`` of
an occurrence sits right after the command name, without a blank.

This module is shared by the controller side (which parses and checks plans) and the
vehicle side (`runtime.vehicle.faults`, which applies them), so it imports only
``coral_lang``.
"""

from __future__ import annotations

import math
import random
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from coral_lang.diagnostics import CoralError, did_you_mean
from coral_lang.profile import CommandSpec, VehicleProfile
from coral_lang.safefile import PROFILE_LIMIT, UnreadableFile, read_text_file

__all__ = [
    "ANY",
    "WILDCARD",
    "FaultPlan",
    "FaultPlanError",
    "FaultRule",
    "load_fault_plan",
    "parse_fault_plan",
    "parse_fault_rule",
    "parse_fault_rules",
]

ANY = "any"
"""The kind that draws one of the command's unexpected reply kinds."""
WILDCARD = "*"
"""The command that stands for every command."""

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\??")
_KIND = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_WHOLE = re.compile(r"[0-9]+")
_RATE = re.compile(r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_EXAMPLE = "e.g. 'DEPTH?=timeout', 'GOTO#2=error', 'DIVE=error@0.1', '*=any@0.05'"


class FaultPlanError(CoralError, ValueError):
    """A fault rule is malformed, or does not fit the vehicle profile.

    The message names where the rule came from (``FILE:LINE:COLUMN`` or ``--fault
    'TEXT'``) and what is wrong with it: fix that rule.
    """


@dataclass(frozen=True)
class FaultRule:
    """One rule of a fault plan.

    Attributes:
        command: the command name, or ``*`` for any command.
        occurrence: force only this use of the command (1-based), or None for every use.
        kind: the reply kind to force, or ``any``.
        rate: the chance that a matching use is forced, in (0, 1].
        text: the rule as written (without comment or surrounding blanks).
        source: where it was written: ``FILE:LINE:COLUMN`` or ``--fault 'TEXT'``.

    Raises:
        FaultPlanError: ``rate`` not in (0, 1] or ``occurrence`` below 1.
    """

    command: str
    occurrence: int | None
    kind: str
    rate: float = 1.0
    text: str = field(default="", compare=False)
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not 0.0 < self.rate <= 1.0:
            raise FaultPlanError(f"rate must be in (0, 1], got {self.rate}")
        if self.occurrence is not None and self.occurrence < 1:
            raise FaultPlanError(f"occurrence must be >= 1, got {self.occurrence}")
        if not self.text:
            object.__setattr__(self, "text", str(self))

    def __str__(self) -> str:
        """The canonical text, e.g. ``GOTO#2=error`` or ``*=any@0.05``."""
        occurrence = "" if self.occurrence is None else f"#{self.occurrence}"
        rate = "" if self.rate == 1.0 else f"@{self.rate!r}"
        return f"{self.command}{occurrence}={self.kind}{rate}"

    def applies_to(self, spec: CommandSpec) -> bool:
        """Whether this rule can force a reply of ``spec`` at all (name and kind fit)."""
        if self.command != WILDCARD and self.command != spec.name:
            return False
        if self.kind == ANY:
            return len(spec.replies) > 1
        return self.kind in spec.replies

    def matches(self, spec: CommandSpec, occurrence: int) -> bool:
        """Whether this rule decides the ``occurrence``-th use of ``spec``."""
        return (self.occurrence is None or self.occurrence == occurrence) and self.applies_to(spec)

    def _where(self) -> str:
        return f"{self.source}: " if self.source else f"fault rule '{self.text}': "


@dataclass(frozen=True)
class FaultPlan:
    """An ordered list of `FaultRule`; the first rule matching a command use decides it."""

    rules: tuple[FaultRule, ...] = ()

    def __len__(self) -> int:
        return len(self.rules)

    def __bool__(self) -> bool:
        return bool(self.rules)

    def __str__(self) -> str:
        """The rules in canonical form, separated by blanks (``parse_fault_rules`` of
        ``str(plan).split()`` gives the plan back)."""
        return " ".join(str(rule) for rule in self.rules)

    def __add__(self, other: FaultPlan) -> FaultPlan:
        return self.merged(other)

    def merged(self, other: FaultPlan) -> FaultPlan:
        """This plan's rules, then ``other``'s: where both match, this plan's win."""
        return FaultPlan(self.rules + other.rules)

    def forced_reply(
        self, spec: CommandSpec, occurrence: int, rng: random.Random
    ) -> tuple[str, FaultRule] | None:
        """The reply kind to force on the ``occurrence``-th use (1-based) of ``spec``,
        with the rule that forced it; None to let the vehicle answer.

        ``rng`` is drawn from only when the deciding rule has a rate below 1 (one
        ``random()``) or kind ``any`` (one ``choice``), so a plan without either never
        touches it.
        """
        for rule in self.rules:
            if not rule.matches(spec, occurrence):
                continue
            if rule.rate < 1.0 and rng.random() >= rule.rate:
                return None
            if rule.kind == ANY:
                return rng.choice(spec.replies[1:]), rule
            return rule.kind, rule
        return None

    def check(self, profile: VehicleProfile) -> None:
        """Refuse rules that cannot apply to ``profile``'s commands.

        Raises:
            FaultPlanError: for the first bad rule: an unknown command (with a did-you-mean),
                a kind the command cannot reply (its kinds listed), ``any`` on a command
                with a single reply kind, or a ``*`` rule no command can satisfy.
        """
        for rule in self.rules:
            _check_rule(rule, profile)


def _check_rule(rule: FaultRule, profile: VehicleProfile) -> None:
    where = rule._where()
    if rule.command == WILDCARD:
        if any(rule.applies_to(spec) for spec in profile.commands):
            return
        if rule.kind == ANY:
            problem = "every command has a single reply kind, so 'any' has nothing to draw"
        else:
            kinds = sorted({kind for spec in profile.commands for kind in spec.replies})
            problem = (
                f"no command of {profile.name} can reply '{rule.kind}'"
                f"{did_you_mean(rule.kind, kinds)}; reply kinds: {', '.join(kinds)}"
            )
        raise FaultPlanError(f"{where}{problem}")
    spec = profile.command(rule.command)
    if spec is None:
        raise FaultPlanError(
            f"{where}unknown command '{rule.command}'"
            f"{did_you_mean(rule.command, profile.command_names)}; {profile.name} has: "
            f"{', '.join(profile.command_names)}"
        )
    if rule.kind == ANY:
        if len(spec.replies) < 2:
            raise FaultPlanError(
                f"{where}'any' needs a command with an unexpected reply kind, but "
                f"{spec.name} only replies '{spec.replies[0]}'"
            )
        return
    if rule.kind not in spec.replies:
        raise FaultPlanError(
            f"{where}{spec.name} cannot reply '{rule.kind}'"
            f"{did_you_mean(rule.kind, spec.replies)}; its replies: {', '.join(spec.replies)}"
            f" (or 'any')"
        )


# ---------------------------------------------------------------------------- parsing


def parse_fault_rules(texts: Sequence[str], source: str = "--fault") -> FaultPlan:
    """A plan from rules given one per string (``--fault`` options), in that order.

    Raises:
        FaultPlanError: a rule is malformed; the message reads ``--fault 'TEXT': ...``
            (with ``source`` in place of ``--fault``).
    """
    return FaultPlan(tuple(parse_fault_rule(text, source) for text in texts))


def parse_fault_rule(text: str, source: str = "--fault") -> FaultRule:
    """One rule given on its own (a ``--fault`` option); errors read ``SOURCE 'TEXT': ...``.

    Raises:
        FaultPlanError: bad syntax, N not a positive whole number, P not in (0, 1].
    """
    where = f"{source} '{text}'"
    return _parse_rule(text, where, lambda column: where)


def load_fault_plan(path: str | Path) -> FaultPlan:
    """A plan from a file: one rule per line, blank lines and ``#`` comments allowed.

    Raises:
        FaultPlanError: the file cannot be read, or a rule is malformed; the message
            names ``FILE:LINE:COLUMN``.
    """
    path = Path(path)
    try:  # a regular file of bounded size: never a FIFO or /dev/zero
        text = read_text_file(path, PROFILE_LIMIT)
    except UnreadableFile as exc:
        raise FaultPlanError(f"{path}: cannot read fault plan: {exc.reason}") from None
    return parse_fault_plan(text, str(path))


def parse_fault_plan(text: str, file: str = "<fault plan>") -> FaultPlan:
    """A plan from the text of a plan file named ``file`` (see `load_fault_plan`).

    Raises:
        FaultPlanError: a rule is malformed; the message names ``FILE:LINE:COLUMN`` of
            the fault and quotes the rule.
    """
    rules: list[FaultRule] = []
    for number, line in enumerate(text.splitlines(), start=1):
        body = _strip_comment(line)
        if not body.strip():
            continue
        rule_text = body.strip()
        start = len(body) - len(body.lstrip())

        def locate(column: int, number: int = number, rule_text: str = rule_text) -> str:
            return f"{file}:{number}:{column + 1}: fault rule '{rule_text}'"

        rules.append(_parse_rule(body, f"{file}:{number}:{start + 1}", locate))
    return FaultPlan(tuple(rules))


def _strip_comment(line: str) -> str:
    """``line`` without its comment: a ``#`` at the start or after a blank."""
    for i, char in enumerate(line):
        if char == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def _parse_rule(text: str, source: str, locate: Callable[[int], str]) -> FaultRule:
    """One rule; ``source`` is recorded in the rule, ``locate(column)`` (0-based column
    in ``text``) prefixes error messages."""

    def fail(column: int, problem: str) -> FaultPlanError:
        return FaultPlanError(f"{locate(column)}: {problem}")

    stripped = text.strip()
    lead = len(text) - len(text.lstrip())
    if not stripped:
        raise fail(0, f"empty fault rule; expected COMMAND=KIND ({_EXAMPLE})")
    equals = text.find("=")
    if equals < 0:
        raise fail(lead, f"expected COMMAND=KIND, found no '=' in '{stripped}' ({_EXAMPLE})")
    target, target_col = _trimmed(text[:equals], 0)
    right, right_col = _trimmed(text[equals + 1 :], equals + 1)
    command, occurrence_text = target, None
    if "#" in target:
        hash_at = target.index("#")
        command, occurrence_text = target[:hash_at], target[hash_at + 1 :]
    if not command:
        raise fail(target_col, "missing command before '=' (a command name, or '*' for any)")
    if command != WILDCARD and not _NAME.fullmatch(command):
        raise fail(
            target_col,
            f"bad command name '{command}': expected a name as in the profile "
            "(letters, digits, _, optionally ending in '?') or '*'",
        )
    occurrence = None
    if occurrence_text is not None:
        occ_col = target_col + len(command) + 1
        if not _WHOLE.fullmatch(occurrence_text) or int(occurrence_text) < 1:
            raise fail(
                occ_col,
                f"the use after '#' must be a positive whole number (1 for the first use), "
                f"got '{occurrence_text}'",
            )
        occurrence = int(occurrence_text)
    kind, rate_text, rate_col = right, None, 0
    if "@" in right:
        at = right.index("@")
        kind = right[:at].rstrip()
        rate_text, rate_col = _trimmed(right[at + 1 :], right_col + at + 1)
    if not kind:
        raise fail(right_col, "missing reply kind after '=' (a reply kind, or 'any')")
    if not _KIND.fullmatch(kind):
        raise fail(
            right_col, f"bad reply kind '{kind}': expected a reply kind of the command, or 'any'"
        )
    rate = 1.0
    if rate_text is not None:
        value = float(rate_text) if _RATE.fullmatch(rate_text) else math.nan
        if not 0.0 < value <= 1.0:
            raise fail(
                rate_col,
                f"the rate after '@' must be a probability in (0, 1], got '{rate_text}'",
            )
        rate = value
    return FaultRule(command, occurrence, kind, rate, text=stripped, source=source)


def _trimmed(part: str, column: int) -> tuple[str, int]:
    """``part`` without surrounding blanks, and the column where what is left starts."""
    stripped = part.lstrip()
    return stripped.rstrip(), column + len(part) - len(stripped)
