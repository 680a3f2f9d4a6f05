"""Termination: a verified mission cannot spin, cannot get stuck, and ends properly.

Deadlock freedom is not termination: two engine transitions handing one token back
and forth never deadlock, and neither does a query retried on every time-out. So every
mission (`applies`) gets three more properties, decided on the reachability graph of
its completely explored, unreduced state space (`analysis.stategraph`):

* ``no_engine_cycle``: no cycle of reachable markings made only of engine transitions
  (plain and command ones; replies and operator inputs are the environment). On such
  a cycle the engine fires forever without waiting for the vehicle: the runtime stops
  it with an engine-spin error. Evidence: a lasso,
  a shortest prefix from the initial marking, then the cycle.
* ``final_always_reachable``: from every reachable marking some declared final marking
  is reachable; nothing the vehicle answers can take the mission where it can no
  longer end properly. Evidence: a shortest trace into a marking from which no final
  marking is reachable, and that marking.
* ``terminates``: every run the runtime can produce ends in a declared final marking.
  The runs are the weakly fair ones of `analysis.fairness` (the engine never leaves an
  engine transition enabled forever, every command gets one of its replies), so this
  holds when no fair infinite run exists (no fair strongly connected component: the
  evidence is a lasso whose cycle satisfies every fairness group, e.g. "DEPTH? replies
  timeout forever, retry") and no dead marking is a non-final one (the evidence is
  the shortest trace to it). Operator inputs have no fairness obligation (the operator
  may never act), and a marking where only inputs are enabled is dead: the run has
  stopped there (`analysis.inputs`). Required only by missions with ``require termination``;
  otherwise a violation is a warning (`PropertyResult.required`).

The first two are required of every mission: a certificate without them proven is
refused (`certificate_gaps`). `non_final_dead_states` lists every dead non-final
marking for the ``deadlock`` property, which reports each with its own trace.

Never proven from an incomplete search: without the whole graph (state budget, edge
budget ``max_edges``, partial-order reduction whose full exploration does not finish)
the three are inconclusive, unless a dead non-final marking was found, which violates
``final_always_reachable`` and ``terminates`` with a real trace.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.report import Evidence, PropertyResult, Verdict, make_trace, witness
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net, TransitionKind, format_tokens

if TYPE_CHECKING:
    # scipy (through analysis.stategraph) loads only when a graph is built.
    from analysis.stategraph import StateGraph

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

NO_ENGINE_CYCLE = "no_engine_cycle"
FINAL_ALWAYS_REACHABLE = "final_always_reachable"
TERMINATES = "terminates"
KEYS = (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES)
ALWAYS_REQUIRED = (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE)
"""Required of every mission: a certificate must show them proven."""
REQUIREMENTS: Mapping[str, str] = {"termination": TERMINATES}
"""A mission's ``require`` word -> the property it makes required."""

TITLES = {
    NO_ENGINE_CYCLE: "no cycle of engine transitions (the engine never spins)",
    FINAL_ALWAYS_REACHABLE: "a final marking stays reachable from every marking",
    TERMINATES: "every fair run ends in a declared final marking",
}
GRAPH_METHOD = "reachability graph"
FAIR_METHOD = "reachability graph, weak fairness of the runtime"
DEFAULT_MAX_EDGES = 8_000_000
"""Edge budget of the graph: 12 bytes an edge, about 100 MB, plus temporaries."""
DEFAULT_MAX_DEADLOCKS = 20
DEAD_CHUNK = 1 << 16
SHOWN_NAMES = 6


def applies(net: Net) -> bool:
    """Whether ``net`` is a mission and gets the termination properties: it declares a
    final marking, sends a command, names a vehicle (a compiled mission always does)
    or has requirements. Other nets (PNML models) have no engine, no vehicle and no
    proper end: they get none of the three."""
    return bool(
        net.finals
        or net.vehicle is not None
        or net.requirements
        or any(t.kind is TransitionKind.COMMAND for t in net.transitions)
    )


def required_keys(net: Net) -> tuple[str, ...]:
    """The termination properties a certificate for ``net`` must show proven."""
    if not applies(net):
        return ()
    extra = [REQUIREMENTS[r] for r in net.requirements if r in REQUIREMENTS]
    return tuple(dict.fromkeys([*ALWAYS_REQUIRED, *extra]))


