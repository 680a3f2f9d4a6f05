"""Parts of a mission: files that start with ``# coral: part of FILE.coral``.

Loading a part compiles the whole mission it names; every way the header can be wrong
is an error at the header (CORAL011).
"""

from __future__ import annotations

from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from coral_lang.compiler import compile_file, compile_source, part_header
from coral_lang.loading import load_net_file
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission"
PARTS = ("abort", "docking", "go_to_operating_site", "waypoint_navigation")
MISSION = "mission m\nvehicle ROMEO\nplace start = 1, done\nfinal { done }\n"
PART = "# coral: part of m.coral\ntransition finish wait { start } signal { done }\n"


def _write(folder: Path, **files: str) -> None:
    for name, text in files.items():
        (folder / f"{name}.coral").write_text(text)


def _located(path: Path) -> list[str]:
    """``line:col: message [code]`` of each error of loading ``path``."""
    result = load_net_file(path)
    return [f"{e.span.line}:{e.span.col}: {e.message} [{e.code}]" for e in result.errors if e.span]


def test_each_pool_phase_loads_as_the_whole_pool_mission() -> None:
    whole = load_net_file(POOL / "pool_mission.coral")
    assert whole.ok and whole.part_of is None and whole.part_path is None
    assert whole.net is not None
    for name in PARTS:
        part = POOL / f"{name}.coral"
        result = load_net_file(part)
        assert result.ok, [e.render(result.sources) for e in result.errors]
        assert result.part_of == POOL / "pool_mission.coral"
        assert result.part_path == part
        assert result.net is not None and result.net.digest() == whole.net.digest()


def test_the_operator_examples_abort_path_is_a_part_of_its_mission() -> None:
    result = load_net_file(EXAMPLES / "operator" / "abort_path.coral")
    assert result.ok and result.part_of == EXAMPLES / "operator" / "abort.coral"


def test_the_header_is_only_a_comment_when_the_mission_includes_the_part(tmp_path: Path) -> None:
    _write(tmp_path, m=MISSION + 'include "p.coral"\n', p=PART)
    with_header = compile_file(tmp_path / "m.coral")
    (tmp_path / "p.coral").write_text(PART.split("\n", 1)[1])
    without = compile_file(tmp_path / "m.coral")
    assert with_header.ok and without.ok and with_header.part_of is None
    assert with_header.net is not None and without.net is not None
    assert with_header.net.digest() == without.net.digest()


def test_a_part_in_a_subfolder_names_its_mission_relative_to_its_own_folder(
    tmp_path: Path,
) -> None:
    (tmp_path / "phases").mkdir()
    _write(tmp_path, m=MISSION + 'include "phases/p.coral"\n')
    part = tmp_path / "phases" / "p.coral"
    part.write_text("# The last phase.\n\n" + PART.replace("m.coral", "../m.coral"))
    result = load_net_file(part)
    assert result.ok and result.part_of == tmp_path / "m.coral" and result.part_path == part


def test_a_mission_that_does_not_exist_is_an_error_at_the_header(tmp_path: Path) -> None:
    _write(tmp_path, p="# A phase.\n" + PART.replace("m.coral", "gone.coral"))
    assert _located(tmp_path / "p.coral") == [
        f"2:1: this file is a part of {tmp_path / 'gone.coral'}, which cannot be read: "
        "no such file [CORAL011]"
    ]


def test_a_mission_that_does_not_include_the_part_is_an_error_and_stays_unquoted(
    tmp_path: Path,
) -> None:
    _write(tmp_path, m=MISSION + "# the secret line\n", p=PART)
    result = load_net_file(tmp_path / "p.coral")
    [error] = result.errors
    assert error.code == "CORAL011" and error.span is not None and error.span.line == 1
    assert error.message == (
        f"{tmp_path / 'm.coral'} does not include this file, directly or through its includes"
    )
    assert 'include "p.coral"' in error.notes[0]
    assert list(result.sources) == [str(tmp_path / "p.coral")]  # the mission is not shown
    assert result.net is None and result.part_of is None


