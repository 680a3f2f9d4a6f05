"""Removal of dead parts: transitions that can never fire, places that never matter.

Rules (each preserves deadlock, reachability over protected places and bounds, since
the reachability graph is unchanged up to the removed, never-enabled parts):

* *never-marked places*: a place is possibly markable if it is initially marked or
  some possibly-fireable transition outputs to it; a transition is possibly fireable
  if all its input places are possibly markable (least fixpoint). A transition that is
  not possibly fireable never fires: removing it cannot change any reachable marking,
  and it is enabled in none, so deadness is unchanged.
* *constant places*: a place every transition gives back what it takes keeps its
  initial marking forever; a transition needing more than that never fires.
* *sink places*: a place no transition consumes from disables nothing; when not
  observed it can go.
* *neutral transitions* (not for deadlock): a transition whose firing changes no
  marking adds no reachable marking; unobserved, it can go for reachability and
  bounds (for deadlock it would change which markings are dead).
"""

from __future__ import annotations

from analysis.reduce.goal import Kind
from analysis.reduce.work import WorkNet


def remove_dead_transitions(w: WorkNet) -> bool:
    """Remove transitions that structurally can never fire; True if any was removed."""
    markable = {p for p, m in w.initial.items() if m > 0}
    fireable: set[str] = set()
    waiting = {t: sum(1 for p in pre if p not in markable) for t, pre in w.pre.items()}
    ready = [t for t, n in waiting.items() if n == 0]
    while ready:
        t = ready.pop()
        fireable.add(t)
        for p in w.post[t]:
            if p in markable:
                continue
            markable.add(p)
            for u in w.consumers[p]:
                waiting[u] -= 1
                if waiting[u] == 0:
                    ready.append(u)
    dead = [t for t in w.pre if t not in fireable]
    # A constant place (every transition returns what it takes) blocks those asking more.
    for p, m in w.initial.items():
        if all(w.post[t].get(p, 0) == w.pre[t][p] for t in w.consumers[p]) and all(
            w.post[t][p] == w.pre[t].get(p, 0) for t in w.producers[p]
        ):
            dead.extend(t for t in w.consumers[p] if w.pre[t][p] > m and t in fireable)
    removed = False
    for t in dict.fromkeys(dead):
        if t in w.protected_transitions:
            continue
        w.remove_transition(t)
        w.applied["dead-transition"] += 1
        removed = True
    return removed


def remove_sink_places(w: WorkNet) -> bool:
    """Remove unobserved places that no transition consumes from."""
    sinks = [p for p in w.initial if not w.consumers.get(p) and p not in w.protected_places]
    for p in sinks:
        w.remove_place(p)
        w.applied["sink-place"] += 1
    return bool(sinks)


def remove_neutral_transitions(w: WorkNet) -> bool:
    """For reachability and bounds: remove unobserved transitions that change nothing."""
    if w.goal.kind is Kind.DEADLOCK:
        return False
    neutral = [t for t in w.pre if w.pre[t] == w.post[t] and t not in w.protected_transitions]
    for t in neutral:
        w.remove_transition(t)
        w.applied["neutral-transition"] += 1
    return bool(neutral)
