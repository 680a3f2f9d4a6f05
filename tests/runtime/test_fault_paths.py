"""Every reply branch of the pool mission, driven at run time with fault plans.

Analysis proves that each abort path ends in a declared final marking; this drives each
one through the real controller, link and simulated ROMEO. A search over fault plans:
start with none; each run lists the commands it sent (with their use numbers); for every
reply kind of a sent command whose branch no run has taken yet, a new plan forces that
kind on that use, on top of the plan of the run that sent it (so abort-path commands,
sent only after an abort, get their turn too). Every run must end in a declared final
marking, and in the end every reply transition of the net must have fired.
"""

from __future__ import annotations

from collections import Counter, deque

import pytest

from coral_lang.net import Net, TransitionKind
from runtime.controller import RunEnd
from runtime.engine import Policy
from runtime.faultplan import FaultPlan, parse_fault_rules
from runtime.fuzz import FuzzOptions, FuzzRun, run_one
from runtime.link import BUILTIN_PROFILES
from tests.runtime.test_properties import mission


def _run(net_name: str, rules: tuple[str, ...], seed: int = 1) -> FuzzRun:
    m = mission(net_name)
    plan = parse_fault_rules(list(rules)) if rules else FaultPlan(rules=())
    options = FuzzOptions(
        runs=1, seed=seed, link=BUILTIN_PROFILES["lan"], policy=Policy.PRIORITY, faults=plan
    )
    return run_one(m.net, m.approval, seed, options, keep_events=True)


def _sent(run: FuzzRun) -> list[tuple[str, str, int]]:
    """(transition, command, use number) of every command the run sent, in order."""
    uses: Counter[str] = Counter()
    out = []
    for event in run.events:
        if event.kind == "command-sent":
            name = str(event.data["name"])
            uses[name] += 1
            out.append((str(event.data["transition"]), name, uses[name]))
    return out


def _reply_transitions(net: Net) -> set[str]:
    return {t.name for t in net.transitions if t.kind is TransitionKind.REPLY}


@pytest.mark.slow
def test_every_reply_branch_of_the_pool_mission_runs_to_a_declared_final_marking() -> None:
    net = mission("pool").net
    kinds = {t.name: list(t.command.replies) for t in net.transitions if t.command is not None}
    wanted = _reply_transitions(net)
    covered: set[str] = set()
    queue: deque[tuple[str, ...]] = deque([()])
    tried: set[tuple[str, ...]] = set()
    endings: Counter[str] = Counter()
    while queue:
        rules = queue.popleft()
        if rules in tried:
            continue
        tried.add(rules)
        run = _run("pool", rules)
        assert run.end is RunEnd.FINAL, (rules, run.ending(), run.detail)
        endings[run.ending()] += 1
        covered |= set(run.fired) & wanted
        for transition, name, use in _sent(run):
            for kind in kinds[transition]:
                if f"{transition}.{kind}" not in covered:
                    queue.append((f"{name}#{use}={kind}", *rules))
    assert covered == wanted, sorted(wanted - covered)
    # The abort paths end where the mission says they end, each of them reached.
    assert set(endings) == {
        "final { mission_complete }",
        "final { aborted_at_surface }",
        "final { operator_alert }",
        "final { not_started }",
    }


def test_a_forced_timeout_takes_the_abort_path_and_surfaces() -> None:
    run = _run("pool", ("DEPTH?=timeout",))
    assert run.end is RunEnd.FINAL
    assert run.marking == {"aborted_at_surface": 1}
    assert "check_depth.timeout" in run.fired and "check_depth.done" not in run.fired
    replies = [e.data for e in run.events if e.kind == "reply"]
    forced = [
        r for r in replies if "forced by fault plan rule 'DEPTH?=timeout'" in str(r["detail"])
    ]
    assert len(forced) == 1 and forced[0]["kind"] == "timeout"


def test_the_nth_use_is_the_one_forced() -> None:
    """``XY?#3=timeout``: the first two legs are flown, the third aborts."""
    run = _run("pool", ("XY?#3=timeout",))
    assert run.marking == {"aborted_at_surface": 1}
    done = sorted(n for n in run.fired if n.endswith(".done") and n.startswith("reach_wp"))
    timed_out = sorted(n for n in run.fired if n.endswith(".timeout") and n.startswith("reach_wp"))
    assert len(done) == 2 and len(timed_out) == 1, sorted(run.fired)
