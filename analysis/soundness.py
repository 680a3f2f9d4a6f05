"""Known-unsound checker revisions: which old certificates no longer prove anything.

A certificate is evidence only as good as the checker that wrote it. When a soundness
bug is found and fixed (a method could answer *proven* for a property that does not
hold), certificates written before the fix may rest on that wrong answer, and a valid
signature does not change that: the key signed what the buggy checker said.

So every certificate records `CHECKER_REVISION`, an integer bumped with each soundness
fix, and `KNOWN_UNSOUND` lists each bug: the revisions it affects, the methods it
affects (matched against each property's ``method``), optionally the nets on which it
can bite, what was wrong and the revision that fixed it. The runtime refuses a
certificate that has a *proven* property decided by an implicated method
(`implicated`), naming the bug and asking for a re-verification; a certificate of an
affected revision whose proofs came from other methods, or whose net cannot trigger
the bug, stays valid. A certificate without a revision was written before revisions
were recorded and counts as `OLDEST_REVISION`.

To record a new soundness fix: bump `CHECKER_REVISION`, and append an `UnsoundCheck`
whose ``last`` is the previous revision and ``fixed_in`` the new one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from coral_lang.net import AssertKind, Net

__all__ = [
    "CHECKER_REVISION",
    "KNOWN_UNSOUND",
    "OLDEST_REVISION",
    "Implication",
    "UnsoundCheck",
    "implicated",
]

CHECKER_REVISION = 2
"""This checker's revision, recorded in every certificate (``checker_revision``)."""
OLDEST_REVISION = 1
"""The revision of a certificate that records none (written before revisions were)."""


def _any_net(net: Net, key: str) -> bool:
    del net, key
    return True


@dataclass(frozen=True)
class UnsoundCheck:
    """One known soundness bug of past checker revisions.

    Attributes:
        name: A short stable name, quoted in refusals and docs.
        first: The first revision with the bug.
        last: The last revision with the bug.
        fixed_in: The revision that fixed it.
        fixed_by: Where the fix is (a commit), for whoever audits a refusal.
        what: What was wrong, in one sentence a reader of a refusal understands.
        methods: Substrings of a property's ``method``: a property decided by a method
            containing any of them is implicated (empty: every method).
        bites: Whether the bug can affect property ``key`` of this net at all (a
            certificate for a net that cannot trigger it is left alone).
    """

    name: str
    first: int
    last: int
    fixed_in: int
    fixed_by: str
    what: str
    methods: tuple[str, ...] = ()
    bites: Callable[[Net, str], bool] = _any_net

    def affects(self, revision: int, method: str) -> bool:
        """Whether a property ``method`` decided at ``revision`` may be wrong."""
        if not self.first <= revision <= self.last:
            return False
        return not self.methods or any(m in method for m in self.methods)


_EXACT_LIMIT = 2**60
"""The explorer counts exactly below this (``analysis.encoding.MAX_FIELD_BITS``)."""


def _beyond_exact_counts(net: Net, key: str) -> bool:
    """Whether an initial count or arc weight of ``net`` exceeds 2**60: only then could
    the explorer's 64-bit sums wrap before revision 2."""
    del key
    if any(place.initial > _EXACT_LIMIT for place in net.places):
        return True
    return any(
        weight > _EXACT_LIMIT
        for transition in net.transitions
        for _, weight in (*transition.inputs, *transition.outputs)
    )


def _weighted_bound(net: Net, key: str) -> bool:
    """Whether property ``key`` is an ``assert bound`` with a weight other than 1."""
    if not key.startswith("assert:") or not key[7:].isdigit():
        return False
    number = int(key[7:])
    if not 1 <= number <= len(net.assertions):
        return False
    assertion = net.assertions[number - 1]
    return assertion.kind is AssertKind.BOUND and any(w != 1 for _, w in assertion.places)


_STATE_SPACE_METHODS = (
    "explicit state space",  # also the stubborn-set reduced one
    "reachability graph",  # termination, built from the explored states
    "LTL model checking",  # on the same graph
    "CTL model checking",
)

KNOWN_UNSOUND: tuple[UnsoundCheck, ...] = (
    UnsoundCheck(
        name="explorer-64-bit-wrap",
        first=1,
        last=1,
        fixed_in=2,
        fixed_by="commit 29d4413",
        what=(
            "the explicit explorer's 64-bit token sums could wrap on a net with an initial "
            "count or arc weight over 2**60 (a net gaining 2**62 tokens a firing was "
            "proven bounded)"
        ),
        methods=_STATE_SPACE_METHODS,
        bites=_beyond_exact_counts,
    ),
    UnsoundCheck(
        name="bound-assert-weights",
        first=1,
        last=1,
        fixed_in=2,
        fixed_by="commit 29d4413",
        what=(
            "'assert bound {p*2, ...} <= k' ignored the weights and bounded the plain sum of tokens"
        ),
        bites=_weighted_bound,
    ),
)


@dataclass(frozen=True)
class Implication:
    """A known bug and the proven properties of one certificate it may have falsified."""

    bug: UnsoundCheck
    properties: tuple[tuple[str, str], ...]
    """``(key, method)`` of each implicated property."""

    def describe(self) -> str:
        """``explorer-64-bit-wrap: the explicit ... (bounded by explicit state space)``."""
        shown = ", ".join(f"{key} by {method}" for key, method in self.properties[:4])
        if len(self.properties) > 4:
            shown += f" and {len(self.properties) - 4} more"
        return (
            f"{self.bug.name}: {self.bug.what}; fixed in revision {self.bug.fixed_in} "
            f"({self.bug.fixed_by}); it decided {shown}"
        )


def implicated(
    revision: int,
    properties: Iterable[Mapping[str, object]],
    net: Net,
    table: Iterable[UnsoundCheck] = KNOWN_UNSOUND,
) -> list[Implication]:
    """Each bug of ``table`` that may have falsified a *proven* property among
    ``properties`` (a certificate's list) written at ``revision`` for ``net``.

    Only proven properties count: a violated or inconclusive verdict is never relied
    on, so a bug that could only have made a proof appear is harmless there.
    """
    proven = [
        (str(p.get("key")), str(p.get("method", "")))
        for p in properties
        if p.get("verdict") == "proven"
    ]
    found: list[Implication] = []
    for bug in table:
        hit = tuple(
            (key, method)
            for key, method in proven
            if bug.affects(revision, method) and bug.bites(net, key)
        )
        if hit:
            found.append(Implication(bug, hit))
    return found
