"""Agglomeration of transitions: in series, and the general pre- and post-agglomeration.

`agglomerate_series` (below), `post_agglomerate` and `pre_agglomerate` (their
docstrings give the conditions and the preservation arguments).

Series rule (Berthelot 1986, "Checking properties of nets using transformations"; the same
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


def _pre_agglomerable(w: WorkNet, h: str) -> str | None:
    """The place ``p`` through which ``h`` passes the conditions of `pre_agglomerate`."""
    post = w.post[h]
    if len(post) != 1 or not w.pre[h] or h in w.protected_transitions:
        return None
    ((p, a),) = tuple(post.items())
    if w.initial[p] or w.producers[p] != {h} or p in w.protected_places:
        return None
    consumers = w.consumers[p]
    if not consumers or h in consumers or w.protected_transitions & consumers:
        return None
    if any(w.pre[f][p] != a for f in consumers):
        return None
    for q in w.pre[h]:
        if w.consumers[q] != {h} or q in w.protected_places:
            return None
    return p


def pre_agglomerate(w: WorkNet) -> bool:
    """Pre-agglomeration of a transition into the consumers of its only output.

    Rule (Berthelot 1986, pre-agglomeration; Haddad & Pradat-Peyre 2006): a transition
    ``h`` with ``post(h) = {p: a}``, ``p`` initially empty with ``h`` its only producer,
    ``h`` not consuming ``p``, a non-empty preset whose places only ``h`` consumes, and
    every consumer ``f`` of ``p`` taking exactly ``a`` from it. Every ``f`` becomes
    ``h.f`` with ``pre = pre(h) + pre(f) - p`` and ``post = post(f)``; ``h`` and ``p``
    go. Nothing observed may be touched: ``h``, the consumers, ``p`` and ``pre(h)``.

    Why it preserves deadlock: once enabled ``h`` stays enabled until it fires (nobody
    else takes its inputs), and its firing only serves the consumers of ``p``. So in any
    sequence each ``h`` can be postponed to just before the ``f`` using its tokens, and
    the ``h`` whose tokens nobody used can be left out: a dead marking ``M`` of the
    original gives the reduced marking with those ``h`` not fired, which is dead (an
    ``h.f`` there lacks the inputs ``f`` lacked in ``M``). Conversely, at a dead marking of
    the reduced net the original may still fire ``h``; firing it until it is disabled
    (its inputs only shrink) gives a dead marking of the original, since every ``f``
    still lacks its other inputs. The witness is therefore completed: after the expanded
    trace, ``h`` is fired while enabled (`Reduction.closers`, in `decide_deadlock`).

    Reachability and bounds: with ``p`` and ``pre(h)`` unobserved, a marking with ``h``
    fired early agrees on every observed place with the one before it, and ``h.f``
    changes the observed places as ``f`` does.
    """
    changed = False
    for h in list(w.pre):
        if h not in w.pre:
            continue
        p = _pre_agglomerable(w, h)
        if p is None:
            continue
        pre, h_expand = dict(w.pre[h]), w.expand[h]
        consumers = sorted(w.consumers[p])
        arcs = {f: (dict(w.pre[f]), dict(w.post[f]), w.expand[f]) for f in consumers}
        for t in (h, *consumers):
            w.remove_transition(t)
        w.remove_place(p)
        for f, (f_pre, f_post, f_expand) in arcs.items():
            del f_pre[p]
            merged = dict(f_pre)
            for q, n in pre.items():
                merged[q] = merged.get(q, 0) + n
            name = f"{h}.{f}" if len(h) + len(f) < 80 else f"agg.{f}"
            w.add_transition(name, merged, f_post, h_expand + f_expand)
        w.closers.append(h_expand)
        w.applied["pre-agglomeration"] += 1
        changed = True
    return changed
