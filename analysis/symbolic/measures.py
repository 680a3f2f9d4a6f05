"""Exact questions about a set of markings held as a BDD over the current (x) bits.

Counting and the heaviest marking are dynamic programs over the diagram's nodes with
Python integers: CUDD's own minterm count is a double, inexact beyond 2^53 states, and
the MCC's StateSpace answers must be exact at 10^20 and beyond.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

Bdd = Any


def _semantic_children(u: Bdd) -> tuple[Bdd, Bdd]:
    """`u`'s low and high cofactors: dd.cudd returns the raw children of the regular
    node, so a complemented edge is pushed down here."""
    low, high = u.low, u.high
    if u.negated:
        return ~low, ~high
    return low, high


def _fold(
    root: Bdd,
    rank: dict[str, int],
    n: int,
    leaf_true: int,
    combine: Callable[[int, int, int, int, int], int],
    false_value: int,
    check: Callable[[], None] | None = None,
) -> int:
    """Post-order evaluation of `combine(rank, low_rank, low_value, high_rank,
    high_value)` at every node without recursion (diagrams can be thousands of levels deep).
    `check` is called every few thousand nodes: it raises to stop a pass that a budget
    no longer allows."""
    memo: dict[int, int] = {}
    true = root.bdd.true
    false = root.bdd.false

    def key(u: Bdd) -> int:
        return int(u) * 2 + (1 if u.negated else 0)

    def value_of(u: Bdd) -> tuple[int, int] | None:
        if u == true:
            return n, leaf_true
        if u == false:
            return n, false_value
        k = key(u)
        if k in memo:
            return rank[u.var], memo[k]
        return None

    stack = [root]
    steps = 0
    while stack:
        steps += 1
        if check is not None and steps % 4096 == 0:
            check()
        u = stack[-1]
        if value_of(u) is not None:
            stack.pop()
            continue
        low, high = _semantic_children(u)
        lv, hv = value_of(low), value_of(high)
        if lv is None:
            stack.append(low)
            continue
        if hv is None:
            stack.append(high)
            continue
        memo[key(u)] = combine(rank[u.var], lv[0], lv[1], hv[0], hv[1])
        stack.pop()
    result = value_of(root)
    assert result is not None
    return result[1]


def count(states: Bdd, xvars: list[str], check: Callable[[], None] | None = None) -> int:
    """Number of assignments of `xvars` in `states`, exactly."""
    n = len(xvars)
    rank = {v: i for i, v in enumerate(xvars)}
    if states == states.bdd.false:
        return 0

    def combine(r: int, lr: int, lv: int, hr: int, hv: int) -> int:
        return (lv << (lr - r - 1)) + (hv << (hr - r - 1))

    memo_root = _fold(states, rank, n, 1, combine, 0, check)
    top = rank[states.var] if states.var is not None else n
    return memo_root << top


def max_weight(
    states: Bdd,
    xvars: list[str],
    weight: dict[str, int],
    check: Callable[[], None] | None = None,
) -> int:
    """Largest sum of `weight` over the variables set to 1, among assignments in
    `states` (variables skipped by a path are free: set to 1). -1 when empty."""
    n = len(xvars)
    rank = {v: i for i, v in enumerate(xvars)}
    if states == states.bdd.false:
        return -1
    prefix = [0]
    for v in xvars:
        prefix.append(prefix[-1] + weight.get(v, 0))
    neg = -(1 << 62)

    def free(a: int, b: int) -> int:  # weights of ranks a..b-1
        return prefix[b] - prefix[a]

    def combine(r: int, lr: int, lv: int, hr: int, hv: int) -> int:
        low = lv + free(r + 1, lr) if lv > neg else neg
        high = hv + weight.get(xvars[r], 0) + free(r + 1, hr) if hv > neg else neg
        return max(low, high)

    best = _fold(states, rank, n, 0, combine, neg, check)
    top = rank[states.var] if states.var is not None else n
    return best + free(0, top)
