"""A plain reference interpreter of a mission net, to check the Engine against.

The Engine is written for speed: index arrays, a heap of enabled transitions, lazy
re-checks of only the consumers of places that gained tokens. This is the same
semantics written the obvious way, with dict markings and a scan of every transition at
every step, so that the two can be run side by side and must agree step by step:

* engine transitions (plain and command) fire on their own, one at a time, until none
  is enabled; reply transitions fire only when the vehicle's reply for their command
  arrives;
* the choice among enabled engine transitions: the highest priority, then the first in
  source order (`Policy.PRIORITY`); `Policy.RANDOM` may pick any enabled transition of
  the highest priority (`ReferenceNet.candidates`);
* each command fired gets the next command id, from 1;
* a reply for an id not in flight, or of a kind the command has no transition for,
  changes nothing;
* with nothing enabled and nothing in flight the mission is over: FINAL if the marking
  is a declared final marking (exactly its tokens; complement places hold the free
  room of their place), else DEADLOCK.

No code is shared with `runtime.engine` beyond the `Outcome` names.

`analysed` adds the other reference the runtime must agree with: what verification
proved about a mission, and its complete reachability graph.
"""

from __future__ import annotations

import functools
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from analysis.certificate import (
    CertificateCheck,
    check_certificate,
    make_certificate,
    write_certificate,
)
from analysis.report import Verdict
from analysis.statespace import explore
from analysis.verify import verify
from coral_lang.compiler import compile_mission
from coral_lang.net import Net, PlaceKind, Transition, TransitionKind
from runtime.engine import Outcome

Pick = Callable[[Sequence[Transition]], Transition]


class ReferenceNet:
    """One mission run by the textbook rules; see the module docstring."""

    def __init__(self, net: Net) -> None:
        self.net = net
        self.marking: dict[str, int] = {p.name: p.initial for p in net.places if p.initial}
        self.in_flight: dict[int, Transition] = {}
        self.next_id = 1
        self.answered: set[int] = set()

    # ------------------------------------------------------------------ the firing rule

    def enabled(self, transition: Transition) -> bool:
        """Every input place holds at least the arc's weight."""
        return all(self.marking.get(place, 0) >= w for place, w in transition.inputs)

    def fire(self, transition: Transition) -> None:
        """Take the input tokens, put the output tokens; the caller checked `enabled`."""
        for place, w in transition.inputs:
            left = self.marking[place] - w
            if left:
                self.marking[place] = left
            else:
                del self.marking[place]
        for place, w in transition.outputs:
            self.marking[place] = self.marking.get(place, 0) + w

    def candidates(self) -> list[Transition]:
        """The enabled engine transitions of the highest priority, in source order."""
        enabled = [
            t
            for t in self.net.transitions
            if t.kind is not TransitionKind.REPLY and self.enabled(t)
        ]
        if not enabled:
            return []
        top = max(t.priority for t in enabled)
        return [t for t in enabled if t.priority == top]

    # ------------------------------------------------------------------ steps

    def settle(self, pick: Pick | None = None) -> list[tuple[str, int | None]]:
        """Fire engine transitions until none is enabled: ``(name, command id)`` each.

        ``pick`` chooses among `candidates` (default: the first, i.e. `Policy.PRIORITY`).
        """
        fired: list[tuple[str, int | None]] = []
        while candidates := self.candidates():
            chosen = candidates[0] if pick is None else pick(candidates)
            assert chosen in candidates, f"{chosen.name} is not a candidate"
            self.fire(chosen)
            command_id = None
            if chosen.command is not None:
                command_id = self.next_id
                self.next_id += 1
                self.in_flight[command_id] = chosen
            fired.append((chosen.name, command_id))
        return fired

    def start(self, pick: Pick | None = None) -> list[tuple[str, int | None]]:
        """The first step of the mission."""
        return self.settle(pick)

    def reply_transition(self, command_id: int, kind: str) -> Transition | None:
        """The reply transition for ``kind`` of the command in flight, if there is one."""
        command = self.in_flight.get(command_id)
        if command is None:
            return None
        for t in self.net.transitions:
            if t.kind is TransitionKind.REPLY and t.reply_to == command.name and t.reply == kind:
                return t
        return None

    def on_reply(
        self, command_id: int, kind: str, pick: Pick | None = None
    ) -> list[tuple[str, int | None]] | None:
        """Fire the reply, then settle; None (nothing changed) for an unexpected reply."""
        reply = self.reply_transition(command_id, kind)
        if reply is None or not self.enabled(reply):
            return None
        del self.in_flight[command_id]
        self.answered.add(command_id)
        self.fire(reply)
        return [(reply.name, command_id), *self.settle(pick)]

    # ------------------------------------------------------------------ where it stands

    def is_final(self) -> bool:
        """Whether the marking is exactly one of the declared final markings."""
        for final in self.net.finals:
            wanted = dict(final.tokens)
            for place in self.net.places:
                if place.kind is PlaceKind.COMPLEMENT and place.complement_of is not None:
                    base = self.net.place(place.complement_of)
                    assert base.capacity is not None
                    wanted[place.name] = base.capacity - wanted.get(base.name, 0)
            if {p: n for p, n in wanted.items() if n} == self.marking:
                return True
        return False

    def outcome(self) -> Outcome:
        """RUNNING while anything can happen; then FINAL or DEADLOCK."""
        if self.in_flight or self.candidates():
            return Outcome.RUNNING
        return Outcome.FINAL if self.is_final() else Outcome.DEADLOCK

    def busy_resources(self) -> list[str]:
        """Each vehicle resource once per command in flight that drives it."""
        return [
            r for t in self.in_flight.values() if t.command is not None for r in t.command.resources
        ]


