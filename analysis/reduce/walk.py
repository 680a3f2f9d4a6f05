"""Random walks on the reduced net: a cheap first try at finding a dead marking.

A breadth-first search stores every marking up to the depth of the nearest dead one;
a net whose processes all block after a few steps each (dining philosophers, a
computation that terminates) often has a dead marking that a walk firing random enabled
transitions reaches in a few hundred steps, while the search stores thousands of
markings first. The walks are seeded (same net, same walk) and bounded in steps; a
walk proves nothing when it finds no dead marking (the search follows), and a dead
marking it finds is expanded and replayed on the original net like any witness.

Enabledness is kept incrementally: firing ``t`` re-tests only the consumers of the
places ``t`` changes, so a step costs what it touches, not the width of the net.
"""

from __future__ import annotations

import random

from coral_lang.net import Net

WALK_STEPS = 300
"""Steps of all walks together: at most a few milliseconds on the reduced conformance
nets; every dead marking a walk found there was within 33 steps."""


def walk_to_deadlock(net: Net, *, steps: int = WALK_STEPS, seed: int = 0) -> list[str] | None:
    """A firing sequence of ``net`` reaching a dead marking, found by random walks
    restarting from the initial marking; None if none was found within ``steps``."""
    if not net.transitions:
        return []
    index = {p.name: i for i, p in enumerate(net.places)}
    pre = [[(index[p], w) for p, w in t.inputs] for t in net.transitions]
    delta: list[dict[int, int]] = []
    for t in net.transitions:
        change: dict[int, int] = {}
        for p, w in t.inputs:
            change[index[p]] = change.get(index[p], 0) - w
        for p, w in t.outputs:
            change[index[p]] = change.get(index[p], 0) + w
        delta.append({i: d for i, d in change.items() if d})
    readers: list[list[int]] = [[] for _ in net.places]
    for j, arcs in enumerate(pre):
        for i, _ in arcs:
            readers[i].append(j)
    touched: dict[int, list[int]] = {}  # transitions whose enabledness j's firing may change
    rng = random.Random(seed)
    length = max(16, 2 * (len(net.places) + len(net.transitions)))
    left = steps
    while left > 0:
        marking = [p.initial for p in net.places]
        enabled = [j for j, arcs in enumerate(pre) if all(marking[i] >= w for i, w in arcs)]
        on = set(enabled)
        trace: list[int] = []
        while enabled and len(trace) < length and left > 0:
            j = enabled[rng.randrange(len(enabled))] if len(enabled) > 1 else enabled[0]
            for i, d in delta[j].items():
                marking[i] += d
            trace.append(j)
            left -= 1
            changed = False
            if j not in touched:  # only for transitions fired: wide nets stay cheap
                touched[j] = sorted({u for i in delta[j] for u in readers[i]})
            for u in touched[j]:
                now = all(marking[i] >= w for i, w in pre[u])
                if now != (u in on):
                    changed = True
                    if now:
                        on.add(u)
                    else:
                        on.discard(u)
            if changed:
                enabled = list(on)  # a set of small ints: the same order on every run
        if not enabled:
            return [net.transitions[j].name for j in trace]
    return None