def test_an_include_through_another_file_counts(tmp_path: Path) -> None:
    _write(
        tmp_path,
        m=MISSION + 'include "middle.coral"\n',
        middle='# coral: part of m.coral\ninclude "p.coral"\n',
        p=PART,
    )
    assert load_net_file(tmp_path / "p.coral").ok
    assert load_net_file(tmp_path / "middle.coral").ok


def test_a_header_naming_the_part_itself_is_refused(tmp_path: Path) -> None:
    _write(tmp_path, p=PART.replace("m.coral", "./p.coral"))
    assert _located(tmp_path / "p.coral") == ["1:1: a part names itself as its mission [CORAL011]"]


def test_a_part_of_a_part_is_refused_with_the_header_it_should_have(tmp_path: Path) -> None:
    (tmp_path / "phases").mkdir()
    _write(tmp_path, m=MISSION + 'include "phases/a.coral"\n')
    (tmp_path / "phases" / "a.coral").write_text('# coral: part of ../m.coral\ninclude "b.coral"\n')
    (tmp_path / "phases" / "b.coral").write_text(PART.replace("m.coral", "a.coral"))
    result = load_net_file(tmp_path / "phases" / "b.coral")
    [error] = result.errors
    assert error.message == (
        f"{tmp_path / 'phases' / 'a.coral'} is itself a part (of ../m.coral): a part names "
        "the whole mission, not another part"
    )
    assert error.notes == ("write '# coral: part of ../m.coral'",)


def test_a_header_after_a_declaration_is_an_error_wherever_the_file_is_read(
    tmp_path: Path,
) -> None:
    late = "transition finish wait { start } signal { done }\n  # coral: part of m.coral\n"
    compiled = compile_source(MISSION + late, "m.coral")
    [error] = compiled.errors
    assert error.span is not None and (error.span.line, error.span.col) == (6, 3)
    assert error.message == "'# coral: part of' must come before the file's first declaration"
    _write(tmp_path, m=MISSION + 'include "p.coral"\n', p=late)
    assert [e.code for e in compile_file(tmp_path / "m.coral").errors] == ["CORAL011"]
    assert "CORAL011" in [e.code for e in load_net_file(tmp_path / "p.coral").errors]


def test_a_second_or_malformed_header_is_an_error() -> None:
    header, errors = part_header(
        "# coral: part of a.coral\n# coral: part of b.coral\n# coral: part a.coral\n", "p"
    )
    assert header is not None and header.mission == "a.coral"
    assert [(e.span.line if e.span else 0, e.message) for e in errors] == [
        (2, "a file is a part of one mission only: line 1 already names a.coral"),
        (3, "a part's header names its mission's file: '# coral: part of MISSION.coral'"),
    ]


def test_a_part_compiled_alone_says_which_mission_to_check() -> None:
    result = compile_file(POOL / "abort.coral")
    assert [e.code for e in result.errors] == ["CORAL007"]  # no knock-on vehicle error
    assert "a part of pool_mission.coral (line 1)" in result.errors[0].notes[0]


@given(
    st.lists(
        st.sampled_from(["", "# a comment", "   ", "#", "# coral: allow CORAL201"]), max_size=6
    )
)
def test_comments_and_blank_lines_may_come_before_the_header(before: list[str]) -> None:
    text = "".join(line + "\n" for line in before) + PART
    header, errors = part_header(text, "p.coral")
    assert errors == []
    assert header is not None and header.mission == "m.coral"
    assert header.span.line == len(before) + 1


def test_a_header_in_a_file_with_windows_line_ends_is_recognised(tmp_path: Path) -> None:
    _write(tmp_path, m=MISSION + 'include "p.coral"\n')
    (tmp_path / "p.coral").write_bytes(PART.replace("\n", "\r\n").encode())
    result = load_net_file(tmp_path / "p.coral")
    assert result.ok and result.part_of == tmp_path / "m.coral"
