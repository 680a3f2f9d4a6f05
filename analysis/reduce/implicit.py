"""Removal of implicit places: places that never disable a transition on their own.

A place ``p`` is *implicit* when, in every reachable marking, each transition that
needs tokens from ``p`` has them whenever its other inputs allow it to fire. Removing an
unobserved implicit place leaves the reachability graph isomorphic (projected), so it
preserves deadlock, reachability over the other places and their bounds
(Berthelot 1986; Garcia-Valles & Colom 1999 for the linear-programming version).
Two cheap, conservative, sparse sufficient conditions are checked here:

* *never decreasing*: no transition takes more from ``p`` than it gives back, and the
  initial marking covers the largest weight any transition asks: ``p`` always has it.
* *dominated by a witness place* ``q``: for every transition ``t``,
  ``pre(t, p) <= pre(t, q)`` and ``C(p, t) >= C(q, t)`` (``C = post - pre``), and
  ``m0(p) >= m0(q)``. Then ``M(p) - M(q)`` never decreases from ``m0(p) - m0(q) >= 0``,
  so ``M(p) >= M(q) >= pre(t, q) >= pre(t, p)`` whenever ``t`` is enabled by ``q``.
  Candidates ``q`` must be inputs of every consumer of ``p``, so only those are tried.
"""

from __future__ import annotations

from analysis.reduce.work import WorkNet


def _change(w: WorkNet, t: str, p: str) -> int:
    return w.post[t].get(p, 0) - w.pre[t].get(p, 0)


def _never_decreasing(w: WorkNet, p: str) -> bool:
    users = w.consumers[p] | w.producers[p]
    if any(_change(w, t, p) < 0 for t in users):
        return False
    return w.initial[p] >= max((w.pre[t][p] for t in w.consumers[p]), default=0)


def _dominated(w: WorkNet, p: str, q: str) -> bool:
    if w.initial[p] < w.initial[q]:
        return False
    for t in w.consumers[p]:
        if w.pre[t][p] > w.pre[t].get(q, 0):
            return False
    for t in w.consumers[p] | w.producers[p] | w.consumers[q] | w.producers[q]:
        if _change(w, t, p) < _change(w, t, q):
            return False
    return True


def remove_implicit_places(w: WorkNet, max_candidates: int = 16) -> bool:
    """Remove unobserved places proved implicit; True if any was removed.

    ``max_candidates`` bounds the witnesses tried per place, so a place on a very wide
    net costs a bounded multiple of its arcs.
    """
    removed = False
    for p in list(w.initial):
        if p in w.protected_places or not w.consumers.get(p):
            continue
        if _never_decreasing(w, p):
            w.remove_place(p)
            w.applied["implicit-place"] += 1
            removed = True
            continue
        consumers = sorted(w.consumers[p], key=lambda t: len(w.pre[t]))
        candidates = [q for q in w.pre[consumers[0]] if q != p]
        for t in consumers[1:]:
            candidates = [q for q in candidates if q in w.pre[t]]
            if not candidates:
                break
        for q in candidates[:max_candidates]:
            if _dominated(w, p, q):
                w.remove_place(p)
                w.applied["implicit-place"] += 1
                removed = True
                break
    return removed
