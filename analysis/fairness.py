"""The fairness the runtime really provides, as groups for `analysis.stategraph`.

The CORAL Engine fires whatever engine transition is enabled (it never leaves one
enabled forever while it waits), and the vehicle answers every command it is sent
with one of the replies its profile lists (a time-out is a reply). So the runs that
can happen are the *weakly fair* runs of the net for these groups:

* each engine transition (plain or command) alone: enabled at every position from
  some point on implies taken infinitely often;
* each command's replies together: while the command is in flight (its pending place
  is marked, so its replies are enabled) one of them is eventually taken.

Properties such as "every run ends in a final marking" and the temporal assertions
of a mission are decided over these runs only; ``docs/verify.md`` spells this out.
A net without commands (a PNML model) gets one group per transition: plain weak
fairness.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from analysis.stategraph import StateGraph
from coral_lang.net import TransitionKind

BoolArray = npt.NDArray[np.bool_]
Group = tuple[BoolArray, BoolArray]
"""``(enabled_at, in_group)``: nodes where the group is enabled, edges it owns."""


def engine_transitions(graph: StateGraph) -> list[int]:
    """Indices of the transitions the engine fires (everything but vehicle replies)."""
    return [
        i for i, t in enumerate(graph.space.net.transitions) if t.kind is not TransitionKind.REPLY
    ]


def fairness_groups(graph: StateGraph) -> list[Group]:
    """The weak-fairness groups of the runtime for the net of ``graph`` (see module)."""
    net = graph.space.net
    groups: list[Group] = []
    for t in engine_transitions(graph):
        groups.append((graph.enabled([t]), graph.labels == t))
    replies: dict[str, list[int]] = {}
    for i, tr in enumerate(net.transitions):
        if tr.kind is TransitionKind.REPLY and tr.reply_to is not None:
            replies.setdefault(tr.reply_to, []).append(i)
    for members in replies.values():
        groups.append((graph.enabled(members), np.isin(graph.labels, members)))
    return groups
