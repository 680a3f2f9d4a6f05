"""Every promised pumping trace is in the report: when the coverability tree has a
replayable pump for any unbounded place, ``bounded``'s evidence carries it (before,
only the first unbounded place's pump was looked at, and the evidence was null when
that one had none)."""

from __future__ import annotations

import dataclasses

import pytest

from analysis import verify as verify_module
from analysis.coverability import CoverabilityResult, coverability
from analysis.report import Verdict
from analysis.verify import VerifyOptions, verify
from coral_lang.net import Net
from tests.analysis.nets import make_net


def _two_pumps() -> Net:
    """``a`` stays marked; ``tx`` and ``ty`` pump ``x`` and ``y`` without end."""
    return make_net(
        "two_pumps",
        {"a": 1, "x": 0, "y": 0},
        {"tx": ({"a": 1}, {"a": 1, "x": 1}), "ty": ({"a": 1}, {"a": 1, "y": 1})},
    )


def _replays(net: Net, trace: list[str], loop: list[str], place: str) -> bool:
    """Fire ``trace`` then ``loop``: every place at least as full, ``place`` fuller."""
    by_name = {t.name: t for t in net.transitions}
    marking = net.initial_marking()
    for name in trace:
        assert net.enabled(marking, by_name[name])
        marking = net.fire(marking, by_name[name])
    start = marking
    for name in loop:
        assert net.enabled(marking, by_name[name])
        marking = net.fire(marking, by_name[name])
    index = net.place_index(place)
    return (
        all(b >= a for a, b in zip(start, marking, strict=True)) and marking[index] > start[index]
    )


def test_the_pump_of_a_later_unbounded_place_is_the_evidence(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    real = coverability

    def first_place_without_pump(*args: object, **kwargs: object) -> CoverabilityResult:
        result = real(*args, **kwargs)  # type: ignore[arg-type]
        first = result.unbounded[0]
        pumps = {n: p for n, p in result.pumps.items() if n != first}
        return dataclasses.replace(result, pumps=pumps, missing_pumps=(first,))

    monkeypatch.setattr(verify_module, "coverability", first_place_without_pump)
    net = _two_pumps()
    bounded = verify(net, VerifyOptions(structural=False)).property("bounded")
    assert bounded.verdict is Verdict.VIOLATED
    assert "1 with a replayable pumping trace" in bounded.detail
    assert bounded.evidence is not None and bounded.evidence.loop
    document = bounded.evidence.to_dict()
    assert document["loop"]
    trace = [s.transition for s in bounded.evidence.trace]
    loop = [s.transition for s in bounded.evidence.loop]
    pumped = [p for p in ("x", "y") if _replays(net, trace, loop, p)]
    assert pumped and pumped[0] in bounded.evidence.note


def test_an_unbounded_net_always_shows_its_replayable_pump() -> None:
    net = _two_pumps()
    bounded = verify(net, VerifyOptions(structural=False)).property("bounded")
    assert bounded.evidence is not None
    trace = [s.transition for s in bounded.evidence.trace]
    loop = [s.transition for s in bounded.evidence.loop]
    assert _replays(net, trace, loop, "x") or _replays(net, trace, loop, "y")
