"""Includes from an include path, and the limits on what one mission may include."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.cli import main
from coral_lang import compiler
from coral_lang.compiler import (
    MAX_INCLUDED_BYTES,
    MAX_INCLUDED_FILES,
    compile_file,
    compile_source,
)
from coral_lang.mission import load_mission

HEADER = "mission m\nvehicle ROMEO\n"
SHARED = "place shared_done\ntransition finish wait { start } signal { shared_done }\n"


def _layout(tmp_path: Path) -> tuple[Path, Path]:
    """``missions/m.coral`` including ``common.coral``, which lives in ``lib/``."""
    (tmp_path / "missions").mkdir()
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "common.coral").write_text(SHARED)
    mission = tmp_path / "missions" / "m.coral"
    mission.write_text(HEADER + 'place start = 1\nfinal { shared_done }\ninclude "common.coral"\n')
    return mission, tmp_path / "lib"


def _messages(result: compiler.CompileResult) -> list[str]:
    return [e.message for e in result.errors]


def test_an_include_path_folder_supplies_files_the_mission_folder_lacks(tmp_path: Path) -> None:
    mission, lib = _layout(tmp_path)
    alone = compile_file(mission)
    assert any("file not found" in m for m in _messages(alone)), _messages(alone)
    result = compile_file(mission, include_path=[lib])
    assert result.ok, _messages(result)
    assert result.net is not None and "shared_done" in result.net.place_names
    # The including file's own folder comes first: a copy beside it wins.
    (mission.parent / "common.coral").write_text(SHARED.replace("shared_done", "local_done"))
    (mission.parent / "m.coral").write_text(mission.read_text().replace("shared_", "local_"))
    local = compile_file(mission, include_path=[lib])
    assert local.net is not None and "local_done" in local.net.place_names


def test_the_include_path_widens_confinement_and_nothing_else(tmp_path: Path) -> None:
    mission, lib = _layout(tmp_path)
    (tmp_path / "secret.coral").write_text("place secret\n")
    mission.write_text(mission.read_text() + 'include "../secret.coral"\n')
    result = compile_file(mission, include_path=[lib])
    [refused] = [e for e in result.errors if "outside" in e.message]
    assert str(refused.span) == f"{mission}:6:1"
    assert str(lib.resolve()) in refused.message and "--include-path" in refused.notes[0]
    assert not any("place secret" in text for text in result.sources.values())
    # Relative to the include-path folder: '../secret.coral' from lib is still outside.
    (lib / "more.coral").write_text('include "../secret.coral"\n')
    nested = compile_source(
        HEADER + 'include "more.coral"\n', "x.coral", base_dir=mission.parent, include_path=[lib]
    )
    assert any("outside" in m for m in _messages(nested))
    assert not any("place secret" in text for text in nested.sources.values())


def test_the_limits_are_16_mb_and_256_files() -> None:
    assert MAX_INCLUDED_BYTES == 16 * 1024 * 1024 and MAX_INCLUDED_FILES == 256


def test_too_many_included_files_are_refused_at_the_include_that_crossed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(compiler, "MAX_INCLUDED_FILES", 3)  # the mission and two more
    for n in range(4):
        (tmp_path / f"part{n}.coral").write_text(f"place p{n}\n")
    mission = tmp_path / "m.coral"
    mission.write_text(HEADER + "".join(f'include "part{n}.coral"\n' for n in range(4)))
    result = compile_file(mission)
    [refused] = result.errors  # reported once, not once per later include
    assert str(refused.span) == f"{mission}:5:1" and refused.code == "CORAL004"
    assert "brings the mission's files to more than 3 files" in refused.message
    assert "part2.coral" in refused.message
    assert not any(name.endswith(("part2.coral", "part3.coral")) for name in result.sources)


def test_too_many_bytes_in_all_are_refused_at_the_include_that_crossed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(compiler, "MAX_INCLUDED_BYTES", 1_000)
    (tmp_path / "small.coral").write_text("# " + "x" * 300 + "\nplace a\n")
    (tmp_path / "big.coral").write_text("# " + "x" * 700 + "\nplace b\n")
    (tmp_path / "nested.coral").write_text('include "big.coral"\n')
    mission = tmp_path / "m.coral"
    mission.write_text(HEADER + 'include "small.coral"\ninclude "nested.coral"\n')
    result = compile_file(mission)
    [refused] = result.errors
    # The include that crossed the total is in nested.coral, line 1: named there.
    assert refused.span is not None and refused.span.file.endswith("nested.coral")
    assert (refused.span.line, refused.span.col) == (1, 1)
    assert "over the 1,000-byte limit" in refused.message
    # Within the limit the same mission compiles.
    monkeypatch.setattr(compiler, "MAX_INCLUDED_BYTES", 2_000)
    assert not compile_file(mission).errors


def test_coral_check_takes_include_path_on_every_compiling_subcommand(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission, lib = _layout(tmp_path)
    assert main(["lint", str(mission)]) == 1  # the include is not found without it
    assert "file not found" in capsys.readouterr().out
    for argv in (
        ["lint", str(mission)],
        ["--format", "json", str(mission)],
        ["verify", str(mission)],
        [str(mission)],
    ):
        assert main([*argv, "--include-path", str(lib)]) in (0, 3), argv
    capsys.readouterr()
    for argv in (["lint", str(mission)], ["verify", str(mission)], [str(mission)]):
        assert main([*argv, "--include-path", str(tmp_path / "nowhere")]) == 2
        assert "--include-path" in capsys.readouterr().err


def test_load_mission_takes_the_include_path(tmp_path: Path) -> None:
    mission, lib = _layout(tmp_path)
    loaded = load_mission(mission, include_path=[lib])
    assert "shared_done" in loaded.net.place_names
    assert any(name.endswith("common.coral") for name in loaded.sources)
