"""Saturation on the nodes of a multi-valued decision diagram (MDD), one level per
place, each level's values the place's token counts as they are found.

Ciardo, Luettgen and Siminiceanu, "Saturation: an efficient iteration strategy for
symbolic state-space generation" (TACAS 2001), and its unbounded form in Ciardo,
Marmorstein and Siminiceanu, "Saturation unbound" (TACAS 2003). A node is *saturated*
when the markings below it are closed under every transition whose top place is at
its level or below. Saturating a node fires the transitions of its own level to a
local fixpoint; firing a transition below its top builds the image node by node and
saturates each new node before it is used, so no partial marking is ever carried
through levels that are not yet closed. The union of saturated nodes is saturated
(images distribute over union), which is what keeps the fixpoint local.

Why nodes rather than the set-level schedule of `analysis.symbolic.saturate`: that
schedule re-closes the groups below after every change, each step an image of a whole
frontier through CUDD; on Peterson-PT-3 and DoubleExponent-PT-003 it took 120,000 to
300,000 such steps and no fixpoint in 60 s. Here the same closure happens once per
node, with caches keyed by node, and counters need no bit width in advance (a value
is a dictionary key): no overflow, no widening, no restart. The result is converted
to a CUDD BDD afterwards (`to_bdd`), sized by the largest value each place took, for
the questions the rest of `analysis.symbolic` answers.

The diagram is quasi-reduced: every path visits every level, node 0 is the empty set
and node 1 the terminal (the end of a marking)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from analysis.symbolic.encoding import arc_weights
from coral_lang.net import Net

EMPTY = 0
TERMINAL = 1

CHECK_EVERY = 2048
"""Calls of the recursive image between two budget checks."""


class Unbounded(Exception):
    """A place would exceed its cap (its P-invariant bound, else the largest counter
    allowed): the net may be unbounded. `place` is the place's index in the net."""

    def __init__(self, place: int) -> None:
        super().__init__(f"place {place} exceeds its cap")
        self.place = place


class Stopped(Exception):
    """A budget ran out during the fixpoint; the message says which."""


Step = tuple[int, int, bool]
"""A transition's effect on one level: ``(need, delta, exact)``. The value must equal
`need` (`exact`, a unit's marked place) or be at least `need` (a counter), and moves
by `delta`."""


@dataclass(frozen=True)
class _Event:
    """A transition as per-level steps. `top` and `bottom` are its first and last
    levels."""

    index: int
    steps: dict[int, Step]
    top: int
    bottom: int


def _steps(
    pre: dict[int, int], post: dict[int, int], levels: Sequence[Sequence[int]]
) -> dict[int, Step] | None:
    """A transition's steps per level (`pre`, `post`: weights per place), or None when
    it can never fire (it takes two tokens from a unit, which holds one)."""
    steps: dict[int, Step] = {}
    for k, places in enumerate(levels):
        if len(places) == 1:
            p = places[0]
            need, delta = pre.get(p, 0), post.get(p, 0) - pre.get(p, 0)
            if (need, delta) != (0, 0):
                steps[k] = (need, delta, False)
            continue
        taken = [(i, pre[p]) for i, p in enumerate(places) if p in pre]
        given = [(i, post[p]) for i, p in enumerate(places) if p in post]
        if not taken:
            continue  # the unit's invariant: no input from it, no output into it
        if len(taken) > 1 or taken[0][1] > 1:
            return None
        if len(given) != 1 or given[0][1] != 1:  # the invariant: one in, one out
            raise ValueError(f"places {sorted(places)} are not a unit")
        source, target = taken[0][0], given[0][0]
        steps[k] = (source, target - source, True)
    return steps