def certificate_gaps(net: Net, properties: Iterable[Mapping[str, object]]) -> list[str]:
    """Why a certificate's ``properties`` (its JSON list) do not cover ``net``: each
    required termination property that is missing or not proven, and each requirement
    this version cannot verify. Empty when they cover it."""
    verdicts = {str(p.get("key")): p.get("verdict") for p in properties}
    gaps = [
        f"{key} {verdicts[key]}" if key in verdicts else f"{key} missing"
        for key in required_keys(net)
        if verdicts.get(key) != Verdict.PROVEN.value
    ]
    gaps += [f"require {r} unknown" for r in net.requirements if r not in REQUIREMENTS]
    return gaps


@dataclass(frozen=True)
class FinalPatterns:
    """The declared finals as arrays, projected on `Net.final_columns`.

    A final leaves each armed place free (0 or 1): expanding it into full markings
    (`Net.final_markings`) costs 2**k rows for k operator inputs, and comparing a block
    of markings against all of them at once cost hundreds of MB. Comparing only the
    constrained columns against one row per declared final costs a block's size.

    Attributes:
        columns: Place columns a final constrains (all but the armed ones).
        armed: Armed place columns; each must hold at most 1.
        patterns: One row per distinct declared final, on ``columns``.
    """

    columns: IntArray
    armed: IntArray
    patterns: IntArray

    @classmethod
    def of(cls, net: Net) -> FinalPatterns:
        """The projected finals of ``net``."""
        test = net.final_test()
        columns = test.columns
        patterns = net.final_patterns()  # declaration order (the test's set has none)
        return cls(
            np.array(columns, dtype=np.int64),
            np.array(test.armed, dtype=np.int64),
            # Explicit shape: with no columns, reshape(-1, 0) cannot infer the rows.
            np.array(patterns, dtype=np.int64).reshape(len(patterns), len(columns)),
        )

    @property
    def full(self) -> bool:
        """Whether the patterns are full markings (the net has no armed place)."""
        return not self.armed.size


def final_rows(block: npt.NDArray[np.integer], finals: FinalPatterns) -> BoolArray:
    """Which rows of ``block`` (full markings) are declared final markings. Memory is
    one boolean per cell of ``block``, whatever the number of inputs or finals."""
    hits = np.zeros(block.shape[0], dtype=np.bool_)
    if not finals.patterns.shape[0]:  # no final (with no places, one is empty yet counts)
        return hits
    projected = block[:, finals.columns]
    for pattern in finals.patterns:
        hits |= (projected == pattern).all(axis=1)
    if finals.armed.size:
        hits &= (block[:, finals.armed] <= 1).all(axis=1)
    return hits


def non_final_dead_states(space: StateSpace) -> IntArray:
    """Every dead state of ``space`` whose marking is not a declared final marking, in
    state order (so by depth: the first has the shortest trace)."""
    dead = np.asarray(space.deadlocks, dtype=np.int64)
    finals = FinalPatterns.of(space.net)
    if not dead.size or not finals.patterns.shape[0]:
        return dead
    keep = np.ones(dead.size, dtype=np.bool_)
    for start in range(0, dead.size, DEAD_CHUNK):
        rows = dead[start : start + DEAD_CHUNK]
        block = space.layout.unpack(space.keys[rows]).astype(np.int64)
        keep[start : start + rows.size] = ~final_rows(block, finals)
    return dead[keep]


def final_states(space: StateSpace) -> BoolArray:
    """Per state of ``space``, whether its marking is a declared final marking.

    Without operator inputs the finals are full markings, and packed keys are linear
    in the marking, so a reachable final has the key `Layout.pack` gives it: compare
    keys instead of unpacking every marking, then confirm the (few) candidates, since
    an unreachable final may share a key. With inputs a final leaves the armed places
    free, so markings are unpacked block by block and compared on `FinalPatterns`."""
    out = np.zeros(space.states, dtype=np.bool_)
    finals = FinalPatterns.of(space.net)
    if not finals.patterns.shape[0] or not space.states:
        return out
    if not finals.full:
        for start in range(0, space.states, DEAD_CHUNK):
            stop = min(start + DEAD_CHUNK, space.states)
            block = space.layout.unpack(space.keys[start:stop])
            out[start:stop] = final_rows(block, finals)
        return out
    packed = space.layout.pack(finals.patterns)
    patterns = [tuple(final) for final in finals.patterns.tolist()]
    # a block of keys at a time: the store keeps them packed in fewer bytes than words
    for start in range(0, space.states, DEAD_CHUNK):
        keys = space.keys[start : min(start + DEAD_CHUNK, space.states)]
        for key, final in zip(packed, patterns, strict=True):
            for row in np.flatnonzero((keys == key).all(axis=1)).tolist():
                out[start + row] |= space.marking(start + row) == final
    return out


