"""The one check pipeline: lint selection, standard input, mission parts, bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.pipeline import STDIN, STDIN_NAME, CheckOptions, check_file, is_selected
from analysis.verify import VerifyOptions
from tests.conftest import EXAMPLES

DEAD = EXAMPLES / "faulty" / "dead_transition.coral"  # CORAL204 and CORAL205 warnings
FAST = VerifyOptions(structural=False)

MISSION = """\
mission whole
vehicle ROMEO

place start = 1
place done, spare

final { done }

transition go
    wait   { start }
    signal { done }

include "part.coral"
"""

PART = """\
# coral: part of whole.coral
# The second half: declares a place nothing uses.
place unused_in_part
"""

codes = st.text(alphabet="CORAL0123456789", min_size=1, max_size=8)


@given(code=codes, select=st.lists(codes, max_size=3), ignore=st.lists(codes, max_size=3))
def test_selection_is_prefix_matching_and_ignore_wins(
    code: str, select: list[str], ignore: list[str]
) -> None:
    chosen = is_selected(code, select, ignore)
    ignored = any(code.startswith(prefix) for prefix in ignore)
    picked = not select or any(code.startswith(prefix) for prefix in select)
    assert chosen == (picked and not ignored)
    assert is_selected(code, select, [*ignore, code]) is False  # ignoring it always wins
    assert is_selected(code, [code[:1]], ()) is True


def test_select_and_ignore_filter_lint_findings_only() -> None:
    everything = check_file(DEAD, CheckOptions())
    assert {d.code for d in everything.diagnostics} == {"CORAL204", "CORAL205"}

    def kept(**options: tuple[str, ...]) -> set[str]:
        return {d.code for d in check_file(DEAD, CheckOptions(**options)).diagnostics}  # type: ignore[arg-type]

    assert kept(ignore=("CORAL205",)) == {"CORAL204"}
    assert kept(select=("CORAL204",)) == {"CORAL204"}
    assert kept(select=("CORAL2",), ignore=("CORAL204",)) == {"CORAL205"}
    assert kept(select=("CORAL9",)) == set()
    # The verified path filters the same way.
    verified = check_file(DEAD, CheckOptions(verify=FAST, ignore=("CORAL2",)))
    assert verified.diagnostics == () and verified.report is not None


def test_compile_errors_cannot_be_ignored(tmp_path: Path) -> None:
    broken = tmp_path / "broken.coral"
    broken.write_text(DEAD.read_text().replace("ROMEO(FIX_XY", "ROMEO(FIX_XZ"))
    outcome = check_file(broken, CheckOptions(ignore=("CORAL",), verify=FAST))
    assert outcome.status() == "errors" and outcome.exit_code() == 1
    assert [d.code for d in outcome.errors] == ["CORAL101"]


def test_standard_input_is_named_stdin_and_includes_resolve_from_the_cwd(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "part.coral").write_text(PART.replace("# coral: part of whole.coral\n", ""))
    monkeypatch.chdir(tmp_path)
    outcome = check_file(STDIN, CheckOptions(text=MISSION))
    assert outcome.path == STDIN_NAME == "<stdin>"
    assert outcome.status() == "clean", outcome.diagnostics
    where = {(d.code, d.span.file if d.span else None) for d in outcome.diagnostics}
    assert ("CORAL203", STDIN_NAME) in where  # 'spare', in the text read
    assert ("CORAL203", "part.coral") in where  # included from the current folder
    broken = check_file(STDIN, CheckOptions(text="mission m\nvehicle ROMEO\nplace = 1\n"))
    assert broken.path == STDIN_NAME and broken.status() == "errors"
    assert all(d.span is None or d.span.file == STDIN_NAME for d in broken.diagnostics)


def test_unreadable_input_is_an_outcome_not_an_exception(tmp_path: Path) -> None:
    assert check_file(tmp_path / "gone.coral", CheckOptions()).input_error == "no such file"
    assert check_file(tmp_path, CheckOptions()).input_error == "it is a directory"
    latin = tmp_path / "latin.coral"
    latin.write_bytes(b"mission caf\xe9\n")
    problem = check_file(latin, CheckOptions()).input_error
    assert problem is not None and problem.startswith("not UTF-8 text")
    huge = check_file(STDIN, CheckOptions(text="#" * (5 * 1024 * 1024)))
    assert huge.path == STDIN_NAME and huge.exit_code() == 2
    assert huge.input_error is not None and "over the limit" in huge.input_error


def test_a_part_is_checked_with_its_mission_and_not_verified(tmp_path: Path) -> None:
    mission, part = tmp_path / "whole.coral", tmp_path / "part.coral"
    mission.write_text(MISSION)
    part.write_text(PART)
    outcome = check_file(part, CheckOptions(verify=FAST))
    assert outcome.status() == "part" and outcome.exit_code() == 0
    assert outcome.report is None and outcome.part_of is not None
    assert Path(outcome.part_of).name == "whole.coral"
    # Only the part's own findings: 'unused_in_part' here, not 'spare' of the mission.
    messages = [d.message for d in outcome.diagnostics]
    assert len(messages) == 1 and "unused_in_part" in messages[0]
    assert check_file(part, CheckOptions(ignore=("CORAL203",))).diagnostics == ()
    entry = outcome.to_dict()
    assert entry["status"] == "part" and entry["part_of"] == outcome.part_of
    # The mission itself is verified as usual and reports both findings.
    whole = check_file(mission, CheckOptions(verify=FAST))
    assert whole.report is not None and whole.part_of is None and len(whole.diagnostics) == 2


def test_a_part_of_a_broken_mission_shows_every_error(tmp_path: Path) -> None:
    (tmp_path / "whole.coral").write_text(MISSION.replace("wait   { start }", "wait { start"))
    part = tmp_path / "part.coral"
    part.write_text(PART)
    outcome = check_file(part, CheckOptions())
    assert outcome.status() == "errors" and outcome.exit_code() == 1
    assert [Path(d.span.file).name for d in outcome.errors if d.span] == ["whole.coral"]


def test_the_pool_missions_parts_pass_together() -> None:
    files = sorted((EXAMPLES / "pool_mission").glob("*.coral"))
    outcomes = [check_file(f, CheckOptions()) for f in files]
    assert {o.status() for o in outcomes} == {"part", "clean"}
    assert [o.path for o in outcomes if o.status() == "clean"] == [
        str(EXAMPLES / "pool_mission" / "pool_mission.coral")
    ]
