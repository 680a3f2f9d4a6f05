"""Agglomeration of transitions in series (a restricted post-agglomeration).

Rule (Berthelot 1986, "Checking properties of nets using transformations"; the same
shape as TAPAAL's rule A, Bønneland et al. 2019): a place ``p``, initially empty, with
exactly one producer ``t1`` and one consumer ``t2`` (``t1 != t2``), where ``p`` is the
only output of ``t1`` and the only input of ``t2``, both with the same weight. Then
``t1`` and ``t2`` become one transition ``t`` with ``pre(t) = pre(t1)`` and
``post(t) = post(t2)``, and ``p`` goes.

Why it preserves deadlock: ``t2`` needs only ``p`` and nobody else takes from ``p``,
so whenever ``p`` is marked ``t2`` is enabled (no deadlock there), and in any firing
sequence each ``t2`` can be moved right after its ``t1`` (it only adds tokens earlier).
So dead markings (``p`` empty) are reachable in both nets alike, and dead in both.

For reachability and bounds the intermediate marking (``t1`` fired, ``t2`` not yet)
must not be observable: ``t1``, ``t2`` and ``p`` are unobserved and either ``pre(t1)``
or ``post(t2)`` has no observed place (then the intermediate marking's observed part
equals the one before ``t1``, or the one after ``t2``).
"""

from __future__ import annotations

from analysis.reduce.goal import Kind
from analysis.reduce.work import WorkNet


def agglomerate_series(w: WorkNet) -> bool:
    """Fuse transitions in series through a private place; True if any was fused."""
    changed = False
    for p in list(w.initial):
        if p not in w.initial or w.initial[p]:
            continue
        # For deadlock ``p`` may be observed: it is empty in every dead marking of the
        # original, and the replayed witness reads it there (see `final_goal`).
        if p in w.protected_places and w.goal.kind is not Kind.DEADLOCK:
            continue
        producers, consumers = w.producers.get(p, set()), w.consumers.get(p, set())
        if len(producers) != 1 or len(consumers) != 1:
            continue
        (t1,), (t2,) = tuple(producers), tuple(consumers)
        if t1 == t2 or w.protected_transitions & {t1, t2}:
            continue
        if w.post[t1] != {p: w.pre[t2][p]} or len(w.pre[t2]) != 1:
            continue
        if w.goal.kind is not Kind.DEADLOCK and (
            w.protected_places & set(w.pre[t1]) and w.protected_places & set(w.post[t2])
        ):
            continue
        pre, post = dict(w.pre[t1]), dict(w.post[t2])
        expand = w.expand[t1] + w.expand[t2]
        name = f"{t1}.{t2}" if len(t1) + len(t2) < 80 else f"agg.{t1}"
        w.remove_transition(t1)
        w.remove_transition(t2)
        w.remove_place(p)
        w.add_transition(name, pre, post, expand)
        w.applied["series-transitions"] += 1
        changed = True
    return changed