# ---------------------------------------------------------------------- what analysis says


@dataclass(frozen=True)
class Analysed:
    """A mission with what verification and the reachability graph say about it.

    Attributes:
        net: the compiled mission.
        approval: a real certificate check if verification passed, else an unverified
            approval (the engine runs it only in these tests).
        verdicts: ``{property key: verdict}`` of `analysis.verify.verify`.
        reachable: every reachable marking (the complete, unreduced state space).
        dead: the reachable markings where nothing can fire, as ``{place: tokens}``.
    """

    net: Net
    approval: CertificateCheck
    verdicts: dict[str, Verdict]
    reachable: frozenset[tuple[int, ...]]
    dead: tuple[dict[str, int], ...]

    def proven(self, key: str) -> bool:
        """Whether verification proved property ``key`` (``deadlock``, ...)."""
        return self.verdicts.get(key) is Verdict.PROVEN

    def is_edge(self, before: tuple[int, ...], transition: Transition) -> bool:
        """Whether firing ``transition`` in ``before`` is an edge of the reachability graph."""
        return (
            before in self.reachable
            and self.net.enabled(before, transition)
            and self.net.fire(before, transition) in self.reachable
        )


@functools.cache
def analysed(path: Path) -> Analysed:
    """Compile, verify and explore the mission at ``path`` (once per test process)."""
    net = compile_mission(path)
    report = verify(net)
    if report.verdict is Verdict.PROVEN:
        with tempfile.TemporaryDirectory() as folder:
            certificate = Path(folder) / "mission.certificate.json"
            write_certificate(make_certificate(report), certificate)
            approval = check_certificate(net, certificate)
    else:
        approval = CertificateCheck(
            path="unverified (property tests)", net_digest=net.digest(), issued="", tool_version=""
        )
    space = explore(net)
    assert space.complete and not space.reduced, "the reference needs every state and edge"
    return Analysed(
        net=net,
        approval=approval,
        verdicts={p.key: p.verdict for p in report.properties},
        reachable=frozenset(tuple(int(v) for v in row) for row in space.markings.tolist()),
        dead=tuple(net.marking_dict(space.marking(int(d))) for d in space.deadlocks),
    )
