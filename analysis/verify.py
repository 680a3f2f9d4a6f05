"""``verify(net) -> Report``: what a mission can do, decided before it runs.

Methods, cheapest first, each verdict saying which one decided it:

1. explicit state space (`analysis.statespace`): exact when it completes within the
   budget; counterexamples found in it are real, with a shortest trace, even when it
   does not complete;
2. Karp-Miller coverability (`analysis.coverability`): boundedness when the state
   space is too large or infinite, with a replayable pumping trace;
3. the z3 state equation (`analysis.stateeq`): proves bad markings unreachable
   without enumerating states. A solution of the equation is not a counterexample:
   unless the search found the bad marking, the verdict is then inconclusive;
4. structural results (invariants, structural boundedness, siphons and traps,
   net class) for the report.

Mission semantics (``docs/language.md``): a dead marking that is a declared final
marking is proper termination; any other dead marking is a deadlock. Resource
conflicts are markings with two commands in flight that drive one vehicle resource.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, cast

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget, memory_limit_reason, peak_resident_bytes, resident_bytes
from analysis.coverability import coverability, node_cap
from analysis.inputs import has_inputs
from analysis.progress import ProgressCallback
from analysis.report import (
    Evidence,
    PropertyResult,
    Report,
    StateSpaceFigures,
    Step,
    Verdict,
    make_trace,
    witness,
)
from analysis.stategraph import GraphError, StateGraph, build_graph
from analysis.statespace import StateSpace, explore
from analysis.symbolic.report import (
    AUTO_SYMBOLIC_MIN_STATES,
    SYMBOLIC,
    symbolic_applicable,
    symbolic_deadlock,
    symbolic_figures,
)
from analysis.termination import (
    DEFAULT_MAX_DEADLOCKS,
    DEFAULT_MAX_EDGES,
    FinalPatterns,
    TerminationLimits,
    check_termination,
    final_rows,
    non_final_dead_states,
)
from analysis.timed.options import TimedOptions
from coral_lang.diagnostics import Span
from coral_lang.net import AssertKind, Net, PlaceKind, format_tokens

if TYPE_CHECKING:
    # Imported where the state equation runs: with the invariants and siphons it needs,
    # it costs tens of milliseconds that a completely explored net never has to pay.
    from analysis import stateeq
    from analysis.symbolic.explore import SymbolicResult
    from analysis.timed.results import TimedReport
    from analysis.timed.schedule import TimedSchedule
    from coral_lang.profile import VehicleProfile

Markings = npt.NDArray[np.int64]
Predicate = Callable[[Markings], npt.NDArray[np.bool_]]

EXPLICIT = "explicit state space"
REALISED = "state equation, solution realised as a firing sequence"
STRUCTURE_SECONDS = 2.0  # each structural computation; results say when they were cut off
SEARCH_SHARE = 0.8  # of the command's time limit, for the explicit search; the rest: proofs
STRUCTURE_FACTS = ("invariants", "structural_boundedness", "siphons_traps")
QUICK_COVERABILITY_NODES = 2_000
QUICK_COVERABILITY_SECONDS = 1.0
QUICK_COVERABILITY_SHARE = 0.1  # of the time left, at most, for the quick tree
QUICK_COVERABILITY_CELLS = 2_000_000  # place values the quick tree may hold (node_cap)
COVERABILITY_SECONDS = 10.0
COVERABILITY_CELLS = 20_000_000  # place values the full tree may hold (320 MB)
PAIR_SECONDS = 10.0  # each state-equation proof that two resources never meet
UNBOUNDED_STATES = 20_000
REALISE_NODES = 20_000  # firing orders tried to turn a state-equation solution into a trace
UNBOUNDED_SECONDS = 3.0
EXPLICIT_POR = "explicit state space (stubborn-set reduced)"
REDUCED = "structural reductions + explicit state space of the reduced net"
REDUCED_BY = {
    "random walk": "structural reductions + random walk on the reduced net",
    "siphon-trap": "structural reductions + siphon-trap property of the reduced net",
}
"""The method of a deadlock verdict the reduced net decided without its search
(`analysis.reduce.deadlock.DeadlockAnswer.by`)."""
AUTO_SYMBOLIC_SHARE = 0.5  # of the time left, for decision diagrams after an explicit stop
SYMBOLIC_SETUP_SECONDS_PER_ARC = 50e-6
"""What setting up decision diagrams (invariants, place and level order, transition
steps or relations) costs per arc and place, with room to spare: 1.3-1.4 s (23-31 us
each) on the 42,000 and 60,000 places and arcs of two generated wide nets. The set-up
reads the budget between its stages, but a share below this stops it before any
fixpoint: after an explicit stop the diagrams are then not started (said in the
inconclusive verdicts), leaving the time to the stages after them."""
TIMED = "timed analysis (zones)"
UNTIMED_WITHIN = "decided by timed analysis: run coral-check verify --timed"
NO_PROFILE = "no vehicle profile: timed analysis needs the mission's profile"


@dataclass(frozen=True)
class VerifyOptions:
    """Budgets and switches for `verify`.

    Attributes:
        max_states: State budget for the explicit search (None: no limit).
        time_limit: Seconds for the explicit search (None: no limit).
        por: Explore a stubborn-set reduced graph: keeps every deadlock and the values
            of the places properties look at, with fewer states. State counts then
            describe the reduced graph; bounds come from coverability.
        structural: Also compute invariants, structural boundedness, siphons/traps.
        z3_timeout_ms: Cap of each z3 query, in milliseconds (the name is kept: it is
            recorded in certificates); `analysis.budget.Budget.z3_timeout_ms` turns the
            remaining time back into z3's milliseconds.
        coverability_nodes: Node budget of the Karp-Miller tree grown when the explicit
            search is incomplete (a small tree is always built first: it proves an
            unbounded net unbounded in milliseconds).
        progress: Called during long explorations (see `analysis.progress`).
        max_deadlocks: Dead non-final markings the ``deadlock`` property lists, each
            with its own shortest trace; the rest are counted.
        max_edges: Edge budget of the reachability graph the termination properties
            need (`analysis.termination`; 12 bytes an edge); past it they are
            inconclusive (None: no limit).
        timed: Also run timed analysis (`analysis.timed`) under these link bounds and
            budget: mission time bounds, time-out adequacy, ``within`` deadlines. None:
            untimed, and ``within`` assertions are inconclusive.
        memory_limit: Bytes of resident memory the process may use (None: the caller's
            budget's, or none). Past it the search stops, the verdicts it left open are
            "inconclusive: memory limit of X reached after N states", never a crash.
        method: "explicit", "symbolic" (the reachable markings as a decision diagram,
            `analysis.symbolic`: exact counts, bounds, boundedness and deadlock on nets
            no explicit search can store) or "auto" (explicit, then symbolic when the
            explicit search stopped before the end on a net the diagrams model, with a
            state budget of at least `AUTO_SYMBOLIC_MIN_STATES`).
    """

    max_states: int | None = 2_000_000
    time_limit: float | None = 120.0
    por: bool = False
    structural: bool = True
    z3_timeout_ms: int = 10_000
    coverability_nodes: int = 20_000
    progress: ProgressCallback | None = None
    max_deadlocks: int = DEFAULT_MAX_DEADLOCKS
    max_edges: int | None = DEFAULT_MAX_EDGES
    timed: TimedOptions | None = None
    memory_limit: int | None = None
    method: str = "auto"


def verify(
    net: Net,
    options: VerifyOptions | None = None,
    *,
    budget: Budget | None = None,
    profiles: Sequence[VehicleProfile] = (),
) -> Report:
    """Decide every property of ``net``; see the module docstring for the methods.
    ``profiles`` (the mission's vehicle profile) are what timed analysis needs."""
    return run_verification(net, options, budget=budget, profiles=profiles).report


@dataclass(frozen=True)
class Verification:
    """A report together with the state space it was decided on.

    Attributes:
        report: The verdicts.
        space: The explicit state space the verdicts were read from (None when the net
            was too large to encode). ``coral-check`` hands it to `analysis.lint`, so the
            reachable markings are explored once per run, not once per tool. It can be
            large: drop it once it has been used.
    """

    report: Report
    space: StateSpace | None


def run_verification(
    net: Net,
    options: VerifyOptions | None = None,
    *,
    budget: Budget | None = None,
    profiles: Sequence[VehicleProfile] = (),
) -> Verification:
    """`verify`, keeping the explored state space for callers that look further.

    Args:
        net: The net.
        options: Budgets (each stage's own: ``time_limit`` for the explicit search...)
            and switches.
        budget: The run's budget: its clock times every stage (tests pass a fake one)
            and every stage's slice ends by its deadline. None: no overall limit.
        profiles: The vehicle profiles the mission was compiled against: timed analysis
            takes work times from them (a PNML net has none: timed analysis is then
            inconclusive).
    """
    options = options or VerifyOptions()
    # One budget for the whole command: ``time_limit`` bounds every stage (search,
    # proofs, termination, timed analysis, structure), not only the search. A stage
    # that finds it spent says so and the later ones report inconclusive, unrun.
    budget = (budget or Budget()).child(seconds=options.time_limit)
    if options.memory_limit is not None:
        budget.memory = options.memory_limit
    started = budget.clock()
    # The digest first, inside the limit: it cannot be cut, and after the stages it
    # was part of the margin past the limit (0.1 s on 20,000 places).
    digest = net.digest()
    try:
        checker = _Checker(net, options, budget)
    except MemoryError:
        reason = f"not analysed: {memory_limit_reason(budget.memory)} before the search"
        return Verification(_unanalysed(net, reason, budget.clock() - started), None)
    stages: list[tuple[str, Callable[[], list[PropertyResult]]]] = [
        ("boundedness", lambda: [checker.bounded()]),
        ("deadlock", lambda: [checker.deadlock()]),
        ("final markings", checker.final_reachable),
        ("termination", checker.termination),
        ("dead transitions", lambda: [checker.dead_transitions()]),
        ("never marked places", lambda: [checker.never_marked_places()]),
        ("resource conflicts", checker.resource_conflicts),
        ("assertions", checker.assertions),
    ]
    properties: list[PropertyResult] = []
    for name, run in stages:
        try:
            properties += run()
        except MemoryError:
            properties.append(_out_of_memory(budget, checker, name))
            break
    timed = None
    if options.timed is not None:
        left = budget.remaining()
        timed_options = options.timed
        if left is not None:
            limit = left if timed_options.time_limit_s is None else timed_options.time_limit_s
            timed_options = replace(timed_options, time_limit_s=min(limit, left))
        timed_options = replace(timed_options, memory_limit=budget.memory)
        try:
            properties, timed = _timed(net, profiles, timed_options, properties)
        except MemoryError:
            properties.append(_out_of_memory(budget, checker, "timed analysis"))
    structure: dict[str, object] = {}
    if options.structural:
        try:
            structure = checker.structure()
        except MemoryError:
            structure = {"summary": f"not computed: {memory_limit_reason(budget.memory)}"}
    report = Report(
        net_name=net.name,
        digest=digest,
        sources=net.sources,
        statespace=checker.figures(),
        properties=properties,
        structure=structure,
        seconds=budget.clock() - started,
        timed=timed,
    )
    return Verification(report, checker.space)


def _out_of_memory(budget: Budget, checker: _Checker, stage: str) -> PropertyResult:
    """The verdict of a stage stopped by a failed allocation: inconclusive, naming the
    limit and what was explored; the properties after it were not analysed."""
    reason = memory_limit_reason(budget.memory, checker.space.states)
    return PropertyResult(
        "analysis",
        "every property analysed",
        Verdict.INCONCLUSIVE,
        checker.method,
        f"inconclusive: {reason}, in {stage}; the properties after it were not analysed",
    )


def _unanalysed(net: Net, reason: str, seconds: float) -> Report:
    """Every property inconclusive for ``reason``, with no state space."""
    keys = [("bounded", "the net is bounded"), ("deadlock", "no deadlock")]
    return Report(
        net_name=net.name,
        digest=net.digest(),
        sources=net.sources,
        statespace=StateSpaceFigures(
            states=0,
            edges=0,
            max_tokens_place=0,
            max_tokens_marking=0,
            place_bounds={},
            complete=False,
            stopped_reason=reason,
            reduced=False,
            seconds=0.0,
            bytes_per_state=0.0,
        ),
        properties=[
            PropertyResult(key, title, Verdict.INCONCLUSIVE, "none", reason) for key, title in keys
        ],
        seconds=seconds,
    )


class _Checker:
    def __init__(self, net: Net, options: VerifyOptions, budget: Budget) -> None:
        self.net = net
        self.options = options
        self.budget = budget
        self.query_seconds = options.z3_timeout_ms / 1000
        visible = None
        if options.por:
            watched = {p for a in net.assertions for p, _ in a.places}
            watched |= {p.name for p in net.places if p.kind is PlaceKind.PENDING and p.resources}
            for final in net.finals:
                watched |= {p for p, _ in final.tokens}
            visible = sorted(watched)
        # A small Karp-Miller tree first: on an unbounded net it proves unboundedness in
        # milliseconds, and the explicit search is then only worth a small budget (it
        # can still find real counterexamples for the other properties).
        # On a wide net each node costs the width of the net: the quick tree keeps to
        # a number of place values (2,000 nodes up to 1,000 places) and to a tenth of
        # the time left, so it stays quick whatever the net and the limit.
        left = budget.remaining()
        quick = QUICK_COVERABILITY_SECONDS
        if left is not None:  # (two digits: the slice is quoted when it stops the tree)
            quick = float(f"{min(quick, left * QUICK_COVERABILITY_SHARE):.2g}")
        self.cover = coverability(
            net,
            max_nodes=node_cap(QUICK_COVERABILITY_NODES, net, QUICK_COVERABILITY_CELLS),
            budget=budget.child(seconds=quick),
        )
        self.symbolic: SymbolicResult | None = None
        if options.method == "symbolic":
            self.symbolic = self._symbolic(SEARCH_SHARE)
        max_states, time_limit = options.max_states, options.time_limit
        if self.symbolic is not None and self.symbolic.complete:
            # the diagram holds every answer it can give: the explicit search only looks
            # for counterexamples (with shortest traces) to the other properties
            max_states = min(max_states or UNBOUNDED_STATES, UNBOUNDED_STATES)
            time_limit = min(time_limit or UNBOUNDED_SECONDS, UNBOUNDED_SECONDS)
        if self.cover.bounded is False:
            max_states = min(max_states or UNBOUNDED_STATES, UNBOUNDED_STATES)
            time_limit = min(time_limit or UNBOUNDED_SECONDS, UNBOUNDED_SECONDS)
        left = budget.remaining()
        shared = time_limit is not None and left is not None and left * SEARCH_SHARE < time_limit
        if shared and left is not None:
            # The search gets a share of what is left of the command's limit (reading
            # the file and the quick tree came first), so the proofs that need no
            # complete state space (the state equation, coverability) still run.
            time_limit = left * SEARCH_SHARE
        # (shared, its reason names the limit the user set, not the share)
        search = budget.child(seconds=time_limit, share=shared)
        before = resident_bytes()
        self.space: StateSpace = explore(
            net,
            max_states=max_states,
            budget=search,
            por=options.por,
            visible=visible,
            progress=options.progress,
        )
        # What the search really cost: the peak's growth over the resident memory
        # before it (the peak of the whole process, so a larger earlier peak hides it:
        # then the stored tables' figure is the better one, and is reported too).
        self.search_bytes = max(0, peak_resident_bytes() - before)
        self.exact = self.space.complete and not self.space.reduced
        self.method = EXPLICIT_POR if self.space.reduced else EXPLICIT
        self._graph: StateGraph | GraphError | None = None
        # Why the decision diagrams did not run after an explicit stop, when it was
        # the time left: quoted with every verdict the incomplete search left open.
        self.symbolic_skipped = ""
        if (
            options.method == "auto"
            and not self.space.complete
            and not self.space.reduced
            and self.cover.bounded is not False
            and (options.max_states is None or options.max_states >= AUTO_SYMBOLIC_MIN_STATES)
            and symbolic_applicable(net)
            and not self.budget.expired()  # (a search stopped by the time limit left none)
        ):
            self.symbolic_skipped = self._symbolic_too_slow(AUTO_SYMBOLIC_SHARE)
            if not self.symbolic_skipped:
                self.symbolic = self._symbolic(AUTO_SYMBOLIC_SHARE)

    def _symbolic_too_slow(self, share: float) -> str:
        """Why ``share`` of the time left is too short to set up decision diagrams on
        this net (`SYMBOLIC_SETUP_SECONDS_PER_ARC`), or "" when it is not."""
        left = self.budget.remaining()
        if left is None:
            return ""
        net = self.net
        size = len(net.places) + net.arc_count
        needed = size * SYMBOLIC_SETUP_SECONDS_PER_ARC
        if left * share >= needed:
            return ""
        return (
            f"decision diagrams not run: {left:.1f} s left of the time limit of "
            f"{self.budget.limit:g} s, and setting them up on {size:,} places and arcs "
            f"takes about {needed:.1f} s"
        )

    def _symbolic(self, share: float) -> SymbolicResult:
        """The reachable markings as a decision diagram, with ``share`` of the time
        left (and the command's memory limit, through its budget)."""
        from analysis.symbolic.explore import SymbolicLimits, explore_symbolic

        left = self.budget.remaining()
        # (its reason names the limit the user set, not the share)
        budget = self.budget.child(
            seconds=None if left is None else left * share, share=left is not None
        )
        return explore_symbolic(self.net, SymbolicLimits(budget=budget))

    @property
    def symbolic_exact(self) -> SymbolicResult | None:
        """The symbolic result when it is complete (every reachable marking), else None."""
        if self.symbolic is not None and self.symbolic.complete:
            return self.symbolic
        return None

    # -- helpers ------------------------------------------------------------------------

    def state_graph(self) -> StateGraph:
        """The reachability graph of the explored space, built on first use and then
        shared by every property that needs edges; raises `GraphError` (also cached)
        when the space is incomplete or reduced."""
        if self._graph is None:
            try:
                self._graph = build_graph(
                    self.space,
                    max_edges=self.options.max_edges,
                    budget=self.budget.child(seconds=self.options.time_limit),
                )
            except GraphError as exc:
                self._graph = exc
        if isinstance(self._graph, GraphError):
            raise self._graph
        return self._graph

    def figures(self) -> StateSpaceFigures:
        space = self.space
        sym = self.symbolic
        if sym is not None and (sym.complete or (not space.complete and sym.states > space.states)):
            # the diagram's figures when exact, or when its lower bound is the better one
            return symbolic_figures(sym)
        return StateSpaceFigures(
            states=space.states,
            edges=space.edges,
            max_tokens_place=space.max_tokens_place,
            max_tokens_marking=space.max_tokens_marking,
            place_bounds={
                p.name: int(b) for p, b in zip(self.net.places, space.place_bounds, strict=True)
            },
            complete=space.complete,
            stopped_reason=space.stopped_reason,
            reduced=space.reduced,
            reduction_note=space.reduction_note,
            seconds=space.seconds,
            bytes_per_state=max(self.search_bytes / max(1, space.states), space.bytes_per_state),
            stored_bytes_per_state=space.bytes_per_state,
        )

    def _incomplete(self) -> str:
        if self.space.reduced and self.space.complete:
            return "the reduced state space does not decide this"
        text = f"the state space is incomplete ({self.space.stopped_reason})"
        if self.symbolic_skipped:
            text += f"; {self.symbolic_skipped}"
        elif self.symbolic is not None and not self.symbolic.complete:
            text += f"; decision diagrams stopped: {self.symbolic.reason}"
        return text

    def _witness(self, state: int) -> Evidence:
        return witness(self.space, state)

    def _search_then_prove(
        self,
        key: str,
        title: str,
        predicate: Predicate,
        bad: Callable[[], stateeq.BadMarkings],
        location: Span | None = None,
        found_detail: str = "",
    ) -> PropertyResult:
        """A safety property: violated if search finds a bad marking, proven if the
        search was exhaustive or the state equation excludes bad markings (``bad``
        builds them, only when the state equation is needed)."""
        hit = self.space.find(predicate)
        if hit is not None:
            depth = self.space.depth_of(hit)
            return PropertyResult(
                key,
                title,
                Verdict.VIOLATED,
                self.method,
                found_detail or f"reachable in {depth} step(s); shortest trace below",
                self._witness(hit),
                location,
            )
        if self.space.complete and (not self.space.reduced or self.options.por):
            # the reduced graph keeps every value of the visible places it watches
            return PropertyResult(
                key,
                title,
                Verdict.PROVEN,
                self.method,
                f"no bad marking among all {self.space.states} reachable states",
                None,
                location,
            )
        from analysis import stateeq

        result, evidence = self._state_equation(bad())
        if isinstance(result, stateeq.Proven):
            return PropertyResult(
                key, title, Verdict.PROVEN, result.method, result.explain(), None, location
            )
        if evidence is not None:
            return PropertyResult(
                key,
                title,
                Verdict.VIOLATED,
                REALISED,
                f"reachable in {len(evidence.trace)} step(s) (not necessarily shortest)",
                evidence,
                location,
            )
        return PropertyResult(
            key,
            title,
            Verdict.INCONCLUSIVE,
            f"{self.method}; {result.method}",
            f"{self._incomplete()}; {result.explain()}",
            None,
            location,
        )

    def _state_equation(
        self, bad: stateeq.BadMarkings, seconds: float = 30.0
    ) -> tuple[stateeq.StateEquationResult, Evidence | None]:
        """Run the state equation; a Candidate is confirmed only if some firing order of
        its counts replays on the net and ends in a bad marking (then it is real)."""
        from analysis import stateeq

        if self.budget.expired():
            # Building the equation alone takes seconds on a wide net: not past the limit.
            reason = f"not run: {self.budget.time_reason()} before the state equation"
            return stateeq.Unknown(bad=bad, reason=reason), None
        result = stateeq.check_unreachable(
            self.net,
            bad,
            query_seconds=self.query_seconds,
            budget=self.budget.child(seconds=seconds),
        )
        if not isinstance(result, stateeq.Candidate):
            return result, None
        sequence = stateeq.realise(self.net, result, max_nodes=REALISE_NODES)
        if sequence is None:
            return result, None
        marking = self.net.initial_marking()
        for t in sequence:
            transition = self.net.transitions[t]
            if not self.net.enabled(marking, transition):
                return result, None
            marking = self.net.fire(marking, transition)
        if not bad.matches(self.net, marking):
            return result, None
        return result, Evidence(
            trace=make_trace(self.net, sequence),
            marking=self.net.marking_dict(marking),
            note="found by ordering a solution of the state equation; replayed on the net",
        )

    # -- properties -----------------------------------------------------------------------

    def bounded(self) -> PropertyResult:
        title = "the net is bounded"
        sym = self.symbolic_exact
        if sym is not None and (not self.exact or self.options.method == "symbolic"):
            return PropertyResult(
                "bounded",
                title,
                Verdict.PROVEN,
                SYMBOLIC,
                f"every place holds at most {sym.max_tokens_place} token(s) "
                f"in all {sym.states} reachable states",
            )
        if self.exact:
            return PropertyResult(
                "bounded",
                title,
                Verdict.PROVEN,
                self.method,
                f"every place holds at most {self.space.max_tokens_place} token(s) "
                f"in all {self.space.states} reachable states",
            )
        result = self.cover
        if result.bounded is None and not self.budget.expired():
            # the quick tree was cut off: grow a full one
            result = coverability(
                self.net,
                max_nodes=node_cap(self.options.coverability_nodes, self.net, COVERABILITY_CELLS),
                budget=self.budget.child(seconds=COVERABILITY_SECONDS),
            )
        if result.bounded is False:
            # The evidence is the pump of the first unbounded place that has one: the
            # first place may have none while a later one does, and the detail promises
            # a replayable trace whenever any place has one.
            name = next((n for n in result.unbounded if n in result.pumps), result.unbounded[0])
            pump = result.pumps.get(name)
            evidence = None
            if pump is not None:
                evidence = Evidence(
                    trace=make_trace(self.net, pump.prefix),
                    loop=make_trace(self.net, pump.loop, start=len(pump.prefix) + 1),
                    note=pump.explain(),
                )
            return PropertyResult(
                "bounded",
                title,
                Verdict.VIOLATED,
                result.method,
                result.explain(),
                evidence,
                items=result.unbounded,
            )
        if result.bounded:
            return PropertyResult("bounded", title, Verdict.PROVEN, result.method, result.explain())
        if self.budget.expired():
            # z3's linear program takes its time building constraints, past any limit
            return PropertyResult(
                "bounded",
                title,
                Verdict.INCONCLUSIVE,
                f"{self.method}; {result.method}",
                f"{self._incomplete()}; {result.explain()}; structural boundedness not "
                f"run: {self.budget.time_reason()}",
            )
        from analysis.structural import structural_boundedness

        structural = structural_boundedness(
            self.net,
            query_seconds=self.query_seconds,
            per_place=False,
            budget=self.budget.child(),
        )
        if structural.structurally_bounded:
            return PropertyResult(
                "bounded", title, Verdict.PROVEN, structural.method, structural.explain()
            )
        return PropertyResult(
            "bounded",
            title,
            Verdict.INCONCLUSIVE,
            f"{self.method}; {result.method}",
            f"{self._incomplete()}; {result.explain()}",
        )

    def deadlock(self) -> PropertyResult:
        net = self.net
        title = "no deadlock (every dead marking is a declared final marking)"
        if not net.finals:
            title = "no deadlock (no reachable marking without an enabled transition)"
        sym = self.symbolic_exact
        stuck = non_final_dead_states(self.space)
        asked = self.options.method == "symbolic"
        if sym is not None and (asked or (not self.space.complete and not stuck.size)):
            decided = symbolic_deadlock(net, sym, title)
            if decided is not None:
                return decided
        if stuck.size:
            state = int(stuck[0])
            depth = self.space.depth_of(state)
            shortest = "" if self.space.reduced else "shortest "
            what = (
                "a dead marking that is not a declared final marking"
                if net.finals
                else ("a marking in which no transition is enabled")
            )
            listed = stuck[: max(1, self.options.max_deadlocks)]
            detail = f"{what} is reachable in {depth} step(s); {shortest}trace below"
            if stuck.size > 1:
                found = "in all" if self.space.complete else "found"
                detail += f"; {stuck.size} such dead markings {found}, each with its own trace"
                if listed.size < stuck.size:
                    detail += f" (the first {listed.size} listed)"
            return PropertyResult(
                "deadlock",
                title,
                Verdict.VIOLATED,
                self.method,
                detail,
                self._witness(state),
                more_evidence=tuple(self._witness(int(s)) for s in listed[1:]),
                omitted=int(stuck.size - listed.size),
            )
        if self.space.complete:
            ends = len(self.space.deadlocks)
            return PropertyResult(
                "deadlock",
                title,
                Verdict.PROVEN,
                self.method,
                f"all {self.space.states} reachable states explored; "
                f"{ends} dead marking(s), all declared final",
            )
        reduced = self._deadlock_by_reduction(title)
        if reduced is not None:
            return reduced
        from analysis import stateeq

        result, evidence = self._state_equation(stateeq.unexpected_deadlocks(net))
        if isinstance(result, stateeq.Proven):
            return PropertyResult(
                "deadlock", title, Verdict.PROVEN, result.method, result.explain()
            )
        if evidence is not None:
            return PropertyResult(
                "deadlock",
                title,
                Verdict.VIOLATED,
                REALISED,
                f"a deadlock is reachable in {len(evidence.trace)} step(s) "
                "(not necessarily shortest)",
                evidence,
            )
        return PropertyResult(
            "deadlock",
            title,
            Verdict.INCONCLUSIVE,
            f"{self.method}; {result.method}",
            f"{self._incomplete()}; {result.explain()}",
        )

    def _deadlock_by_reduction(self, title: str) -> PropertyResult | None:
        """When the full search stopped undecided: structural reductions (`analysis.reduce`)
        and a search of the reduced net within half of what is left of the budget. The
        declared finals' places are protected, so the reduced net's dead markings are
        final exactly when the original's are; a witness is replayed on this net. None
        when the net is not reducible or the reduced search does not decide either."""
        from analysis.reduce import decide_deadlock
        from analysis.reduce.driver import reducible

        if not reducible(self.net) or self.budget.expired():
            return None
        left = self.budget.remaining()
        test = self.net.final_test()
        max_states = self.options.max_states
        if self.cover.bounded is False:  # as for the full search: a small budget only
            max_states = min(max_states or UNBOUNDED_STATES, UNBOUNDED_STATES)
        answer = decide_deadlock(
            self.net,
            max_states=max_states,
            budget=self.budget.child(seconds=None if left is None else left / 2),
            accepted=test.matches if self.net.finals else None,
        )
        if answer.deadlock is None:
            return None
        size = answer.reduction.summary()
        method = REDUCED_BY.get(answer.by, REDUCED)
        if not answer.deadlock:
            return PropertyResult(
                "deadlock",
                title,
                Verdict.PROVEN,
                method,
                f"{answer.proof} ({size})"
                if answer.proof
                else f"all {answer.states} reachable states of the reduced net explored ({size}); "
                + (
                    "every dead marking is a declared final marking"
                    if self.net.finals
                    else "no dead marking"
                ),
            )
        trace = answer.trace or []
        index = {t.name: i for i, t in enumerate(self.net.transitions)}
        sequence = [index[name] for name in trace]
        marking = self.net.initial_marking()
        for i in sequence:
            marking = self.net.fire(marking, self.net.transitions[i])
        return PropertyResult(
            "deadlock",
            title,
            Verdict.VIOLATED,
            method,
            f"{'a non-final dead marking' if self.net.finals else 'a dead marking'}"
            f" is reachable in {len(sequence)} step(s) (found on the reduced net: {size}; "
            "trace mapped back and replayed on this net)",
            Evidence(
                trace=make_trace(self.net, sequence),
                marking=self.net.marking_dict(marking),
                note="found on the structurally reduced net; replayed on the original",
            ),
        )

    def termination(self) -> list[PropertyResult]:
        """``no_engine_cycle``, ``final_always_reachable``, ``terminates`` (for missions;
        see `analysis.termination`)."""
        bounded = self.cover.bounded is not False  # else the small budgets, as above
        return check_termination(
            self.space,
            TerminationLimits(
                max_edges=self.options.max_edges,
                max_states=self.options.max_states if bounded else UNBOUNDED_STATES,
                time_limit=self.options.time_limit if bounded else UNBOUNDED_SECONDS,
            ),
            self.state_graph,
            self.budget,
        )

    def final_reachable(self) -> list[PropertyResult]:
        net = self.net
        if not net.finals:
            return []
        title = "a declared final marking is reachable"
        finals = FinalPatterns.of(net)
        hit = self.space.find(lambda block: final_rows(block, finals))
        if hit is not None:
            reached = format_tokens(self.net.marking_dict(self.space.marking(hit)).items())
            return [
                PropertyResult(
                    "final_reachable",
                    title,
                    Verdict.PROVEN,
                    self.method,
                    f"{reached} reached in {self.space.depth_of(hit)} step(s)",
                    self._witness(hit),
                )
            ]
        if self.exact:
            return [
                PropertyResult(
                    "final_reachable",
                    title,
                    Verdict.VIOLATED,
                    self.method,
                    f"none of the {len(net.finals)} final marking(s) is among all "
                    f"{self.space.states} reachable states: the mission can never end properly",
                )
            ]
        return [
            PropertyResult(
                "final_reachable",
                title,
                Verdict.INCONCLUSIVE,
                self.method,
                f"no final marking found; {self._incomplete()}",
            )
        ]

    def dead_transitions(self) -> PropertyResult:
        title = "every transition can fire (no dead transitions)"
        never = [self.net.transitions[int(t)].name for t in self.space.dead_transitions]
        if not never:
            return PropertyResult(
                "dead_transitions",
                title,
                Verdict.PROVEN,
                self.method,
                f"all {len(self.net.transitions)} transitions fire in some reachable state",
            )
        if self.exact:
            shown = ", ".join(never[:10]) + (" ..." if len(never) > 10 else "")
            return PropertyResult(
                "dead_transitions",
                title,
                Verdict.VIOLATED,
                self.method,
                f"{len(never)} transition(s) can never fire: {shown}",
                items=tuple(never),
            )
        return PropertyResult(
            "dead_transitions",
            title,
            Verdict.INCONCLUSIVE,
            self.method,
            f"{len(never)} transition(s) not seen firing; {self._incomplete()}",
            items=tuple(never),
        )

    def never_marked_places(self) -> PropertyResult:
        title = "every place can be marked"
        unmarked = [
            p.name
            for p, bound in zip(self.net.places, self.space.place_bounds, strict=True)
            if bound == 0 and p.kind is PlaceKind.MISSION
        ]
        if not unmarked:
            return PropertyResult(
                "never_marked_places",
                title,
                Verdict.PROVEN,
                self.method,
                "every place holds a token in some reachable state",
            )
        if self.exact:
            return PropertyResult(
                "never_marked_places",
                title,
                Verdict.VIOLATED,
                self.method,
                f"{len(unmarked)} place(s) never hold a token: {', '.join(unmarked[:10])}"
                + (" ..." if len(unmarked) > 10 else ""),
                items=tuple(unmarked),
            )
        return PropertyResult(
            "never_marked_places",
            title,
            Verdict.INCONCLUSIVE,
            self.method,
            f"{len(unmarked)} place(s) not seen marked; {self._incomplete()}",
            items=tuple(unmarked),
        )

    def resource_conflicts(self) -> list[PropertyResult]:
        net = self.net
        pending = [p for p in net.places if p.kind is PlaceKind.PENDING and p.resources]
        if not pending:
            return []
        pairs = [
            (a, b)
            for a, b in itertools.combinations(pending, 2)
            if set(a.resources) & set(b.resources)
        ]
        columns = [(net.place_index(a.name), net.place_index(b.name)) for a, b in pairs]
        singles = [net.place_index(p.name) for p in pending]

        def conflict(block: Markings) -> npt.NDArray[np.bool_]:
            hit = np.zeros(len(block), dtype=bool)
            for i, j in columns:
                hit |= (block[:, i] > 0) & (block[:, j] > 0)
            for i in singles:
                hit |= block[:, i] > 1
            return hit

        title = "no two commands in flight on one vehicle resource"
        hit = self.space.find(conflict)
        if hit is not None:
            marking = self.space.marking(hit)
            busy = [p for p in pending if marking[net.place_index(p.name)] > 0]
            shared = sorted(
                {
                    r
                    for a, b in itertools.combinations(busy, 2)
                    for r in set(a.resources) & set(b.resources)
                }
                | {r for p in busy if marking[net.place_index(p.name)] > 1 for r in p.resources}
            )
            names = [p.pending_of or p.name for p in busy]
            return [
                PropertyResult(
                    "resource_conflicts",
                    title,
                    Verdict.VIOLATED,
                    self.method,
                    f"{' and '.join(names)} in flight together, both driving {', '.join(shared)}; "
                    f"reachable in {self.space.depth_of(hit)} step(s)",
                    self._witness(hit),
                    items=tuple(names),
                )
            ]
        if self.space.complete:
            return [
                PropertyResult(
                    "resource_conflicts",
                    title,
                    Verdict.PROVEN,
                    self.method,
                    f"checked {len(pairs)} pair(s) of commands sharing a resource "
                    f"in all {self.space.states} reachable states",
                )
            ]
        from analysis import stateeq

        unproven = []
        for a, b in pairs:
            result = stateeq.check_unreachable(
                net,
                stateeq.never_together([a.name, b.name]),
                query_seconds=self.query_seconds,
                budget=self.budget.child(seconds=PAIR_SECONDS),
            )
            if not isinstance(result, stateeq.Proven):
                unproven.append(f"{a.pending_of} with {b.pending_of}")
        for p in pending:
            result = stateeq.check_unreachable(
                net,
                stateeq.above_bound([p.name], 1),
                query_seconds=self.query_seconds,
                budget=self.budget.child(seconds=PAIR_SECONDS),
            )
            if not isinstance(result, stateeq.Proven):
                unproven.append(f"{p.pending_of} twice")
        if not unproven:
            return [
                PropertyResult(
                    "resource_conflicts",
                    title,
                    Verdict.PROVEN,
                    stateeq.METHOD,
                    f"the state equation excludes all {len(pairs)} conflicting pair(s)",
                )
            ]
        return [
            PropertyResult(
                "resource_conflicts",
                title,
                Verdict.INCONCLUSIVE,
                f"{self.method}; {stateeq.METHOD}",
                f"{self._incomplete()}; not excluded: {', '.join(unproven[:5])}",
            )
        ]

    def assertions(self) -> list[PropertyResult]:
        results = []
        for number, assertion in enumerate(self.net.assertions, start=1):
            key = f"assert:{number}"
            if assertion.temporal:
                from analysis.temporal import check_temporal

                results.append(
                    check_temporal(self.net, self.space, self.state_graph, assertion, key)
                )
                continue
            title = assertion.describe()
            if assertion.kind is AssertKind.WITHIN:
                # A deadline is about time, which the untimed state space has none of:
                # `_timed` replaces this verdict when the verification is timed.
                results.append(
                    PropertyResult(
                        key,
                        title,
                        Verdict.INCONCLUSIVE,
                        self.method,
                        UNTIMED_WITHIN,
                        span=assertion.span,
                    )
                )
                continue
            columns = [(self.net.place_index(p), w) for p, w in assertion.places]

            def covers(
                block: Markings, cols: list[tuple[int, int]] = columns
            ) -> npt.NDArray[np.bool_]:
                hit = np.ones(len(block), dtype=bool)
                for i, w in cols:
                    hit &= block[:, i] >= w
                return hit

            covering = partial(_covering, assertion.places, title)
            if assertion.kind is AssertKind.NEVER:
                results.append(
                    self._search_then_prove(
                        key,
                        title,
                        covers,
                        covering,
                        assertion.span,
                    )
                )
            elif assertion.kind is AssertKind.BOUND:
                bound = assertion.bound or 0
                cols = [i for i, _ in columns]
                # ``assert bound {p*2, q} <= k`` bounds the weighted sum 2*M(p) + M(q):
                # a weight is part of what the mission says, never dropped.
                weights = np.array([w for _, w in columns], dtype=np.int64)

                def above(
                    block: Markings,
                    cols: list[int] = cols,
                    weights: npt.NDArray[np.int64] = weights,
                    k: int = bound,
                ) -> npt.NDArray[np.bool_]:
                    if (weights == 1).all():  # the common case, kept vectorised
                        over: npt.NDArray[np.bool_] = block[:, cols].sum(axis=1) > k
                        return over
                    # object dtype: exact Python ints, so a large count times a large
                    # weight cannot wrap around int64 and hide a violation.
                    total = block[:, cols].astype(object) @ weights.astype(object)
                    return np.asarray(total > k, dtype=bool)

                results.append(
                    self._search_then_prove(
                        key,
                        title,
                        above,
                        partial(_above, assertion.places, bound),
                        assertion.span,
                    )
                )
            else:
                results.append(self._reachable(key, title, covers, covering, assertion.span))
        return results

    def _reachable(
        self,
        key: str,
        title: str,
        predicate: Predicate,
        wanted: Callable[[], stateeq.BadMarkings],
        location: Span | None,
    ) -> PropertyResult:
        hit = self.space.find(predicate)
        if hit is not None:
            return PropertyResult(
                key,
                title,
                Verdict.PROVEN,
                self.method,
                f"reached in {self.space.depth_of(hit)} step(s)",
                self._witness(hit),
                location,
            )
        if self.space.complete:
            return PropertyResult(
                key,
                title,
                Verdict.VIOLATED,
                self.method,
                f"no marking among all {self.space.states} reachable states has these tokens",
                None,
                location,
            )
        from analysis import stateeq

        result, evidence = self._state_equation(wanted())
        if evidence is not None:
            return PropertyResult(
                key,
                title,
                Verdict.PROVEN,
                REALISED,
                f"reached in {len(evidence.trace)} step(s)",
                evidence,
                location,
            )
        if isinstance(result, stateeq.Proven):
            return PropertyResult(
                key,
                title,
                Verdict.VIOLATED,
                result.method,
                "unreachable: " + result.explain(),
                None,
                location,
            )
        return PropertyResult(
            key,
            title,
            Verdict.INCONCLUSIVE,
            f"{self.method}; {result.method}",
            f"not found; {self._incomplete()}; {result.explain()}",
            None,
            location,
        )

    # -- structure --------------------------------------------------------------------------

    def structure(self) -> dict[str, object]:
        """Structural facts for the report; each computation has its own time slice,
        inside the command's budget: once that is spent the remaining ones are
        reported as not computed, naming the limit, instead of running."""
        from analysis.invariants import invariant_report
        from analysis.siphons import siphon_trap_check
        from analysis.structural import classify, structural_boundedness

        net = self.net
        facts: dict[str, object] = {
            "places": len(net.places),
            "transitions": len(net.transitions),
            "arcs": net.arc_count,
        }
        # Near-linear in the arcs (see `classify`): always computed.
        facts["class"] = list(classify(net).names())
        if self._spent(facts, "invariants", "invariants"):
            return facts
        invariants = invariant_report(net, budget=self.budget.child(seconds=STRUCTURE_SECONDS))
        facts["invariants"] = {
            "summary": invariants.explain(),
            "p_invariants": [inv.describe() for inv in invariants.p.invariants[:50]],
            "t_invariants": [inv.describe() for inv in invariants.t.invariants[:50]],
            "conservative": invariants.conservative,
            "covered_by_p_invariants": invariants.covered_by_p,
            "consistent": invariants.consistent,
        }
        if invariants.covered_by_p:
            # The sum of the covering invariants is a weighting y > 0 with y^T C = 0:
            # the linear program (and loading z3 for it) would only say so again.
            facts["structural_boundedness"] = {
                "verdict": True,
                "summary": "structurally bounded: the P-invariants cover every place, so "
                "their sum is a positive weighting y with y^T C = 0",
            }
        else:
            if self._spent(facts, "structural_boundedness", "structural boundedness"):
                return facts
            bounded = structural_boundedness(
                net,
                query_seconds=self.query_seconds,
                per_place=False,
                budget=self.budget.child(seconds=STRUCTURE_SECONDS),
            )
            facts["structural_boundedness"] = {
                "verdict": bounded.structurally_bounded,
                "summary": bounded.explain(),
            }
        if self._spent(facts, "siphons_traps", "siphons and traps"):
            return facts
        siphons = siphon_trap_check(net, budget=self.budget.child(seconds=STRUCTURE_SECONDS))
        summary = siphons.explain()
        if has_inputs(net):
            summary += (
                " (about markings where no transition at all is enabled: with operator "
                "inputs a marking where only inputs are enabled is dead too, and this "
                "says nothing about those)"
            )
        facts["siphons_traps"] = {"summary": summary}
        return facts

    def _spent(self, facts: dict[str, object], key: str, what: str) -> bool:
        """Whether the command's budget is spent; if so, mark ``key`` and every later
        structural fact as not computed, naming the limit (an honest gap, not a hang)."""
        if not self.budget.expired():
            return False
        reason = f"not computed: {self.budget.time_reason()} before {what}"
        for later in STRUCTURE_FACTS[STRUCTURE_FACTS.index(key) :]:
            facts[later] = {"verdict": None, "summary": reason}
        return True


# -- timed analysis -----------------------------------------------------------------------


def _timed(
    net: Net,
    profiles: Sequence[VehicleProfile],
    options: TimedOptions,
    properties: list[PropertyResult],
) -> tuple[list[PropertyResult], TimedReport | None]:
    """The untimed ``properties`` with timed analysis's verdicts added (``timed:bounds``,
    ``timed:timeout:T`` per query) and put in place of the ``within`` assertions'
    (``assert:N``); and the whole `TimedReport` (None when it could not run)."""
    within = {
        f"assert:{n}": a
        for n, a in enumerate(net.assertions, start=1)
        if a.kind is AssertKind.WITHIN
    }
    bounds_title = "Mission time is bounded"
    report: TimedReport | None = None
    if not profiles:
        reason = NO_PROFILE
    else:
        analyse = _timed_analyser()
        if isinstance(analyse, str):
            reason = analyse
        else:
            report = analyse(net, profiles, options)
            reason = report.reason if not report.complete else report.unbounded
    if report is None or not report.complete or report.unbounded:
        bounds = PropertyResult(
            "timed:bounds", bounds_title, Verdict.INCONCLUSIVE, TIMED, reason or "incomplete"
        )
    else:
        figures = "; ".join(f.describe() for f in report.finals)
        detail = figures or "every run ends; no declared final marking is reached"
        if report.stuck:
            # The bounds are to the declared finals; runs that stop elsewhere are the
            # deadlock property's business, but the figures must not hide them.
            stuck = "; ".join(format_tokens(sorted(m.items())) for m in report.stuck[:3])
            more = f" and {len(report.stuck) - 3} more" if len(report.stuck) > 3 else ""
            detail += f" (runs can also stop in a marking that is not final: {stuck}{more})"
        bounds = PropertyResult("timed:bounds", bounds_title, Verdict.PROVEN, TIMED, detail)
    deadlines = {} if report is None else {f"assert:{d.index}": d for d in report.deadlines}
    result = []
    for prop in properties:
        assertion = within.get(prop.key)
        if assertion is None:
            result.append(prop)
            continue
        deadline = deadlines.get(prop.key)
        if deadline is None:
            why = reason or "timed analysis gave no verdict on it"
            result.append(
                PropertyResult(
                    prop.key, prop.title, Verdict.INCONCLUSIVE, TIMED, why, span=assertion.span
                )
            )
            continue
        evidence = None
        if deadline.verdict is Verdict.VIOLATED and deadline.counterexample is not None:
            evidence = _schedule_evidence(net, deadline.counterexample, None)
        result.append(
            PropertyResult(
                prop.key,
                prop.title,
                deadline.verdict,
                TIMED,
                deadline.detail,
                evidence,
                assertion.span,
            )
        )
    result.append(bounds)
    for query in () if report is None else report.queries:
        span = query.span
        if span is None:
            try:
                span = net.transition(query.transition).span
            except KeyError:
                span = None
        evidence = None
        if query.verdict is Verdict.VIOLATED and query.counterexample is not None:
            evidence = _schedule_evidence(net, query.counterexample, query.transition)
        detail = query.detail
        if query.verdict is Verdict.PROVEN and query.margin_s is not None and not detail:
            detail = f"margin {query.margin_s:.1f} s"
        result.append(
            PropertyResult(
                f"timed:timeout:{query.transition}",
                f"Time-out of {query.transition} ({query.command}, {query.time_out_s:g} s) "
                "is adequate",
                query.verdict,
                TIMED,
                detail,
                evidence,
                span,
                items=(query.transition,),
                required=False,
            )
        )
    return result, report


TimedAnalyser = Callable[[Net, Sequence["VehicleProfile"], TimedOptions], "TimedReport"]


def _timed_analyser() -> TimedAnalyser | str:
    """`analysis.timed.analyse_timed`, looked up when called (so tests can replace it)."""
    from analysis import timed

    return cast(TimedAnalyser, timed.analyse_timed)


def _schedule_evidence(net: Net, schedule: TimedSchedule, transition: str | None) -> Evidence:
    """A timed counterexample as a trace anyone can replay on the net (each step says
    when it fires), with the schedule's summary as the note."""
    from analysis.report import schedule_summary

    steps: list[Step] = []
    for firing in schedule.firings:
        try:
            index = net.transition_index(firing.transition)
        except KeyError:
            continue
        (step,) = make_trace(net, [index], start=len(steps) + 1)
        steps.append(
            Step(
                number=step.number,
                transition=step.transition,
                kind=step.kind,
                description=f"at {firing.time:.1f} s: {step.description}",
                span=step.span,
                command=step.command,
                reply=step.reply,
            )
        )
    return Evidence(
        trace=tuple(steps), marking=schedule.final, note=schedule_summary(schedule, transition)
    )


def _covering(places: tuple[tuple[str, int], ...], label: str) -> stateeq.BadMarkings:
    """Markings with at least these tokens, for the state equation."""
    from analysis import stateeq

    constraints = tuple(stateeq.PlaceConstraint(((p, 1),), ">=", w) for p, w in places)
    return stateeq.BadMarkings(constraints=constraints, label=label)


def _above(places: tuple[tuple[str, int], ...], bound: int) -> stateeq.BadMarkings:
    """Markings whose weighted token sum over ``places`` exceeds ``bound``
    (``assert bound {p*2, q} <= k``: 2*M(p) + M(q) > k); unweighted places count once."""
    from analysis import stateeq

    if all(w == 1 for _, w in places):
        return stateeq.above_bound([p for p, _ in places], bound)
    terms = tuple(places)
    shown = " + ".join(p if w == 1 else f"{w}*{p}" for p, w in terms)
    return stateeq.BadMarkings(
        constraints=(stateeq.PlaceConstraint(terms, ">=", bound + 1),),
        label=f"{shown} above {bound}",
    )
