"""Hand-made nets shared by the analysis tests, written as compact dictionaries."""

from __future__ import annotations

from collections.abc import Sequence

from coral_lang.net import FinalMarking, Net, Place, Transition

Arcs = dict[str, int]


def make_net(
    name: str,
    places: dict[str, int],
    transitions: dict[str, tuple[Arcs, Arcs]],
    finals: tuple[FinalMarking, ...] = (),
) -> Net:
    """A net from ``{place: initial tokens}`` and ``{transition: (inputs, outputs)}``."""
    return Net(
        name,
        tuple(Place(p, m) for p, m in places.items()),
        tuple(
            Transition(t, tuple(ins.items()), tuple(outs.items()))
            for t, (ins, outs) in transitions.items()
        ),
        finals=finals,
    )


def mutex() -> Net:
    """Two processes, one lock: bounded, deadlock-free, cs1 and cs2 never together."""
    return make_net(
        "mutex",
        {"idle1": 1, "cs1": 0, "idle2": 1, "cs2": 0, "lock": 1},
        {
            "enter1": ({"idle1": 1, "lock": 1}, {"cs1": 1}),
            "exit1": ({"cs1": 1}, {"idle1": 1, "lock": 1}),
            "enter2": ({"idle2": 1, "lock": 1}, {"cs2": 1}),
            "exit2": ({"cs2": 1}, {"idle2": 1, "lock": 1}),
        },
    )


def replay(net: Net, trace: Sequence[int]) -> tuple[int, ...]:
    """The marking a trace of transition numbers leads to, asserting every step is
    enabled where it fires."""
    marking = net.initial_marking()
    for t in trace:
        assert net.enabled(marking, net.transitions[t])
        marking = net.fire(marking, net.transitions[t])
    return marking


def replay_names(net: Net, names: Sequence[str]) -> dict[str, int]:
    """`replay` for a trace of transition names; the marked places of the end."""
    marking = replay(net, [net.transition_index(name) for name in names])
    return {p.name: v for p, v in zip(net.places, marking, strict=True) if v}
