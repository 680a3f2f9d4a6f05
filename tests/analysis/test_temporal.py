"""Temporal assertions end to end: ``coral-check verify`` on small missions (proven,
violated with a lasso or trace at the right lines, inconclusive with the reason) and on
the pool mission with temporal assertions added (``data/pool_temporal``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from analysis import verify as verify_module
from analysis.cli import main
from analysis.report import Verdict
from analysis.stategraph import GraphError, StateGraph, build_graph
from analysis.statespace import explore
from analysis.temporal import check_temporal
from analysis.verify import VerifyOptions, verify
from coral_lang.compiler import compile_source
from coral_lang.net import Net

DATA = Path(__file__).parent / "data"

# A depth query that may time out and be retried for ever: line numbers matter below.
RETRY = """\
mission retry
vehicle ROMEO
place start = 1
place depth_set, depth_ok, abort
final { depth_ok }
final { abort }

transition set_depth
    wait   { start }
    action { ROMEO(DEPTH, z = 2.0) -> { ack: depth_set, error: abort } }

transition check_depth
    wait   { depth_set }
    action { ROMEO(DEPTH?, z = 2.0, time_out = 60 s) -> { done: depth_ok, timeout: depth_set } }

"""
SET_DEPTH, SET_DEPTH_REPLY, CHECK_DEPTH, CHECK_DEPTH_REPLY = 8, 10, 12, 14

# An engine loop (a heartbeat) beside one command: fair runs answer the command, but
# some path of the graph ticks for ever.
HEARTBEAT = """\
mission heartbeat
vehicle ROMEO
place start = 1, beat = 1, depth_ok, abort
transition tick wait { beat } signal { beat }
transition set_depth
    wait   { start }
    action { ROMEO(DEPTH, z = 2.0) -> { ack: depth_ok, error: abort } }
