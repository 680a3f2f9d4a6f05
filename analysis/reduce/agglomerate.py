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


MAX_GROWTH = 8
"""Post-agglomeration replaces ``|H| + |F|`` transitions by ``|H| x |F|``; it is applied
only when that adds at most this many transitions, so rounds cannot blow the net up."""


def _post_agglomerable(w: WorkNet, p: str) -> tuple[list[str], list[str], int] | None:
    """The producers, consumers and consumer weight when ``p`` passes the conditions of
    `post_agglomerate`, else None."""
    if w.initial[p]:
        return None
    deadlock = w.goal.kind is Kind.DEADLOCK
    if p in w.protected_places and not deadlock:
        return None
    producers, consumers = w.producers.get(p, set()), w.consumers.get(p, set())
    if not producers or not consumers or producers & consumers:
        return None
    if w.protected_transitions & (producers | consumers):
        return None
    weights = {w.pre[f][p] for f in consumers}
    if len(weights) != 1 or any(len(w.pre[f]) != 1 for f in consumers):
        return None
    (weight,) = weights
    for h in producers:
        k, rest = divmod(w.post[h][p], weight)
        if rest or (k > 1 and len(consumers) > 1):
            return None
    if not deadlock and any(w.protected_places & set(w.post[f]) for f in consumers):
        return None
    grown = len(producers) * len(consumers) - len(producers) - len(consumers)
    if grown > MAX_GROWTH:
        return None
    return sorted(producers), sorted(consumers), weight


def post_agglomerate(w: WorkNet) -> bool:
    """General post-agglomeration through a place; True if any place was agglomerated.

    Rule (Berthelot 1986, post-agglomeration; Haddad & Pradat-Peyre 2006): a place ``p``,
    initially empty, with producers ``H`` and consumers ``F``, disjoint and non-empty,
    where every ``f`` in ``F`` has ``pre(f) = {p: w}`` (the same ``w`` for all) and every
    ``h`` in ``H`` puts ``k_h w`` tokens into ``p`` (``k_h > 1`` only when ``F`` is one
    transition). Every pair ``(h, f)`` becomes one transition ``h.f`` with
    ``pre = pre(h)`` and ``post = post(h) - p + k_h post(f)``; ``H``, ``F`` and ``p`` go.
    The series rule is the case ``|H| = |F| = 1`` with ``post(h) = {p: w}``.

    Why it preserves deadlock: ``p`` only ever holds multiples of ``w``, every ``f``
    needs nothing but ``w`` tokens of ``p`` and no other transition reads ``p``. So in a
    firing sequence the ``i``-th firing of an ``f`` can be moved right after the ``i``-th
    unit produced into ``p`` (nothing between them consumes ``p``, and moving outputs
    earlier disables nothing): every marking with ``p`` empty reachable in the original
    is reachable in the reduced net, and the converse holds by expanding ``h.f`` into
    ``h`` then ``f``. A dead marking has ``p`` empty (a unit in ``p`` enables every
    ``f``), and at a marking with ``p`` empty ``h.f`` is enabled exactly when ``h`` is
    while every ``f`` is disabled: the same markings are dead in both nets.

    Reachability and bounds: ``p``, ``H`` and ``F`` unobserved and no ``f`` outputs to an
    observed place. A marking of the original with units pending in ``p`` then agrees on
    every observed place (and, presets of observed transitions being observed, on their
    enabledness) with the marking after firing some ``f`` per pending unit, which has
    ``p`` empty and so is reachable in the reduced net.
    """
    changed = False
    for p in list(w.initial):
        if p not in w.initial:
            continue
        found = _post_agglomerable(w, p)
        if found is None:
            continue
        producers, consumers, weight = found
        arcs = {
            h: (dict(w.pre[h]), dict(w.post[h]), w.expand[h], w.post[h][p] // weight)
            for h in producers
        }
        outs = {f: (dict(w.post[f]), w.expand[f]) for f in consumers}
        for t in (*producers, *consumers):
            w.remove_transition(t)
        w.remove_place(p)
        for h, (pre, post, h_expand, k) in arcs.items():
            del post[p]
            for f, (f_post, f_expand) in outs.items():
                merged = dict(post)
                for q, n in f_post.items():
                    merged[q] = merged.get(q, 0) + k * n
                name = f"{h}.{f}" if len(h) + len(f) < 80 else f"agg.{h}"
                w.add_transition(name, pre, merged, h_expand + f_expand * k)
        w.applied["post-agglomeration"] += 1
        changed = True
    return changed
