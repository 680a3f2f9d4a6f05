"""Fusion of places in series (Berthelot 1986; TAPAAL's rule B, Bønneland et al. 2019).

Rule: a transition ``t`` with ``pre(t) = {p1: 1}`` and ``post(t) = {p2: 1}``,
``p1 != p2``, ``t`` the only consumer of ``p1``. Then ``t`` goes and ``p1`` is merged
into ``p2``: whatever produced into ``p1`` produces into ``p2`` instead, and the initial
tokens of ``p1`` start in ``p2`` (``t`` fired once per token before anything else: the
`Reduction.prefix` every expanded trace starts with).

Why it preserves deadlock: while ``p1`` is marked ``t`` is enabled, and in any firing
sequence ``t`` can fire right after each production into ``p1``, and at the very
start for each initial token of ``p1`` (it only consumes from ``p1``, which nobody else
reads, and only adds to ``p2`` earlier). The reduced net is the original with ``t``
fired eagerly, started from the marking the prefix reaches; dead markings have ``p1``
empty in the original and correspond one to one. A reduced firing of a producer ``u`` that put
``k`` tokens into ``p1`` expands to ``u`` then ``t`` ``k`` times.

For reachability and bounds, ``p1``, ``p2`` and ``t`` must be unobserved: the original
has markings with tokens still waiting in ``p1``, which the reduced net skips.
"""

from __future__ import annotations

from analysis.reduce.goal import Kind
from analysis.reduce.work import WorkNet


def fuse_series_places(w: WorkNet) -> bool:
    """Merge places in series through a private transition; True if any was merged."""
    changed = False
    for t in list(w.pre):
        if t not in w.pre or t in w.protected_transitions:
            continue
        pre, post = w.pre[t], w.post[t]
        if len(pre) != 1 or len(post) != 1:
            continue
        ((p1, w1),), ((p2, w2),) = tuple(pre.items()), tuple(post.items())
        if w1 != 1 or w2 != 1 or p1 == p2 or w.consumers[p1] != {t}:
            continue
        if w.goal.kind is not Kind.DEADLOCK and w.protected_places & {p1, p2}:
            continue
        then = w.expand[t]
        if w.initial[p1]:  # fire t eagerly on the initial tokens too
            w.prefix.extend(then * w.initial[p1])
            w.initial[p2] += w.initial[p1]
            w.initial[p1] = 0
        w.remove_transition(t)
        for u in list(w.producers[p1]):
            k = w.post[u][p1]
            w.set_post(u, p2, w.post[u].get(p2, 0) + k)
            w.expand[u] = w.expand[u] + then * k
        w.remove_place(p1)
        w.applied["series-places"] += 1
        changed = True
    return changed