@dataclass(frozen=True)
class TerminationLimits:
    """What `check_termination` may spend.

    Attributes:
        max_edges: Edge budget of the reachability graph (None: no limit).
        max_states: State budget of the unreduced exploration made when the given
            state space is partial-order reduced.
        time_limit: Seconds for that exploration and, separately, for building the edges
            (each a slice of the caller's `Budget`).
    """

    max_edges: int | None = DEFAULT_MAX_EDGES
    max_states: int | None = None
    time_limit: float | None = None


def check_termination(
    space: StateSpace,
    limits: TerminationLimits | None = None,
    graph: Callable[[], StateGraph] | None = None,
    budget: Budget | None = None,
) -> list[PropertyResult]:
    """The three termination properties of ``space.net`` (none when it is not a
    mission, see `applies`); a requirement this version does not know is an
    inconclusive property of its own (``require:NAME``).

    Args:
        space: The explored state space (complete or not, reduced or not).
        limits: Edge, state and time limits.
        graph: Gives the reachability graph of ``space`` when it is not reduced (or
            raises `GraphError`): a caller that shares one graph between several
            checks passes it; by default it is built here.
        budget: The caller's budget (clock and deadline); the stages take slices of it.
    """
    net = space.net
    if not applies(net):
        return []
    checker = _Termination(space, limits or TerminationLimits(), graph, budget or Budget())
    results = checker.results()
    for name in net.requirements:
        if name not in REQUIREMENTS:
            results.append(
                PropertyResult(
                    f"require:{name}",
                    f"require {name}",
                    Verdict.INCONCLUSIVE,
                    "none",
                    f"this version of coral does not know how to verify 'require {name}' "
                    f"(it knows: {', '.join(sorted(REQUIREMENTS))})",
                )
            )
    return results


class _Results:
    """Builds the results with each one's ``required`` flag."""

    required: set[str]

    def _result(
        self,
        key: str,
        verdict: Verdict,
        method: str,
        detail: str,
        evidence: Evidence | None = None,
    ) -> PropertyResult:
        # A lasso's loop names what repeats: SARIF locates the result at those lines.
        loop = tuple(dict.fromkeys(step.transition for step in evidence.loop)) if evidence else ()
        return PropertyResult(
            key,
            TITLES[key],
            verdict,
            method,
            detail,
            evidence,
            items=loop,
            required=key in self.required,
        )


class _Termination(_Results):
    def __init__(
        self,
        space: StateSpace,
        limits: TerminationLimits,
        graph: Callable[[], StateGraph] | None,
        budget: Budget,
    ) -> None:
        self.space = space
        self.net = space.net
        self.limits = limits
        self.budget = budget
        self.graph = graph
        self.required = set(required_keys(self.net))
        self.stuck = non_final_dead_states(space)

    def results(self) -> list[PropertyResult]:
        from analysis.stategraph import GraphError, build_graph

        space = self.space
        full = space
        why = ""
        if space.reduced and space.complete:
            # The reduced graph keeps deadlocks, not cycles: explore all of it.
            full = explore(
                self.net,
                max_states=self.limits.max_states,
                budget=self.budget.child(seconds=self.limits.time_limit),
            )
            if not full.complete:
                why = f"the unreduced state space is incomplete ({full.stopped_reason})"
        if not why:
            try:
                if full is space and self.graph is not None:
                    graph = self.graph()
                else:
                    graph = build_graph(
                        full,
                        max_edges=self.limits.max_edges,
                        budget=self.budget.child(seconds=self.limits.time_limit),
                    )
            except GraphError as exc:
                why = str(exc)
            else:
                stuck = self.stuck if full is space else non_final_dead_states(full)
                return _Decider(graph, self.required, stuck).results()
        return self._undecided(why)

    def _undecided(self, why: str) -> list[PropertyResult]:
        """Without the whole graph: a dead non-final marking found is still a real
        counterexample to the last two; nothing is proven."""
        results = [self._result(NO_ENGINE_CYCLE, Verdict.INCONCLUSIVE, GRAPH_METHOD, why)]
        if self.stuck.size:
            method = "explicit state space" + (
                " (stubborn-set reduced)" if self.space.reduced else ""
            )
            state = int(self.stuck[0])
            marking = format_tokens(self.net.marking_dict(self.space.marking(state)).items())
            depth = self.space.depth_of(state)
            evidence = witness(self.space, state)
            detail = (
                f"the dead marking {marking}, not a declared final marking, is reachable "
                f"in {depth} step(s): no final marking is reachable from it"
            )
            results.append(
                self._result(FINAL_ALWAYS_REACHABLE, Verdict.VIOLATED, method, detail, evidence)
            )
            results.append(
                self._result(
                    TERMINATES,
                    Verdict.VIOLATED,
                    method,
                    f"a run ends in the dead marking {marking}, not a declared final "
                    f"marking, after {depth} step(s) (see deadlock)",
                    evidence,
                )
            )
            return results
        results.append(
            self._result(FINAL_ALWAYS_REACHABLE, Verdict.INCONCLUSIVE, GRAPH_METHOD, why)
        )
        results.append(self._result(TERMINATES, Verdict.INCONCLUSIVE, FAIR_METHOD, why))
        return results


