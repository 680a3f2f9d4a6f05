"""``coral-check query`` end to end through `analysis.cli.main`, on vendored MCC data."""

from __future__ import annotations

import gzip
import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from analysis.cli import main
from tests.conftest import REPO

MCC = REPO / "tests" / "data" / "mcc"
MODEL = "Philosophers-PT-000005"


def _answers(model: str) -> dict[str, Any]:
    with (MCC / "answers.yaml").open() as handle:
        models = yaml.safe_load(handle)["models"]
    entry: dict[str, Any] = next(m for m in models if m["model"] == model)
    return entry


def _unzip(source: Path, target: Path) -> Path:
    target.write_bytes(gzip.decompress(source.read_bytes()))
    return target


@pytest.fixture
def mcc_dir(tmp_path: Path) -> Path:
    """The MCC layout: ``model.pnml`` and ``<Examination>.xml`` in one folder."""
    folder = tmp_path / MODEL
    folder.mkdir()
    _unzip(MCC / "pnml" / f"{MODEL}.pnml.gz", folder / "model.pnml")
    for exam in ("CTLFireability", "ReachabilityCardinality", "UpperBounds"):
        _unzip(MCC / "queries" / f"{MODEL}.{exam}.xml.gz", folder / f"{exam}.xml")
    return folder


def _lines(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        words = line.split()
        assert words[0] == "FORMULA", line
        out[words[1]] = words[2]
    return out


def _expected(exam: str) -> dict[str, str]:
    formulas = _answers(MODEL)["examinations"][exam]["formulas"]
    return {
        f["id"]: (
            str(f["expected"]).upper() if isinstance(f["expected"], bool) else str(f["expected"])
        )
        for f in formulas
    }


@pytest.mark.slow
def test_query_files_print_one_mcc_line_each(
    mcc_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            "query",
            str(mcc_dir / "model.pnml"),
            str(mcc_dir / "CTLFireability.xml"),
            str(mcc_dir / "UpperBounds.xml"),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert _lines(out) == {**_expected("CTLFireability"), **_expected("UpperBounds")}
    assert all(line.endswith("TECHNIQUES EXPLICIT STATE_COMPRESSION") for line in out.splitlines())


@pytest.mark.slow
def test_examinations_found_in_the_mcc_folder(
    mcc_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            "query",
            str(mcc_dir),
            "--examination",
            "ReachabilityCardinality",
            "--examination",
            "ReachabilityDeadlock",
            "--examination",
            "Liveness",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    globals_ = _answers(MODEL)["global_properties"]
    expected = {
        **_expected("ReachabilityCardinality"),
        "ReachabilityDeadlock": str(globals_["ReachabilityDeadlock"]["expected"]).upper(),
        "Liveness": str(globals_["Liveness"]["expected"]).upper(),
    }
    assert _lines(out) == expected


def test_json_document_has_answers_times_and_traces(
    mcc_dir: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out_file = tmp_path / "out.json"
    code = main(
        [
            "query",
            str(mcc_dir),
            "--examination",
            "ReachabilityCardinality",
            "--examination",
            "ReachabilityDeadlock",
            "--format",
            "json",
            "-o",
            str(out_file),
        ]
    )
    assert code == 0 and capsys.readouterr().out == ""
    document = json.loads(out_file.read_text())
    assert document["model"] == MODEL
    assert document["answered"] == 17 and document["cannot_compute"] == 0
    results = {r["id"]: r for r in document["results"]}
    deadlock = results["ReachabilityDeadlock"]
    assert deadlock["answer"] is True and deadlock["trace_kind"] == "witness"
    assert all(isinstance(name, str) for name in deadlock["trace"])
    for r in document["results"]:
        assert r["status"] == "answered" and r["seconds"] >= 0 and r["techniques"]
        if r["trace"] is not None:
            assert r["trace_kind"] == ("witness" if r["answer"] else "counterexample")


def test_cannot_compute_exits_3(mcc_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["query", str(mcc_dir), "--examination", "CTLFireability", "--max-states", "5"])
    out = capsys.readouterr().out
    assert code == 3
    assert "CANNOT_COMPUTE" in out
    assert all(
        line.endswith("CANNOT_COMPUTE") or " TECHNIQUES " in line for line in out.splitlines()
    )


def test_bad_inputs_exit_2(
    mcc_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = str(mcc_dir / "model.pnml")
    bad_xml = tmp_path / "bad.xml"
    bad_xml.write_text("<property-set>\n<property><id>x</id><formula><oops/></formula>")
    unknown = tmp_path / "unknown.xml"
    unknown.write_text(
        '<property-set xmlns="http://mcc.lip6.fr/"><property><id>x</id><formula>'
        "<is-fireable><transition>nope</transition></is-fireable></formula></property>"
        "</property-set>"
    )
    bad_pnml = tmp_path / "bad.pnml"
    bad_pnml.write_text("<pnml><net")
    cases = [
        (["query", str(tmp_path / "missing.pnml"), str(bad_xml)], "no such file"),
        (["query", model, str(tmp_path / "missing.xml")], "missing.xml': no such file"),
        (["query", model, str(tmp_path)], "it is a directory"),
        (["query", model, str(bad_xml)], "bad.xml:2: not well-formed XML"),
        (["query", model, str(unknown)], "unknown.xml:1: unknown transition 'nope'"),
        (["query", str(bad_pnml), "--examination", "OneSafe"], "not well-formed XML"),
        (["query", model], "nothing to do"),
        (["query", model, "--examination", "LTLFireability"], "no LTLFireability.xml beside"),
        (["query", str(tmp_path), "--examination", "OneSafe"], "folder without model.pnml"),
        (["query", model, "--examination", "Reversibility"], "invalid choice"),
        (["query", model, "--examination", "OneSafe", "--time-limit", "0"], "more than 0"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err, (argv, err)
        assert "Traceback" not in err


def test_help_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["query", "--help"]) == 0
    assert "coral-check query" in capsys.readouterr().out


def test_output_over_an_input_is_refused(mcc_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = mcc_dir / "model.pnml"
    queries = mcc_dir / "UpperBounds.xml"
    before = queries.read_bytes()
    for argv in (
        ["query", str(model), str(queries), "-o", str(queries)],
        ["query", str(model), "--examination", "OneSafe", "-o", str(model)],
    ):
        assert main(argv) == 2
        assert "refusing to overwrite it" in capsys.readouterr().err
    assert queries.read_bytes() == before


def test_budgets_keep_query_s_own_defaults_and_help(capsys: pytest.CaptureFixture[str]) -> None:
    from analysis.examinations import DEFAULT_MAX_EDGES, DEFAULT_MAX_STATES
    from analysis.query_cli import build_query_parser

    args = build_query_parser().parse_args(["m.pnml", "--examination", "OneSafe"])
    assert (args.max_states, args.time_limit, args.max_edges) == (
        DEFAULT_MAX_STATES,
        600.0,
        DEFAULT_MAX_EDGES,
    )
    assert main(["query", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "time for the whole run (default 600)" in out and "--color" not in out