"""


def write(tmp_path: Path, text: str, *asserts: str) -> str:
    path = tmp_path / "m.coral"
    path.write_text(text + "".join(a + "\n" for a in asserts))
    return str(path)


def run(path: str, *options: str) -> tuple[int, dict[str, Any]]:
    """Exit code and ``{key: property}`` of ``coral-check verify`` in JSON."""
    out = Path(path).with_suffix(".json")
    code = main(["verify", path, "--format", "json", "--no-structure", "-o", str(out), *options])
    (checked,) = json.loads(out.read_text())["files"]
    return code, {p["key"]: p for p in checked["report"]["properties"]}


def lines(steps: list[dict[str, Any]]) -> list[int]:
    return [s["location"]["line"] for s in steps]


def test_liveness_violation_comes_with_a_lasso_at_the_right_lines(tmp_path: Path) -> None:
    code, props = run(
        write(
            tmp_path,
            RETRY,
            "assert eventually final",
            "assert in_flight(check_depth) leadsto depth_ok",
        )
    )
    assert code == 1
    for key in ("assert:1", "assert:2"):
        result = props[key]
        assert result["verdict"] == "violated"
        assert "fair run" in result["detail"]
        evidence = result["evidence"]
        assert evidence["loop"], "a lasso: the retry loop repeats for ever"
        assert set(lines(evidence["loop"])) == {CHECK_DEPTH, CHECK_DEPTH_REPLY}
        assert {s["transition"] for s in evidence["loop"]} == {
            "check_depth",
            "check_depth.timeout",
        }
        assert lines(evidence["trace"])[:2] == [SET_DEPTH, SET_DEPTH_REPLY]
        assert evidence["trace"][1]["reply"] == "ack"
    assert props["assert:1"]["location"]["line"] == RETRY.count("\n") + 1


def test_lasso_steps_replay_on_the_net(tmp_path: Path) -> None:
    path = write(tmp_path, RETRY, "assert eventually depth_ok or abort")
    net = compile_source(Path(path).read_text(), path).raise_for_errors()
    result = verify(net, VerifyOptions(structural=False)).property("assert:1")
    assert result.verdict is Verdict.VIOLATED and result.evidence is not None
    marking = net.initial_marking()
    for step in result.evidence.trace:
        transition = net.transition(step.transition)
        assert net.enabled(marking, transition)
        marking = net.fire(marking, transition)
    assert net.marking_dict(marking) == result.evidence.marking
    entry = marking
    for step in result.evidence.loop:
        transition = net.transition(step.transition)
        assert net.enabled(marking, transition)
        marking = net.fire(marking, transition)
    assert marking == entry, "the loop comes back where it started"


def test_safety_violation_comes_with_a_shortest_trace(tmp_path: Path) -> None:
    code, props = run(
        write(tmp_path, RETRY, "assert always not abort", "assert always depth_ok + abort <= 1")
    )
    assert code == 1
    violated = props["assert:1"]
    assert violated["verdict"] == "violated"
    assert violated["method"] == "explicit state space"
    assert [s["transition"] for s in violated["evidence"]["trace"]] == [
        "set_depth",
        "set_depth.error",
    ]
    assert lines(violated["evidence"]["trace"]) == [SET_DEPTH, SET_DEPTH_REPLY]
    assert violated["evidence"]["marking"] == {"abort": 1}
    assert props["assert:2"]["verdict"] == "proven"


def test_ltl_with_events_and_a_run_that_ends(tmp_path: Path) -> None:
    _, props = run(
        write(
            tmp_path,
            RETRY,
            "assert ltl G (fires(check_depth.timeout) -> X depth_set)",
            "assert ltl G not fires(set_depth.error)",
            "assert ltl not depth_ok U (depth_ok or abort or depth_set)",
        )
    )
    assert props["assert:1"]["verdict"] == "proven"
    ended = props["assert:2"]
    assert ended["verdict"] == "violated"
    assert ended["evidence"]["loop"] == []
    assert ended["evidence"]["marking"] == {"abort": 1}
    assert "declared final marking" in ended["evidence"]["note"]
    assert props["assert:3"]["verdict"] == "proven"


def test_ctl_witnesses_and_counterexamples(tmp_path: Path) -> None:
    _, props = run(
        write(
            tmp_path,
            RETRY,
            "assert ctl EF depth_ok",
            "assert ctl AG not depth_ok",
            "assert ctl AF final",
            "assert ctl EG not final",
            "assert ctl AG EF final and E [ not abort U depth_ok ]",
        )
    )
    witness = props["assert:1"]
    assert witness["verdict"] == "proven"
    assert [s["transition"] for s in witness["evidence"]["trace"]] == [
        "set_depth",
        "set_depth.ack",
        "check_depth",
        "check_depth.done",
    ]
    assert witness["evidence"]["marking"] == {"depth_ok": 1}
    counter = props["assert:2"]
    assert counter["verdict"] == "violated"
    assert counter["evidence"]["marking"] == {"depth_ok": 1}
    never_ends = props["assert:3"]
    assert never_ends["verdict"] == "violated" and never_ends["evidence"]["loop"]
    assert set(lines(never_ends["evidence"]["loop"])) == {CHECK_DEPTH, CHECK_DEPTH_REPLY}
    assert props["assert:4"]["verdict"] == "proven" and props["assert:4"]["evidence"]["loop"]
    both = props["assert:5"]
    assert both["verdict"] == "proven" and both["evidence"]["marking"] == {"depth_ok": 1}


def test_fairness_is_the_runtimes_and_ctl_assumes_none(tmp_path: Path) -> None:
    _, props = run(
        write(
            tmp_path,
            HEARTBEAT,
            "assert eventually depth_ok or abort",
            "assert ctl AF (depth_ok or abort)",
            "assert always fireable(tick)",
        )
    )
    assert props["assert:1"]["verdict"] == "proven"
    unfair = props["assert:2"]
    assert unfair["verdict"] == "violated"
    assert [s["transition"] for s in unfair["evidence"]["loop"]] == ["tick"]
    assert props["assert:3"]["verdict"] == "proven"


def test_incomplete_or_reduced_state_space_is_inconclusive_with_the_reason(
    tmp_path: Path,
) -> None:
    path = write(
        tmp_path,
        RETRY,
        "assert eventually final",
        "assert ctl EF depth_ok",
        "assert always depth_ok + abort <= 1",
        "assert always not in_flight(set_depth)",
    )
    code, props = run(path, "--max-states", "2")
    assert code == 1  # the violation of the last one is still found
    for key in ("assert:1", "assert:2", "assert:3"):
        assert props[key]["verdict"] == "inconclusive"
        assert "incomplete" in props[key]["detail"]
    assert props["assert:4"]["verdict"] == "violated"
    _, props = run(path, "--por")
    for key in ("assert:1", "assert:2"):
        assert props[key]["verdict"] == "inconclusive"
        assert "reduced" in props[key]["detail"]


def test_graph_is_built_once_per_verification(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[int] = []

    def counting(*args: Any, **kwargs: Any) -> StateGraph:
        calls.append(1)
        return build_graph(*args, **kwargs)

    monkeypatch.setattr(verify_module, "build_graph", counting)
    path = write(
        tmp_path, RETRY, "assert eventually final", "assert ctl EF depth_ok", "assert ctl AF final"
    )
    net = compile_source(Path(path).read_text(), path).raise_for_errors()
    verify(net, VerifyOptions(structural=False))
    assert len(calls) == 1


def test_check_temporal_turns_a_missing_graph_into_inconclusive(tmp_path: Path) -> None:
    net: Net = compile_source(
        RETRY + "assert eventually final\nassert always not abort\n", "m.coral"
    ).raise_for_errors()
    space = explore(net)

    def no_graph() -> StateGraph:
        raise GraphError("the edge budget ran out")

    eventually, always = net.assertions
    result = check_temporal(net, space, no_graph, eventually, "assert:1")
    assert result.verdict is Verdict.INCONCLUSIVE and result.detail == "the edge budget ran out"
    # 'always' needs no edges: decided on the markings alone
    assert check_temporal(net, space, no_graph, always, "assert:2").verdict is Verdict.VIOLATED
    with pytest.raises(ValueError, match="not a temporal assertion"):
        check_temporal(
            net,
            space,
            no_graph,
            compile_source(RETRY + "assert never { abort }\n").raise_for_errors().assertions[0],
            "x",
        )


def test_pool_mission_with_temporal_assertions_is_proven(
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = str(DATA / "pool_temporal" / "pool_mission.coral")
    assert main(["verify", path, "--no-structure"]) == 0
    out = capsys.readouterr().out
    assert "PROVEN        assert in_flight(check_depth) leadsto depth_ok or abort" in out
    assert "assert ctl AG EF final" in out
    assert "VIOLATED" not in out and "INCONCLUSIVE" not in out


def test_a_place_read_only_by_a_temporal_assertion_is_used(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = RETRY.replace("place depth_set", "place watched\nplace depth_set")
    main(["lint", write(tmp_path, text, "assert always not watched")])
    assert "CORAL203" not in capsys.readouterr().out
    main(["lint", write(tmp_path, text)])
    assert "CORAL203" in capsys.readouterr().out