class _Decider(_Results):
    """The three properties on a complete reachability graph."""

    def __init__(self, graph: StateGraph, required: set[str], stuck: IntArray) -> None:
        self.graph = graph
        self.required = required
        self.space = graph.space
        self.net = graph.space.net
        self.n = graph.n_states
        self.src = graph.sources
        self.dst = graph.targets
        self.start = np.zeros(self.n, dtype=np.bool_)
        if self.n:
            self.start[0] = True
        self.stuck = stuck

    def results(self) -> list[PropertyResult]:
        return [self.no_engine_cycle(), self.final_always_reachable(), self.terminates()]

    # -- no_engine_cycle -------------------------------------------------------------------

    def no_engine_cycle(self) -> PropertyResult:
        from analysis.stategraph import nontrivial, scc_labels, shortest_path

        graph, n = self.graph, self.n
        # The vehicle's replies and the operator's inputs are the environment.
        environment = np.array(
            [t.kind in (TransitionKind.REPLY, TransitionKind.INPUT) for t in self.net.transitions],
            dtype=np.bool_,
        )
        mine = np.flatnonzero(~environment[graph.labels])
        s, d = self.src[mine], self.dst[mine]
        comp = scc_labels(n, s, d)
        on_cycle = nontrivial(n, s, d, comp)[comp] if n else np.zeros(0, dtype=np.bool_)
        if not on_cycle.any():
            return self._result(
                NO_ENGINE_CYCLE,
                Verdict.PROVEN,
                GRAPH_METHOD,
                f"no cycle of engine transitions among all {n} reachable markings "
                f"({graph.n_edges} edges): the engine always comes to wait for the vehicle",
            )
        prefix = shortest_path(n, self.src, self.dst, self.start, on_cycle)
        assert prefix is not None  # every node is reachable from the initial marking
        entry = int(self.dst[prefix[-1]]) if prefix else 0
        inside = np.flatnonzero((comp[s] == comp[entry]) & (comp[d] == comp[entry]))
        local = _cycle_through(n, s[inside], d[inside], entry)
        cycle = [int(mine[inside[e]]) for e in local]
        evidence = self._lasso(
            prefix,
            cycle,
            "the engine fires these forever without a reply from the vehicle; the runtime "
            "stops it with an engine-spin error",
        )
        names = _names(self.net, (int(graph.labels[e]) for e in cycle))
        return self._result(
            NO_ENGINE_CYCLE,
            Verdict.VIOLATED,
            GRAPH_METHOD,
            f"after {len(prefix)} step(s) the engine can fire {names} over and over without "
            "waiting for the vehicle",
            evidence,
        )

    # -- final_always_reachable -------------------------------------------------------------

    def final_always_reachable(self) -> PropertyResult:
        from analysis.stategraph import backward_reach

        net, n = self.net, self.n
        good = backward_reach(n, self.src, self.dst, final_states(self.space))
        bad = np.flatnonzero(~good)
        if not bad.size:
            return self._result(
                FINAL_ALWAYS_REACHABLE,
                Verdict.PROVEN,
                GRAPH_METHOD,
                f"some declared final marking is reachable from all {n} reachable markings",
            )
        state = int(bad[0])  # states are numbered by depth: this one is nearest
        marking = format_tokens(net.marking_dict(self.space.marking(state)).items())
        if not net.finals:
            detail = "the mission declares no final marking: it can never end properly"
        else:
            dead = " (a dead marking)" if self.graph.dead[state] else ""
            detail = (
                f"no final marking is reachable from {marking}{dead}, reached in "
                f"{self.space.depth_of(state)} step(s); {bad.size} of the {n} reachable "
                "markings are like it"
            )
        return self._result(
            FINAL_ALWAYS_REACHABLE,
            Verdict.VIOLATED,
            GRAPH_METHOD,
            detail,
            witness(self.space, state, "no declared final marking is reachable from here"),
        )

    # -- terminates --------------------------------------------------------------------------

    def terminates(self) -> PropertyResult:
        from analysis.stategraph import shortest_path

        fair = FairComponents(self.graph)
        stuck = self.stuck
        dead_note = ""
        if stuck.size:
            first = format_tokens(self.net.marking_dict(self.space.marking(int(stuck[0]))).items())
            dead_note = (
                f"{stuck.size} dead marking(s) are not declared final, e.g. {first} after "
                f"{self.space.depth_of(int(stuck[0]))} step(s) (see deadlock)"
            )
        if fair.target.any():
            prefix = shortest_path(self.n, self.src, self.dst, self.start, fair.target)
            assert prefix is not None
            entry = int(self.dst[prefix[-1]]) if prefix else 0
            cycle = fair.cycle(entry)
            names = _names(self.net, (int(self.graph.labels[e]) for e in cycle))
            evidence = self._lasso(
                prefix,
                cycle,
                "a run the runtime allows: every engine transition enabled throughout fires, "
                "every command in flight gets a reply, and the mission never ends",
            )
            detail = (
                f"a fair run never ends: after {len(prefix)} step(s) it repeats {names} forever"
                + (f"; also {dead_note}" if dead_note else "")
            )
            return self._result(TERMINATES, Verdict.VIOLATED, FAIR_METHOD, detail, evidence)
        if stuck.size:
            return self._result(
                TERMINATES,
                Verdict.VIOLATED,
                FAIR_METHOD,
                f"a run ends without a final marking: {dead_note}",
                witness(self.space, int(stuck[0])),
            )
        return self._result(
            TERMINATES,
            Verdict.PROVEN,
            FAIR_METHOD,
            f"no fair cycle among all {self.n} reachable markings, and every dead marking "
            "is a declared final marking",
        )

    # -- evidence ----------------------------------------------------------------------------

    def _lasso(self, prefix: Sequence[int], cycle: Sequence[int], note: str) -> Evidence:
        labels = self.graph.labels
        entry = int(self.dst[prefix[-1]]) if prefix else 0
        return Evidence(
            trace=make_trace(self.net, [int(labels[e]) for e in prefix]),
            loop=make_trace(self.net, [int(labels[e]) for e in cycle], start=len(prefix) + 1),
            marking=self.net.marking_dict(self.space.marking(entry)),
            note=note,
        )