class MddSaturation:
    """One saturation run over `levels` (the top level first): a level is one place
    (a counter) or a *unit*, places that together always hold exactly one token (a
    P-invariant of weights 1 and initial value 1), whose value is the position of the
    marked place in the unit. A unit is one level with k values instead of k levels
    of two: Peterson-PT-3's 244 places become a few dozen levels.

    `caps[p]` is the largest value place `p` may take; `check(nodes)` is called every
    `CHECK_EVERY` recursive images with the number of nodes held, and returns a reason
    to stop (a time or node budget) or None."""

    def __init__(
        self,
        net: Net,
        levels: Sequence[Sequence[int]],
        caps: Sequence[int],
        check: Callable[[int], str | None],
    ) -> None:
        self.net = net
        self.units = [list(places) for places in levels]
        self.levels = len(self.units)
        self.check = check
        self.caps = [caps[u[0]] if len(u) == 1 else len(u) - 1 for u in self.units]
        self.by_top: list[list[_Event]] = [[] for _ in range(self.levels)]
        self.always_enabled = False
        level_of = {p: k for k, u in enumerate(self.units) for p in u}
        for number, tr in enumerate(net.transitions):
            pre, post = arc_weights(net, tr)
            touched = sorted({level_of[p] for p in (*pre, *post)})
            steps = _steps(pre, post, [self.units[k] for k in touched])
            if steps is None:
                continue  # never fires: never enabled, never a step
            if not steps:
                self.always_enabled = True  # no place constrains it: no dead marking
                continue
            steps = {touched[k]: step for k, step in steps.items()}
            event = _Event(number, steps, min(steps), max(steps))
            self.by_top[event.top].append(event)
        # node table: children per node, its level, and the unique table
        self.children: list[dict[int, int]] = [{}, {}]
        self.level: list[int] = [self.levels, self.levels]
        self.unique: dict[tuple[int, tuple[tuple[int, int], ...]], int] = {}
        self.union_cache: dict[tuple[int, int], int] = {}
        self.fire_cache: list[dict[int, int]] = [{} for _ in net.transitions]
        self.saturated: dict[int, int] = {}
        self.calls = 0
        # per level, the events whose top it is: by the exact value they need (a
        # unit's place), and (need, (event, delta)) for counters
        self.exact: list[dict[int, list[tuple[_Event, int]]]] = []
        self.counting: list[list[tuple[int, tuple[_Event, int]]]] = []
        for level, events in enumerate(self.by_top):
            exact: dict[int, list[tuple[_Event, int]]] = {}
            counting: list[tuple[int, tuple[_Event, int]]] = []
            for event in events:
                need, delta, is_exact = event.steps[level]
                if is_exact:
                    exact.setdefault(need, []).append((event, delta))
                else:
                    counting.append((need, (event, delta)))
            self.exact.append(exact)
            self.counting.append(counting)

    def widest_test(self) -> int:
        """The most levels one transition tests without changing them (a guard that
        reads every other process, as Dekker's `enter` does)."""
        events = (e for level in self.by_top for e in level)
        return max((sum(1 for s in e.steps.values() if s[1] == 0) for e in events), default=0)

    # -- nodes ---------------------------------------------------------------------
    def node(self, level: int, children: dict[int, int]) -> int:
        """The unique node of `level` with these (non-empty) children; a new node
        keeps `children` itself, which the caller must not change afterwards."""
        key = (level, tuple(sorted(children.items())))
        found = self.unique.get(key)
        if found is not None:
            return found
        self.children.append(children)
        self.level.append(level)
        number = len(self.children) - 1
        self.unique[key] = number
        return number

    def union(self, a: int, b: int) -> int:
        if a in (EMPTY, b):
            return b
        if b == EMPTY:
            return a
        if a > b:
            a, b = b, a
        found = self.union_cache.get((a, b))
        if found is not None:
            return found
        merged = dict(self.children[a])
        for value, child in self.children[b].items():
            mine = merged.get(value)
            merged[value] = child if mine is None else self.union(mine, child)
        result = self.node(self.level[a], merged)
        self.union_cache[(a, b)] = result
        return result

    # -- saturation ----------------------------------------------------------------
    def run(self, initial: Sequence[int]) -> int:
        """The saturated node of the markings reachable from `initial` (token counts
        per place, in the net's order). Raises `Unbounded` or `Stopped`."""
        limit = sys.getrecursionlimit()
        sys.setrecursionlimit(max(limit, 8 * self.levels + 1000))
        try:
            node = TERMINAL
            for k in reversed(range(self.levels)):
                unit = self.units[k]
                if len(unit) == 1:
                    value = initial[unit[0]]
                    if value > self.caps[k]:
                        raise Unbounded(unit[0])
                else:
                    value = next(i for i, p in enumerate(unit) if initial[p])
                node = self._saturate(k, {value: node})
            return node
        finally:
            sys.setrecursionlimit(limit)

    def _saturate(self, level: int, children: dict[int, int]) -> int:
        """Close `children` (a node of `level` being built, every child saturated)
        under the transitions whose top is `level`, then intern it. The same node
        built twice is closed once (`saturated`)."""
        if not self.by_top[level]:
            return self.node(level, children)
        before = self.node(level, dict(children))
        done = self.saturated.get(before)
        if done is not None:
            return done
        exact, counting = self.exact[level], self.counting[level]
        cap = self.caps[level]
        pending = set(children)
        while pending:
            value = pending.pop()
            fired = exact.get(value, ())
            if counting:
                fired = [*fired, *(pair for need, pair in counting if value >= need)]
            for event, delta in fired:
                image = self._fire(event, level + 1, children[value])
                if image == EMPTY:
                    continue
                target = value + delta
                if target > cap:
                    raise Unbounded(self.units[level][0])
                old = children.get(target, EMPTY)
                new = self.union(old, image)
                if new != old:
                    children[target] = new
                    pending.add(target)
        after = self.node(level, children)
        self.saturated[before] = self.saturated[after] = after
        return after

    def _fire(self, event: _Event, level: int, node: int) -> int:
        """The image of `node` (at `level`, below the event's top) under the event's
        steps from `level` down, saturated."""
        if level > event.bottom or node == EMPTY:
            return node
        cache = self.fire_cache[event.index]
        found = cache.get(node)
        if found is not None:
            return found
        self.calls += 1
        if self.calls % CHECK_EVERY == 0:
            reason = self.check(len(self.children))
            if reason is not None:
                raise Stopped(reason)
        step = event.steps.get(level)
        result: dict[int, int] = {}
        for value, child in self.children[node].items():
            target = value
            if step is not None:
                need, delta, exact = step
                if value != need if exact else value < need:
                    continue
                target = value + delta
            image = self._fire(event, level + 1, child)
            if image == EMPTY:
                continue
            if target > self.caps[level]:
                raise Unbounded(self.units[level][0])
            old = result.get(target)
            result[target] = image if old is None else self.union(old, image)
        made = self._saturate(level, result) if result else EMPTY
        cache[node] = made
        return made

    # -- questions -----------------------------------------------------------------
    def tokens(self, level: int, value: int) -> int:
        """Tokens the places of `level` hold when it takes `value`."""
        return value if len(self.units[level]) == 1 else 1

    def heaviest(self, root: int) -> int:
        """The most tokens in one marking of `root` (-1 when empty)."""
        memo = {EMPTY: -1, TERMINAL: 0}
        for node in self._bottom_up(root):
            level = self.level[node]
            memo[node] = max(
                self.tokens(level, v) + memo[c] if memo[c] >= 0 else -1
                for v, c in self.children[node].items()
            )
        return memo[root]

    def dead(self, root: int, check: Callable[[], None]) -> int:
        """The markings of `root` that enable no transition, in one pass down the
        diagram carrying the set of transitions whose guards have all held so far
        (a bit mask): a transition leaves the set at a level whose value fails its
        guard, and a path on which one is still in the set at its last level is not
        dead. `check` raises to stop."""
        if self.always_enabled:
            return EMPTY
        events = [e for level in self.by_top for e in level]
        starts = [0] * self.levels
        ends = [0] * self.levels
        guards: list[list[tuple[int, int, bool]]] = [[] for _ in range(self.levels)]
        for bit, event in enumerate(events):
            starts[event.top] |= 1 << bit
            ends[event.bottom] |= 1 << bit
            for level, (need, _, exact) in event.steps.items():
                guards[level].append((1 << bit, need, exact))
        fails: dict[tuple[int, int], int] = {}
        memo: dict[tuple[int, int], int] = {}
        steps = 0

        def failing(level: int, value: int) -> int:
            mask = fails.get((level, value))
            if mask is None:
                mask = 0
                for bit, need, exact in guards[level]:
                    if value != need if exact else value < need:
                        mask |= bit
                fails[(level, value)] = mask
            return mask

        def walk(node: int, alive: int) -> int:
            nonlocal steps
            if node == TERMINAL:
                return TERMINAL if alive == 0 else EMPTY
            found = memo.get((node, alive))
            if found is not None:
                return found
            steps += 1
            if steps % CHECK_EVERY == 0:
                check()
            level = self.level[node]
            alive |= starts[level]
            kept: dict[int, int] = {}
            for value, child in self.children[node].items():
                left = alive & ~failing(level, value)
                if left & ends[level]:
                    continue  # a transition whose every guard held: enabled
                part = walk(child, left)
                if part != EMPTY:
                    kept[value] = part
            result = self.node(level, kept) if kept else EMPTY
            memo[(node, alive & ~starts[level])] = result
            return result

        limit = sys.getrecursionlimit()
        sys.setrecursionlimit(max(limit, 8 * self.levels + 1000))
        try:
            return walk(root, 0) if root != EMPTY else EMPTY
        finally:
            sys.setrecursionlimit(limit)

    def pick(self, root: int) -> list[int]:
        """One marking of `root` (non-empty), token counts in the net's order."""
        marking = [0] * len(self.net.places)
        node = root
        while node != TERMINAL:
            level = self.level[node]
            value, node = min(self.children[node].items())
            unit = self.units[level]
            if len(unit) == 1:
                marking[unit[0]] = value
            else:
                marking[unit[value]] = 1
        return marking

    def largest(self, root: int) -> list[int]:
        """Per place (net order), the largest value it takes in `root`'s markings."""
        best = [0] * self.levels
        marked: list[set[int]] = [set() for _ in range(self.levels)]
        seen = {root}
        stack = [root]
        while stack:
            node = stack.pop()
            if node <= TERMINAL:
                continue
            level = self.level[node]
            for value, child in self.children[node].items():
                best[level] = max(best[level], value)
                if len(self.units[level]) > 1:
                    marked[level].add(self.units[level][value])
                if child not in seen:
                    seen.add(child)
                    stack.append(child)
        result = [0] * len(self.net.places)
        for k, unit in enumerate(self.units):
            if len(unit) == 1:
                result[unit[0]] = best[k]
        for k, unit in enumerate(self.units):
            if len(unit) > 1:
                for p in unit:
                    result[p] = int(p in marked[k])
        return result

    def count(self, root: int) -> int:
        """Number of markings in `root`, exactly."""
        memo = {EMPTY: 0, TERMINAL: 1}
        for node in self._bottom_up(root):
            memo[node] = sum(memo[c] for c in self.children[node].values())
        return memo[root]

    def _bottom_up(self, root: int) -> list[int]:
        """The inner nodes under `root`, children before parents (no recursion: a
        diagram is as deep as the net has places)."""
        nodes = []
        seen = {EMPTY, TERMINAL}
        stack: list[tuple[int, bool]] = [(root, False)]
        while stack:
            node, expanded = stack.pop()
            if expanded:
                nodes.append(node)
                continue
            if node in seen:
                continue
            seen.add(node)
            stack.append((node, True))
            stack.extend((c, False) for c in self.children[node].values() if c not in seen)
        return nodes

    def to_bdd(self, root: int, value: Callable[[int, int], Any], bdd: Any) -> Any:
        """`root` as a BDD of `bdd`: per node, the disjunction over its values of the
        level's places taking that value (``value(place, tokens)`` is that cube) and
        the child. The BDD's variable order must follow the levels so each node's
        disjunction is built at its own variables."""
        memo: dict[int, Any] = {EMPTY: bdd.false, TERMINAL: bdd.true}
        cubes: dict[tuple[int, int], Any] = {}
        for node in self._bottom_up(root):
            level = self.level[node]
            unit = self.units[level]
            result = bdd.false
            for v, child in self.children[node].items():
                cube = cubes.get((level, v))
                if cube is None:
                    if len(unit) == 1:
                        cube = value(unit[0], v)
                    else:
                        cube = bdd.true
                        for i, p in enumerate(unit):
                            cube &= value(p, int(i == v))
                    cubes[(level, v)] = cube
                result |= cube & memo[child]
            memo[node] = result
        return memo[root]
