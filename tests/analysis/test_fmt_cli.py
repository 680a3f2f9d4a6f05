"""``coral-check fmt``: in place (atomically), ``--check``, ``--diff``, standard input, and
files that do not parse left alone. The layout itself is `coral_lang.formatting`'s
(tests/coral_lang/test_formatting.py); here only what the command does with files."""

from __future__ import annotations

import io
import os
import stat
import subprocess
from pathlib import Path

import pytest

from analysis import cli_fmt
from analysis.cli import main
from coral_lang.formatting import format_source

MESSY = (
    "mission m\nvehicle ROMEO\n# why this mission exists\n"
    "place   a = 1,b\nfinal {b}\ntransition t wait {a} signal {b}  # the only step\n"
)
BROKEN = "mission m\nvehicle ROMEO\nplace a = 1,\ntransition\n"


@pytest.fixture
def messy(tmp_path: Path) -> Path:
    path = tmp_path / "messy.coral"
    path.write_text(MESSY)
    return path


@pytest.fixture
def tidy(tmp_path: Path) -> Path:
    path = tmp_path / "tidy.coral"
    path.write_text(format_source(MESSY, str(path)))
    return path


def test_the_fixture_is_really_messy_and_formatting_settles() -> None:
    formatted = format_source(MESSY, "m.coral")
    assert formatted != MESSY and format_source(formatted, "m.coral") == formatted
    assert "# why this mission exists" in formatted and "# the only step" in formatted


