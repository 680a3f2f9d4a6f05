"""Implicit places proved by linear programming (structural implicitness).

Condition (Colom & Silva 1991, "Improving the linearly based characterization of P/T
nets"; Garcia-Valles & Colom 1999, "Implicit places in net systems"): a place ``p`` is
implicit when some ``y >= 0`` over the other places ``R`` satisfies

* ``y . C[R, t] <= C[p, t]`` for every transition ``t``, so ``M(p) - y . M(R)`` never
  falls below its initial value ``mu = m0(p) - y . m0(R)``;
* ``y . Pre[R, t] + mu >= Pre[p, t]`` for every consumer ``t`` of ``p``.

Then whenever ``t``'s other inputs enable it, ``M(p) >= y . M(R) + mu >=
y . Pre[R, t] + mu >= Pre[p, t]``: ``p`` never disables anything, and removing it
leaves the reachability graph isomorphic (deadlock, reachability over the other places
and their bounds are preserved). The cheap sufficient conditions of `implicit` are the
cases with one witness place; this finds combinations of several.

Cost: ``y`` ranges over the places that share a transition with ``p`` (the LP has as
many rows as the transitions touching them), places with a larger neighbourhood are not
tried, and the whole rule stops at the work net's LP deadline (a slice of the budget).
"""

from __future__ import annotations

import time

import numpy as np

from analysis.reduce.work import WorkNet

MAX_NEIGHBOURS = 40
"""Places with more neighbour places than this are not tried (the LP would be large)."""


def _implicit(w: WorkNet, p: str) -> bool:
    from scipy.optimize import linprog  # only when the rule is asked for

    touching = w.consumers[p] | w.producers[p]
    neighbours = sorted({q for t in touching for q in (*w.pre[t], *w.post[t])} - {p})
    if not neighbours or len(neighbours) > MAX_NEIGHBOURS:
        return False
    column = {q: i for i, q in enumerate(neighbours)}
    rows = sorted(touching | {t for q in neighbours for t in w.consumers[q] | w.producers[q]})
    a_ub: list[list[float]] = []
    b_ub: list[float] = []
    m0 = np.array([w.initial[q] for q in neighbours], dtype=float)
    for t in rows:  # y . C[R, t] <= C[p, t]
        row = np.zeros(len(neighbours))
        for q, k in w.post[t].items():
            if q in column:
                row[column[q]] += k
        for q, k in w.pre[t].items():
            if q in column:
                row[column[q]] -= k
        a_ub.append(list(row))
        b_ub.append(float(w.post[t].get(p, 0) - w.pre[t].get(p, 0)))
    for t in w.consumers[p]:  # y . (m0(R) - Pre[R, t]) <= m0(p) - Pre[p, t]
        row = m0.copy()
        for q, k in w.pre[t].items():
            if q in column:
                row[column[q]] -= k
        a_ub.append(list(row))
        b_ub.append(float(w.initial[p] - w.pre[t][p]))
    result = linprog(
        np.zeros(len(neighbours)),
        A_ub=np.array(a_ub),
        b_ub=np.array(b_ub),
        bounds=[(0, None)] * len(neighbours),
        method="highs",
    )
    return bool(result.status == 0)


def remove_lp_implicit_places(w: WorkNet) -> bool:
    """Remove unobserved places the LP proves implicit; True if any was removed.

    Each place is tried once per reduction (a failed place is remembered): the LP is
    the costliest rule, and the deadline bounds it in any case."""
    removed = False
    for p in list(w.initial):
        if w.lp_deadline is not None and time.monotonic() > w.lp_deadline:
            break
        if p in w.protected_places or p in w.lp_tried or not w.consumers.get(p):
            continue
        w.lp_tried.add(p)
        if _implicit(w, p):
            w.remove_place(p)
            w.applied["implicit-place-lp"] += 1
            removed = True
    return removed
