"""End to end: a net where the memory limit alone decides the outcome of
``coral-check verify``. Its deadlock freedom is out of reach of every method that needs
no state space (the state equation and its traps admit a spurious dead marking, the
structural reductions leave the net as it is), and its 2^26 markings do not fit in
200 MiB: the run must end with exit 3, the deadlock verdict inconclusive and naming the
memory limit, never a crash or a wrong verdict."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from analysis import stateeq
from analysis.budget import Budget
from analysis.reduce import decide_deadlock
from coral_lang.pnml import read_pnml

ROOT = Path(__file__).resolve().parents[2]


def guarded_toggles_pnml(n: int) -> str:
    """``n`` on/off switches (2^n markings, no deadlock: a switch can always flip), all
    reading a place ``x`` that holds one token; ``kill_i`` would move switch ``i``'s
    token to a sink but needs two tokens in ``x``, and ``drain`` would empty ``x`` but
    needs two in ``a0``: neither can fire. Their firing counts solve the state
    equation for a dead marking (all tokens in the sinks, ``x`` still marked, so every
    trap that matters stays marked), and the read arcs keep the series rules from
    folding the switches."""
    one = "<initialMarking><text>1</text></initialMarking>"
    two = "<inscription><text>2</text></inscription>"
    places = f'<place id="x">{one}</place><place id="d"/>' + "".join(
        f'<place id="a{i}">{one}</place><place id="b{i}"/><place id="s{i}"/>' for i in range(n)
    )
    transitions = '<transition id="drain"/>' + "".join(
        f'<transition id="on{i}"/><transition id="off{i}"/><transition id="kill{i}"/>'
        for i in range(n)
    )
    arcs = [
        ("x", "drain", 1),
        ("drain", "d", 1),
        ("a0", "drain", 2),
        ("drain", "a0", 2),
    ]
    for i in range(n):
        arcs += [
            (f"a{i}", f"on{i}", 1),
            (f"on{i}", f"b{i}", 1),
            (f"b{i}", f"off{i}", 1),
            (f"off{i}", f"a{i}", 1),
            ("x", f"on{i}", 1),
            (f"on{i}", "x", 1),
            ("x", f"off{i}", 1),
            (f"off{i}", "x", 1),
            (f"a{i}", f"kill{i}", 1),
            (f"kill{i}", f"s{i}", 1),
            ("x", f"kill{i}", 2),
            (f"kill{i}", "x", 2),
        ]
    text = "".join(
        f'<arc id="e{k}" source="{src}" target="{dst}">{two if w == 2 else ""}</arc>'
        for k, (src, dst, w) in enumerate(arcs)
    )
    return (
        '<?xml version="1.0"?><pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">'
        '<net id="guarded" type="http://www.pnml.org/version-2009/grammar/ptnet"><page id="p">'
        f"{places}{transitions}{text}</page></net></pnml>"
    )


def test_only_a_search_can_show_the_net_deadlock_free(tmp_path: Path) -> None:
    """The premise: neither the state equation with traps nor the reductions decide."""
    model = tmp_path / "guarded.pnml"
    model.write_text(guarded_toggles_pnml(6))
    net = read_pnml(model)
    result = stateeq.check_unreachable(net, stateeq.deadlocks(), budget=Budget(60.0))
    assert isinstance(result, stateeq.Candidate)
    assert stateeq.realise(net, result) is None  # spurious: no firing order
    answer = decide_deadlock(net, max_states=10, budget=Budget(60.0))
    assert answer.deadlock is None  # the reduced net still needs more than 10 states


def test_the_memory_limit_decides_verify(tmp_path: Path) -> None:
    model = tmp_path / "guarded.pnml"
    model.write_text(guarded_toggles_pnml(26))  # 2^26 markings: over 200 MiB at any packing
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "analysis.cli", "verify", str(model), "--format", "json"]
    command += ["--method", "explicit"]  # a decision diagram would count them all
    limits = ["--memory-limit", "200M", "--max-states", "100000000", "--time-limit", "60"]
    done = subprocess.run(
        [*command, *limits], capture_output=True, text=True, env=env, timeout=120, check=False
    )
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr
    report = json.loads(done.stdout)["files"][0]["report"]
    assert report["verdict"] == "inconclusive"
    assert report["statespace"]["stopped_reason"].startswith(
        "memory limit of 200 MiB reached after"
    )
    deadlock = next(p for p in report["properties"] if p["key"] == "deadlock")
    assert deadlock["verdict"] == "inconclusive"
    assert "memory limit of 200 MiB reached" in deadlock["detail"]
    assert all(p["verdict"] != "violated" for p in report["properties"])