def test_in_place_rewrites_only_what_changes_and_keeps_the_mode(
    messy: Path, tidy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    messy.chmod(0o640)
    before = tidy.stat().st_mtime_ns
    assert main(["fmt", str(messy), str(tidy)]) == 0
    assert messy.read_text() == format_source(MESSY, str(messy))
    assert stat.S_IMODE(messy.stat().st_mode) == 0o640
    assert tidy.stat().st_mtime_ns == before  # unchanged files are not written
    err = capsys.readouterr().err
    assert f"reformatted {messy}" in err and "1 file reformatted, 1 file already formatted" in err
    assert not [p for p in messy.parent.iterdir() if p.name.endswith(".tmp")]
    assert main(["fmt", str(messy)]) == 0  # a second run has nothing to do


def test_check_lists_the_files_that_would_change_and_writes_nothing(
    messy: Path, tidy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["fmt", "--check", str(messy), str(tidy)]) == 1
    assert messy.read_text() == MESSY
    err = capsys.readouterr().err
    assert f"would reformat {messy}" in err and str(tidy) not in err
    assert "1 file would be reformatted, 1 file already formatted" in err
    assert main(["fmt", "--check", str(tidy)]) == 0


def test_diff_prints_a_unified_diff_and_writes_nothing(
    messy: Path, tidy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["fmt", "--diff", str(messy), str(tidy)]) == 1
    out = capsys.readouterr().out
    assert out.startswith(f"--- {messy}\n+++ {messy} (formatted)\n@@ ")
    assert "-place   a = 1,b\n" in out and "+place a = 1, b\n" in out
    assert messy.read_text() == MESSY
    assert main(["fmt", "--diff", str(tidy)]) == 0
    assert capsys.readouterr().out == ""


def test_a_file_that_does_not_parse_is_reported_and_never_touched(
    tmp_path: Path, messy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "broken.coral"
    broken.write_text(BROKEN)
    assert main(["fmt", str(broken), str(messy)]) == 1
    assert broken.read_text() == BROKEN
    assert messy.read_text() != MESSY  # the other file is still formatted
    err = capsys.readouterr().err
    assert f"{broken}:4:" in err and "error:" in err and "not formatted" in err


def test_unreadable_files_are_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fmt", str(tmp_path / "missing.coral")]) == 2
    err = capsys.readouterr().err
    assert "cannot read" in err and "no such file" in err
    net = tmp_path / "net.pnml"
    net.write_text("<pnml/>")
    assert main(["fmt", str(net)]) == 2
    assert "a PNML net has no CORAL layout" in capsys.readouterr().err


def test_standard_input_goes_to_standard_output(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.stdin", io.StringIO(MESSY))
    assert main(["fmt", "-"]) == 0
    assert capsys.readouterr().out == format_source(MESSY, "<stdin>")
    monkeypatch.setattr("sys.stdin", io.StringIO(MESSY))
    assert main(["fmt", "--check", "-"]) == 1
    assert "would reformat <stdin>" in capsys.readouterr().err
    monkeypatch.setattr("sys.stdin", io.StringIO(BROKEN))
    assert main(["fmt", "-"]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and "<stdin>:4:" in captured.err


def test_a_failed_write_leaves_the_file_and_no_temporary(
    messy: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def refuse(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    assert main(["fmt", str(messy)]) == 2
    assert messy.read_text() == MESSY
    assert not [p for p in messy.parent.iterdir() if p.name.endswith(".tmp")]
    assert "No space left on device" in capsys.readouterr().err


def test_the_formatter_is_the_library_s(messy: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The command adds no layout of its own: whatever format_source returns is written."""
    monkeypatch.setattr(cli_fmt, "_format", lambda text, file: text.upper())
    assert main(["fmt", str(messy)]) == 0
    assert messy.read_text() == MESSY.upper()


def test_a_symlink_is_written_through_to_its_target(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    real = tmp_path / "real"
    real.mkdir()
    target = real / "target.coral"
    target.write_text(MESSY)
    target.chmod(0o600)
    link = tmp_path / "link.coral"
    link.symlink_to(target)
    assert main(["fmt", str(link)]) == 0
    assert link.is_symlink() and link.resolve() == target.resolve()
    assert target.read_text() == format_source(MESSY, str(link))
    assert stat.S_IMODE(target.stat().st_mode) == 0o600
    assert not [p for p in [*tmp_path.iterdir(), *real.iterdir()] if p.name.endswith(".tmp")]
    assert f"reformatted {link}" in capsys.readouterr().err


def _lines(text: str) -> list[str]:
    """Lines ended by "\\n" only, as patch reads them (never `str.splitlines`)."""
    *ended, last = text.split("\n")
    return [line + "\n" for line in ended] + ([last] if last else [])


def _apply_unified_diff(before: str, diff: str) -> str:
    """Apply a one-file unified diff as patch does, honouring the
    "\\ No newline at end of file" marker (a deliberately small, strict reader)."""
    old = _lines(before)
    out: list[str] = []
    lines = _lines(diff)
    assert lines[0].startswith("--- ") and lines[1].startswith("+++ ")
    at = 0  # next line of `old` not yet copied
    last: list[str] | None = None  # the list the previous diff line went to
    for line in lines[2:]:
        if line.startswith("@@"):
            start = int(line.split()[1].lstrip("-").split(",")[0])
            first = max(start - 1, 0)
            out += old[at:first]
            at = first
            continue
        if line == cli_fmt.NO_NEWLINE:
            assert last is not None and last[-1].endswith("\n")
            last[-1] = last[-1][:-1]
            continue
        tag, body = line[0], line[1:]
        assert tag in " -+", line
        if tag in " -":
            assert old[at].rstrip("\n") == body.rstrip("\n")
            at += 1
        if tag in " +":
            out.append(body)
            last = out
        else:
            last = [body]
    return "".join(out + old[at:])


@pytest.mark.parametrize("final_newline", [True, False])
def test_diff_without_a_final_newline_is_a_proper_unified_diff(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], final_newline: bool
) -> None:
    text = MESSY if final_newline else MESSY.rstrip("\n")
    path = tmp_path / "m.coral"
    path.write_text(text)
    formatted = format_source(text, str(path))
    assert main(["fmt", "--diff", str(path)]) == 1
    diff = capsys.readouterr().out
    lines = _lines(diff)
    assert all(line.endswith("\n") for line in lines)
    assert all(line[0] in " -+@\\" for line in lines[2:]), diff
    assert (cli_fmt.NO_NEWLINE in lines) is not final_newline
    assert _apply_unified_diff(text, diff) == formatted
    assert path.read_text() == text


def test_the_diff_applies_with_patch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], patch_program: str
) -> None:
    patch = patch_program
    path = tmp_path / "m.coral"
    path.write_text(MESSY.rstrip("\n"))
    assert main(["fmt", "--diff", str(path)]) == 1
    diff = tmp_path / "m.diff"
    diff.write_text(capsys.readouterr().out)
    subprocess.run(
        [patch, "-s", str(path), str(diff)], check=True, cwd=tmp_path, capture_output=True
    )
    assert path.read_text() == format_source(MESSY.rstrip("\n"), str(path))


ODD_BREAKS = (
    "mission m\nvehicle ROMEO\n# page\x0cbreak, line\u2028separator, \x85 \x1c\x1d\x1e \v end\n"
    "place   a = 1,b\nfinal {b}\ntransition t wait {a} signal {b}  # x\u2029y\x0cz"
)
"""A mission whose comments hold every character `str.splitlines` breaks at but diff
and patch do not (no final newline either)."""


def _fmt_diff(path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> str:
    path.write_text(text, encoding="utf-8", newline="")
    assert main(["fmt", "--diff", str(path)]) == 1
    return capsys.readouterr().out


def test_the_diff_of_comments_with_odd_line_breaks_applies(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "m.coral"
    diff = _fmt_diff(path, ODD_BREAKS, capsys)
    hunk = [line for line in _lines(diff) if line.startswith("-#")]
    assert hunk == [], diff  # the comment line is unchanged: context, never cut in two
    assert _apply_unified_diff(ODD_BREAKS, diff) == format_source(ODD_BREAKS, str(path))


def test_the_diff_of_odd_line_breaks_applies_with_patch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], patch_program: str
) -> None:
    patch = patch_program
    path = tmp_path / "m.coral"
    diff = tmp_path / "m.diff"
    diff.write_text(_fmt_diff(path, ODD_BREAKS, capsys), encoding="utf-8", newline="")
    subprocess.run(
        [patch, "-s", str(path), str(diff)], check=True, cwd=tmp_path, capture_output=True
    )
    expected = format_source(ODD_BREAKS, str(path))
    assert path.read_bytes().decode("utf-8") == expected