def _names(net: Net, transitions: Iterable[int]) -> str:
    names = [net.transitions[t].name for t in transitions]
    shown = " -> ".join(names[:SHOWN_NAMES])
    return shown + (f" -> ... ({len(names)} steps)" if len(names) > SHOWN_NAMES else "")


def _cycle_through(n: int, src: IntArray, dst: IntArray, entry: int) -> list[int]:
    """A shortest cycle from ``entry`` back to it along edges ``src -> dst`` (indices
    into them); ``entry`` must lie on one."""
    from analysis.stategraph import shortest_path

    loops = np.flatnonzero((src == entry) & (dst == entry))
    if loops.size:
        return [int(loops[0])]
    out = np.flatnonzero(src == entry)
    heads = np.zeros(n, dtype=np.bool_)
    heads[dst[out]] = True
    goal = np.zeros(n, dtype=np.bool_)
    goal[entry] = True
    back = shortest_path(n, src, dst, heads, goal)
    assert back, "entry lies on a cycle"
    first = int(src[back[0]])
    step = int(out[dst[out] == first][0])
    return [step, *back]


class FairComponents:
    """The strongly connected components of a reachability graph in which a run
    satisfying the runtime's weak fairness (`analysis.fairness`) can stay forever.

    The same decision as `analysis.stategraph.fair_sccs` over
    `analysis.fairness.fairness_groups`, without one array per group: a component ``C``
    (with a cycle) is fair unless some group is enabled at every node of ``C`` and has
    no edge inside ``C``. Counting (component, group) pairs over the edges decides that
    for every group at once, in memory proportional to the edges.

    Attributes:
        comp: component of each node.
        fair: per component, whether it has a cycle and admits a fair run.
        target: per node, whether its component is fair.
    """

    def __init__(self, graph: StateGraph) -> None:
        from analysis.fairness import group_of_transition
        from analysis.stategraph import nontrivial, scc_labels

        self.graph = graph
        net = graph.space.net
        n, src, dst, labels = graph.n_states, graph.sources, graph.targets, graph.labels
        self.group_of_transition = group_of_transition(net)
        n_groups = int(self.group_of_transition.max(initial=-1)) + 1
        self.edge_group = self.group_of_transition[labels] if labels.size else labels
        comp = scc_labels(n, src, dst)
        n_comp = int(comp.max(initial=-1)) + 1
        fair = nontrivial(n, src, dst, comp)
        if n_groups and fair.any():
            grouped = self.edge_group >= 0
            g = self.edge_group[grouped]
            # (node, group) pairs where the group is enabled, counted per component
            pairs = np.unique(src[grouped] * n_groups + g)
            nodes, groups = pairs // n_groups, pairs % n_groups
            keys, counts = np.unique(comp[nodes] * n_groups + groups, return_counts=True)
            size = np.bincount(comp, minlength=n_comp)
            everywhere = keys[counts == size[keys // n_groups]]
            # (component, group) pairs with an edge of the group inside the component
            inner = grouped & (comp[src] == comp[dst])
            kept = np.unique(comp[src[inner]] * n_groups + self.edge_group[inner])
            starving = everywhere[~np.isin(everywhere, kept)]
            fair[starving // n_groups] = False
        self.comp = comp
        self.fair = fair
        self.target: BoolArray = fair[comp] if n else np.zeros(0, dtype=np.bool_)

    def enabled_groups(self, node: int) -> set[int]:
        """The fairness groups enabled at ``node``."""
        graph = self.graph
        edges = self.edge_group[int(graph.indptr[node]) : int(graph.indptr[node + 1])]
        return {int(g) for g in edges if g >= 0}

    def cycle(self, entry: int) -> list[int]:
        """A cycle through ``entry`` inside its (fair) component that satisfies every
        group: for each group enabled at every node visited so far and not yet taken,
        walk to a node of the component where it is disabled, or else take one of its
        edges inside the component; then return to ``entry``. Edge indices."""
        from analysis.stategraph import node_mask, shortest_path

        graph = self.graph
        n, src, dst = graph.n_states, graph.sources, graph.targets
        c = int(self.comp[entry])
        members = self.comp == c
        idx = np.flatnonzero(members[src] & members[dst])
        s, d = src[idx], dst[idx]
        cycle: list[int] = []
        here = entry
        always = self.enabled_groups(entry)  # enabled at every node visited so far
        taken: set[int] = set()

        def walk(path: Sequence[int]) -> None:
            nonlocal here, always
            for e in path:
                cycle.append(int(idx[e]))
                group = int(self.edge_group[idx[e]])
                if group >= 0:
                    taken.add(group)
                here = int(d[e])
                always &= self.enabled_groups(here)

        while pending := sorted(always - taken):
            group = pending[0]
            edges_of_group = self.edge_group == group
            enabled_at = np.zeros(n, dtype=np.bool_)
            enabled_at[src[edges_of_group]] = True
            elsewhere = members & ~enabled_at
            if elsewhere.any():
                path = shortest_path(n, s, d, node_mask(n, here), elsewhere)
                assert path is not None
                walk(path)
                continue
            own = np.flatnonzero(edges_of_group[idx])
            assert own.size, "a fair component has an inner edge of every group enabled on it"
            heads = np.zeros(n, dtype=np.bool_)
            heads[s[own]] = True
            path = shortest_path(n, s, d, node_mask(n, here), heads)
            assert path is not None
            walk(path)
            walk([int(own[s[own] == here][0])])
        if here != entry or not cycle:
            if here == entry:
                walk(_cycle_through(n, s, d, entry))
            else:
                back = shortest_path(n, s, d, node_mask(n, here), node_mask(n, entry))
                assert back is not None
                walk(back)
        return cycle
