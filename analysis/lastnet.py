"""`last_net`: a function of a net that remembers its result for the last net it saw.

Several stages of one check derive the same lists from the same net (the quick
coverability tree and the full one; the place orders of the decision diagrams read each
transition's places three times). On a net of 20,000 transitions building them takes a
tenth of a second or more each time, often past the command's time limit. Only the last
net is remembered, by weak reference: a cache never keeps a net alive, and a check of
many nets in a row holds one result at a time. Results are shared, so callers treat
them as read-only.
"""

from __future__ import annotations

import functools
import weakref
from collections.abc import Callable
from typing import TypeVar

from coral_lang.net import Net

T = TypeVar("T")


def last_net(function: Callable[[Net], T]) -> Callable[[Net], T]:
    """``function``, remembering its result for the last net it was called with."""
    last: list[tuple[weakref.ref[Net], T]] = []

    @functools.wraps(function)
    def remembered(net: Net) -> T:
        if last and last[0][0]() is net:
            return last[0][1]
        found = function(net)
        last[:] = [(weakref.ref(net), found)]
        return found

    return remembered
