"""``coral-check export``: the compiled net as PNML and DOT, to files or stdout; nothing
written for a mission with errors."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from analysis.cli import main
from coral_lang.compiler import compile_mission
from coral_lang.dot import to_dot
from coral_lang.pnml import read_pnml
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
UNHANDLED = EXAMPLES / "faulty" / "unhandled_reply.coral"


def test_pnml_and_dot_to_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pnml, dot = tmp_path / "pool.pnml", tmp_path / "pool.dot"
    assert main(["export", str(POOL), "--pnml", str(pnml), "--dot", str(dot)]) == 0
    net = compile_mission(POOL)
    assert read_pnml(pnml).digest() == net.digest()  # the same net, read back
    assert dot.read_text() == to_dot(net)
    assert capsys.readouterr().out == ""


def test_dash_writes_to_stdout_and_reads_stdin(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["export", str(POOL), "--dot", "-"]) == 0
    assert capsys.readouterr().out == to_dot(compile_mission(POOL))
    text = "mission s\nvehicle ROMEO\nplace a = 1, b\nfinal { b }\ntransition t wait { a } signal { b }\n"
    monkeypatch.setattr("sys.stdin", io.StringIO(text))
    assert main(["export", "-", "--pnml", "-"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("<?xml") and "<pnml" in out and 'id="t"' in out


def test_a_pnml_net_exports_to_dot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pnml = tmp_path / "pool.pnml"
    assert main(["export", str(POOL), "--pnml", str(pnml)]) == 0
    assert main(["export", str(pnml), "--dot", "-"]) == 0
    assert capsys.readouterr().out.startswith('digraph "pool_mission" {')


def test_errors_write_nothing_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.pnml"
    assert main(["export", str(UNHANDLED), "--pnml", str(out), "--dot", "-"]) == 1
    captured = capsys.readouterr()
    assert not out.exists() and captured.out == ""
    assert "[CORAL106]" in captured.err and "not exported" in captured.err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([str(POOL)], "nothing to write: give --pnml OUT and/or --dot OUT"),
        ([str(POOL), "--pnml", "-", "--dot", "-"], "--pnml and --dot both write to '-'"),
        ([str(POOL), "--dot", "/no/such/folder/x.dot"], "no such folder"),
        (["missing.coral", "--dot", "-"], "cannot read 'missing.coral': no such file"),
    ],
)
def test_usage_and_input_errors_are_exit_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["export", *argv]) == 2
    assert message in capsys.readouterr().err
