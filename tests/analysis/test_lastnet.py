"""`last_net`: one computation per net in a row, a new one for another net, and no net
kept alive by the memory of it."""

from __future__ import annotations

import gc
import weakref

from analysis.lastnet import last_net
from coral_lang.net import Net
from tests.analysis.nets import mutex


def test_the_last_net_is_computed_once_and_another_net_anew() -> None:
    calls: list[str] = []

    @last_net
    def places(net: Net) -> int:
        calls.append(net.name)
        return len(net.places)

    first, second = mutex(), mutex()
    assert places(first) == places(first) == len(first.places)
    assert places(second) == len(second.places)
    assert places(first) == len(first.places)
    assert calls == [first.name, second.name, first.name]


def test_a_remembered_net_can_still_be_freed() -> None:
    @last_net
    def names(net: Net) -> list[str]:
        return [p.name for p in net.places]

    net = mutex()
    names(net)
    gone = weakref.ref(net)
    del net
    gc.collect()
    assert gone() is None
