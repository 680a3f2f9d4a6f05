"""The fairness the runtime really provides, as groups for `analysis.stategraph`.

The CORAL Engine fires whatever engine transition is enabled (it never leaves one
enabled forever while it waits), and the vehicle answers every command it is sent
with one of the replies its profile lists (a time-out is a reply). So the runs that
can happen are the *weakly fair* runs of the net for these groups:

* each engine transition (plain or command) alone: enabled at every position from
  some point on implies taken infinitely often;
* each command's replies together: while the command is in flight (its pending place
  is marked, so its replies are enabled) one of them is eventually taken.

Operator inputs carry no obligation: the operator may never act, so a run that leaves
an input enabled forever is still a run the runtime can produce.

Properties such as "every run ends in a final marking" and the temporal assertions
of a mission are decided over these runs only; ``docs/verify.md`` spells this out.
A net without commands (a PNML model) gets one group per transition: plain weak
fairness.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from analysis.stategraph import StateGraph
from coral_lang.net import Net, TransitionKind

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]
Group = tuple[BoolArray, BoolArray]
"""``(enabled_at, in_group)``: nodes where the group is enabled, edges it owns."""


def group_of_transition(net: Net) -> IntArray:
    """The fairness group of each transition of ``net`` (see module): groups ``0 ..
    E-1`` are the engine transitions in net order, one each; then one group per
    command, holding its replies, in the order of the command's first reply; ``-1`` for
    a reply that answers no command and for an operator input (no fairness constraint)."""
    out = np.full(len(net.transitions), -1, dtype=np.int64)
    environment = (TransitionKind.REPLY, TransitionKind.INPUT)
    engine = [i for i, tr in enumerate(net.transitions) if tr.kind not in environment]
    out[engine] = np.arange(len(engine))
    commands: dict[str, int] = {}
    for i, tr in enumerate(net.transitions):
        if tr.kind is TransitionKind.REPLY and tr.reply_to is not None:
            out[i] = commands.setdefault(tr.reply_to, len(engine) + len(commands))
    return out


def fairness_groups(graph: StateGraph) -> list[Group]:
    """The weak-fairness groups of the runtime for the net of ``graph`` (see module),
    in the order of `group_of_transition`."""
    of = group_of_transition(graph.space.net)
    edge_group = of[graph.labels]
    groups: list[Group] = []
    for g in range(int(of.max(initial=-1)) + 1):
        in_group: BoolArray = edge_group == g
        enabled_at = np.zeros(graph.n_states, dtype=np.bool_)
        enabled_at[graph.sources[in_group]] = True
        groups.append((enabled_at, in_group))
    return groups
