"""Redundant transitions: duplicates, dominated self-loops, and always-enabled ones.

Rules (Berthelot 1986; TAPAAL's rules for parallel transitions and self-loops,
Jensen, Nielsen, Oestergaard & Srba 2016 and Bønneland et al. 2019):

* *duplicate transitions*: ``t`` and ``u`` with ``pre(t) = pre(u)`` and
  ``post(t) = post(u)``; an unobserved one goes. Both are enabled in the same markings
  and lead to the same marking, so the reachable markings, their deadness, and the
  enabledness of every kept transition are unchanged (all three goals). A firing of the
  removed one in an original sequence is replaced by the kept one.
* *dominated self-loops* (deadlock): ``t`` with ``pre(t) = post(t)`` and some other
  transition ``u`` with ``pre(u) <= pre(t)``. Firing ``t`` changes no marking, so the
  reachable markings are the same without it; a marking enabling ``t`` enables ``u``,
  so no marking becomes dead. (For reachability and bounds `dead` removes every
  unobserved self-loop.)
* *always-enabled transition* (deadlock): a transition with an empty preset is enabled
  in every marking, so no reachable marking is dead. The net then becomes that one
  transition with no arcs (plus the observed places, isolated): it has no dead marking
  either, and its search stores one marking.
"""

from __future__ import annotations

from analysis.reduce.goal import Kind
from analysis.reduce.work import WorkNet


def remove_duplicate_transitions(w: WorkNet) -> bool:
    """Remove unobserved transitions with the same arcs as another; True if any was."""
    kept: dict[tuple[frozenset[tuple[str, int]], frozenset[tuple[str, int]]], str] = {}
    removed = False
    # Observed transitions first, so the one kept of a group is observed if any is.
    order = sorted(w.pre, key=lambda t: t not in w.protected_transitions)
    for t in order:
        key = (frozenset(w.pre[t].items()), frozenset(w.post[t].items()))
        if key not in kept or t in w.protected_transitions:
            kept.setdefault(key, t)
            continue
        w.remove_transition(t)
        w.applied["duplicate-transition"] += 1
        removed = True
    return removed


def _by_rarest_input(w: WorkNet) -> dict[str, list[str]]:
    """Transitions with inputs, each listed under the input place with the fewest
    consumers: a ``u`` with ``pre(u) <= pre(t)`` is listed under a place of ``pre(t)``,
    so the candidates for ``t`` are the lists of its input places (each ``u`` in one
    list, so a place that thousands read costs nothing extra)."""
    index: dict[str, list[str]] = {}
    for u, pre in w.pre.items():
        if pre:
            rarest = min(pre, key=lambda q: (len(w.consumers[q]), q))
            index.setdefault(rarest, []).append(u)
    return index


def remove_dominated_self_loops(w: WorkNet) -> bool:
    """For deadlock: remove self-loops enabled only where another transition is."""
    if w.goal.kind is not Kind.DEADLOCK:
        return False
    loops = [t for t in w.pre if w.pre[t] == w.post[t] and t not in w.protected_transitions]
    if not loops:
        return False
    index = _by_rarest_input(w)
    removed = False
    for t in loops:
        pre = w.pre[t]
        if not pre:
            continue  # left for `collapse_live` (nothing is smaller)
        if any(
            u != t and u in w.pre and all(pre.get(q, 0) >= n for q, n in w.pre[u].items())
            for p in pre
            for u in index.get(p, ())
        ):
            w.remove_transition(t)
            w.applied["dominated-self-loop"] += 1
            removed = True
    return removed


def collapse_live(w: WorkNet) -> bool:
    """For deadlock: with a transition of empty preset, reduce the net to it alone."""
    if w.goal.kind is not Kind.DEADLOCK:
        return False
    live = next((t for t, pre in w.pre.items() if not pre), None)
    if live is None or (len(w.pre) == 1 and not w.post[live] and not _unobserved(w)):
        return False
    for t in list(w.pre):
        if t != live:
            w.remove_transition(t)
    for p in _unobserved(w):
        w.remove_place(p)
    for p in list(w.post[live]):
        w.set_post(live, p, 0)
    w.applied["always-enabled"] += 1
    return True


def _unobserved(w: WorkNet) -> list[str]:
    return [p for p in w.initial if p not in w.protected_places]
