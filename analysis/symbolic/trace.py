"""A shortest firing sequence to a dead marking, from the diagrams.

Forward breadth-first layers of images from the initial marking (layer k: the markings
first reached after k firings) until a layer meets the dead markings; one dead marking
of that layer is the witness, so no dead marking is closer to the start. The sequence
is then rebuilt backwards on concrete markings: the predecessor of a marking by a
transition is the marking minus its outputs plus its inputs, and a step is kept when
that predecessor enables the transition (`Net.enabled`, the net's own rule) and is a
marking of the layer below.

Images of layers stay inside the reachable markings, whose diagram is the small one;
the earlier search went backwards by preimages of the witness, whose unconstrained
predecessors made diagrams of unreachable markings (16.8 s of Referendum-PT-0015's
24 s of answers).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from analysis.symbolic.explore import SymbolicNet

Bdd = Any


class TraceError(Exception):
    """The layers and the net disagree (an internal error, never expected)."""


def shortest_to_dead(
    sym: SymbolicNet, dead: Bdd, check: Callable[[], None]
) -> tuple[list[int], list[str]]:
    """A dead marking closest to the initial one and a shortest firing sequence to it
    (transition names). `dead` holds the dead markings (over the current bits), some
    of them reachable; `check` raises to stop when a budget runs out."""
    from analysis.symbolic.explore import decode

    bdd = sym.bdd
    false = bdd.false
    layer = sym.initial
    layers = [layer]
    seen = layer
    while (layer & dead) == false:
        following = false
        for t in sym.transitions:
            check()
            following |= sym.image(layer, t)
        layer = following & ~seen
        if layer == false:
            raise TraceError("no dead marking is reachable forwards")
        seen |= layer
        layers.append(layer)
    pick = bdd.pick(layer & dead, care_vars=set(sym.xvars))
    witness = decode(sym, pick or {})
    return witness, _walk_back(sym, layers, witness, check)


def _walk_back(
    sym: SymbolicNet, layers: list[Bdd], witness: list[int], check: Callable[[], None]
) -> list[str]:
    net = sym.net
    index = {p.name: i for i, p in enumerate(net.places)}
    effects = []
    for tr in net.transitions:
        delta: dict[int, int] = {}
        for name, w in tr.inputs:
            delta[index[name]] = delta.get(index[name], 0) + w
        for name, w in tr.outputs:
            delta[index[name]] = delta.get(index[name], 0) - w
        effects.append((tr, delta))
    marking = list(witness)
    trace: list[str] = []
    for below in reversed(layers[:-1]):
        check()
        for tr, delta in effects:
            before = list(marking)
            for p, d in delta.items():
                before[p] += d
            if min(before, default=0) < 0 or not net.enabled(tuple(before), tr):
                continue
            if sym.contains(below, before):
                marking = before
                trace.append(tr.name)
                break
        else:
            raise TraceError("no transition leads from the layer below")
    trace.reverse()
    return trace
