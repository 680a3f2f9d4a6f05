"""Red-team scale limits (issue 17): lint and structural analysis stay near-linear and
bounded in memory on large generated missions."""

from __future__ import annotations

import resource
import time
import tracemalloc

import pytest

from analysis.invariants import invariant_report, p_invariants
from analysis.lint import LintOptions, lint
from analysis.structural import classify, structural_boundedness
from coral_lang.compiler import CompileResult, compile_source
from coral_lang.diagnostics import Severity


def _chain(n: int) -> str:
    """A mission of ``n`` transitions in one chain: t0 moves p0's token to p1, and so on."""
    lines = ["mission chain", "vehicle ROMEO", "place p0 = 1"]
    lines += [f"place p{k}" for k in range(1, n + 1)]
    lines += [f"transition t{k} wait {{ p{k} }} signal {{ p{k + 1} }}" for k in range(n)]
    lines.append(f"final {{ p{n} }}")
    return "\n".join(lines) + "\n"


def _compiled(text: str) -> CompileResult:
    result = compile_source(text, "scale.coral")
    assert result.errors == [], [d.render() for d in result.errors[:3]]
    return result


def _lint_seconds(result: CompileResult, options: LintOptions | None = None) -> float:
    start = time.perf_counter()
    lint(result, options)
    return time.perf_counter() - start


@pytest.mark.slow
def test_a_20000_transition_chain_lints_in_seconds() -> None:
    big = _compiled(_chain(20_000))
    start = time.perf_counter()
    findings = lint(big)
    seconds = time.perf_counter() - start
    assert findings == []
    assert seconds < 5.0  # every pair of transitions: about 100 s
    small = _compiled(_chain(5_000))
    # near-linear: four times the transitions, well under sixteen times the time
    assert _lint_seconds(big) < 8 * _lint_seconds(small) + 0.5


def test_a_place_with_many_consumers_is_capped_with_a_note() -> None:
    n = 80  # 3160 pairs race for the one token in 'start'
    lines = ["mission fan", "vehicle ROMEO", "place start = 1"]
    lines += [f"place out{k}" for k in range(n)]
    lines += [f"final {{ out{k} }}" for k in range(n)]
    lines += [f"transition t{k} wait {{ start }} signal {{ out{k} }}" for k in range(n)]
    result = _compiled("\n".join(lines) + "\n")
    findings = lint(result, LintOptions(max_pairs_per_place=100))
    notes = [d for d in findings if d.severity is Severity.NOTE]
    races = [d for d in findings if d.code == "CORAL207" and d.severity is Severity.WARNING]
    assert len(notes) == 1
    assert "'start'" in notes[0].message
    assert "skipped: 3060 pairs" in notes[0].message
    assert len(races) == 100
    # with a cap above the pairs every one is examined, and every one races
    everything = lint(result, LintOptions(max_pairs_per_place=10_000))
    assert len([d for d in everything if d.code == "CORAL207"]) == n * (n - 1) // 2


def _with_unused_places(n: int) -> CompileResult:
    lines = ["mission m", "vehicle ROMEO", "place s = 1, a, b", "final { b }"]
    lines += ["transition go wait { s } signal { a }", "transition on wait { a } signal { b }"]
    lines += [f"place u{k}" for k in range(n)]
    return _compiled("\n".join(lines) + "\n")


@pytest.mark.slow
def test_structure_of_20000_unused_places_stays_small_and_fast() -> None:
    net = _with_unused_places(20_000).net
    assert net is not None
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    tracemalloc.start()
    start = time.perf_counter()
    try:
        report = invariant_report(net)
        net_class = classify(net)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - start < 3.0
    assert peak < 200 * 2**20  # dense place x place rows: over 6 GB
    start = time.perf_counter()
    bounded = structural_boundedness(net, per_place=False)  # z3, outside tracemalloc
    assert time.perf_counter() - start < 15.0
    growth_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before
    assert growth_kib < 500 * 1024
    assert not report.p.complete
    assert "20,001 invariants found, 5 listed" in report.p.reason  # u0 ... s+a+b
    assert report.covered_by_p is None  # inconclusive, never a wrong "not covered"
    assert report.t.complete and report.consistent is False
    assert net_class.state_machine and net_class.conservative
    assert bounded.structurally_bounded is True


def test_structural_results_are_unchanged_below_the_size_budget() -> None:
    net = _with_unused_places(20).net
    assert net is not None
    basis = p_invariants(net)
    assert basis.complete
    names = {inv.support_names() for inv in basis.invariants}
    assert ("s", "a", "b") in names and ("u0",) in names and len(names) == 21
    assert not p_invariants(net, max_cells=10).complete
