"""coral-check as a function: help texts, every exit code, formats, colour, start-up cost."""

from __future__ import annotations

import io
import json
import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.cli import build_lint_parser, build_parser, build_verify_parser, main
from analysis.outcome import JSON_SCHEMA_VERSION, worst_exit_code
from tests.conftest import EXAMPLES, REPO

POOL = str(EXAMPLES / "pool_mission" / "pool_mission.coral")
FAULTY = EXAMPLES / "faulty"
DEADLOCK = str(FAULTY / "deadlock.coral")
UNHANDLED = str(FAULTY / "unhandled_reply.coral")

# Ten steps to the only final marking: with a budget of 3 states the search cannot
# reach it, and nothing else decides reachability, so the verdict is inconclusive.
CHAIN = (
    "mission chain\nvehicle ROMEO\n"
    "place p0 = 1, p1, p2, p3, p4, p5, p6, p7, p8, p9, p10\nfinal { p10 }\n"
    + "".join(f"transition t{i} wait {{ p{i} }} signal {{ p{i + 1} }}\n" for i in range(10))
)


@pytest.fixture
def chain(tmp_path: Path) -> str:
    path = tmp_path / "chain.coral"
    path.write_text(CHAIN)
    return str(path)


# -- help -------------------------------------------------------------------------------


@pytest.fixture
def wide(monkeypatch: pytest.MonkeyPatch) -> None:
    """Help text on one line per paragraph (argparse wraps at the terminal's width)."""
    monkeypatch.setenv("COLUMNS", "1000")


@pytest.mark.usefixtures("wide")
def test_help_lists_the_subcommands_in_the_usage_line_and_the_exit_codes(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    usage = out.splitlines()[0]
    assert usage == (
        "usage: coral-check [-h] [--version] {check,lint,verify,fmt,export,keygen,resign,query} ..."
    )
    assert "coral-check --explain CODE" in out and "coral.toml" in out
    assert "exit codes: 0 clean" in out and "2 > 1 > 3 > 0" in out
    assert build_parser().prog == "coral-check"
    assert main(["check", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: coral-check check [-h]")
    assert "--format {text,json,sarif,html}" in out and "--select CODES" in out
    assert "--color {auto,always,never}" in out and "NO_COLOR" in out


def test_version_on_the_command_and_its_subcommands_is_the_package_s(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--version"]) == 0
    assert re.fullmatch(r"coral-check \(coral \S+\)\n", capsys.readouterr().out)


@pytest.mark.usefixtures("wide")
def test_lint_help_and_verify_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: coral-check lint") and "pre-commit" in out
    assert "--format {text,json,sarif}" in out and "2 > 1 > 0" in out
    assert main(["verify", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: coral-check verify") and "--certificate FILE" in out
    assert "--color {auto,always,never}" in out
    assert build_lint_parser().prog == "coral-check lint"
    assert build_verify_parser().prog == "coral-check verify"


# -- exit codes -------------------------------------------------------------------------


def test_clean_mission_exits_0_with_verdicts_and_summary(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([POOL]) == 0
    captured = capsys.readouterr()
    assert "net 'pool_mission'  sha256:" in captured.out
    assert re.search(r"^PROVEN +: 12 proven, 0 violated, 0 inconclusive$", captured.out, re.M)
    assert captured.out.rstrip().endswith("pool_mission.coral: proven, 0 warnings")
    assert captured.err == ""


def test_violated_property_exits_1_with_the_trace(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([DEADLOCK]) == 1
    out = capsys.readouterr().out
    assert "VIOLATED" in out and "set_depth: DEPTH replied error" in out
    assert "deadlock.coral:25" in out and out.rstrip().endswith(
        "deadlock.coral: violated, 0 warnings"
    )


def test_compile_errors_exit_1_with_diagnostics_and_no_verification(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([UNHANDLED]) == 1
    out = capsys.readouterr().out
    assert "unhandled_reply.coral:20:20: error:" in out and "[CORAL106]" in out and "^~~~~~" in out
    assert "1 error; not verified" in out and "PROVEN" not in out


def test_inconclusive_exits_3(chain: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([chain, "--max-states", "3"]) == 3
    assert "INCONCLUSIVE" in capsys.readouterr().out
    assert main([chain]) == 0


def test_unreadable_input_and_bad_usage_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main([str(tmp_path / "nope.coral")]) == 2
    assert "coral-check: error: cannot read" in capsys.readouterr().err
    assert main([str(tmp_path)]) == 2
    assert "it is a directory" in capsys.readouterr().err
    latin = tmp_path / "latin.coral"
    latin.write_bytes(b"mission caf\xe9\n")
    assert main([str(latin)]) == 2
    assert "not UTF-8 text (invalid continuation byte at byte 11)" in capsys.readouterr().err
    for bad in (
        [],
        ["--no-such-flag", POOL],
        ["--format", "xml", POOL],
        ["--max-states", "0", POOL],
        ["--time-limit", "soon", POOL],
        ["--link-rtt", "-1", POOL],
        ["--color", "sometimes", POOL],
        ["-o", str(tmp_path / "no" / "such" / "dir.json"), POOL],
        ["-o", str(tmp_path), POOL],
        ["lint", "--format", "html", POOL],
        ["lint"],
    ):
        assert main(bad) == 2, bad
    err = capsys.readouterr().err
    assert "invalid choice: 'xml'" in err and "not a number: 'soon'" in err
    assert "must be 0 or more" in err and "no such folder" in err and "it is a directory" in err
    assert "Traceback" not in err


def test_bad_profile_exits_2_naming_the_field(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicle: ROMEO\ncommands: {DEPTH: {kind: taks, replies: [ack]}}\n")
    assert main(["--profile", str(bad), POOL]) == 2
    assert "commands.DEPTH.kind" in capsys.readouterr().err


@pytest.mark.slow
def test_worst_exit_code_wins_in_the_order_2_1_3_0(chain: str, tmp_path: Path) -> None:
    missing = str(tmp_path / "missing.coral")
    assert main([POOL, UNHANDLED]) == 1
    assert main([POOL, missing]) == 2
    assert main([chain, DEADLOCK, "--max-states", "3"]) == 1
    assert main([POOL, chain, "--max-states", "3"]) == 3
    assert main([DEADLOCK, missing, chain, "--max-states", "3"]) == 2
    assert worst_exit_code([]) == 0
    for codes, worst in (([0, 3], 3), ([3, 1], 1), ([1, 2, 3], 2), ([0, 0], 0)):
        assert worst_exit_code(codes) == worst == worst_exit_code(reversed(codes))


# -- lint only --------------------------------------------------------------------------


def test_lint_subcommand_lints_without_verifying(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", str(FAULTY / "dead_transition.coral"), POOL]) == 0
    out = capsys.readouterr().out
    assert "[CORAL204]" in out and "dead_transition.coral: ok, 2 warnings" in out
    assert "ok, net 'pool_mission'" in out and "digest sha256:" in out
    assert "VIOLATED" not in out and "PROVEN" not in out and "2 files: 2 clean" in out
    assert main(["lint", UNHANDLED]) == 1
    assert main(["lint", "-q", POOL]) == 0
    assert capsys.readouterr().out.endswith("unhandled_reply.coral: 1 error\n")


def test_lint_subcommand_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", "--format", "json", str(FAULTY / "dead_transition.coral")]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["command"] == "lint" and data["files"][0]["report"] is None
    assert data["files"][0]["status"] == "clean"
    assert {d["code"] for d in data["files"][0]["diagnostics"]} == {"CORAL204", "CORAL205"}


# -- JSON -------------------------------------------------------------------------------


def test_json_document_is_one_versioned_object_per_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.json"
    missing = str(tmp_path / "missing.coral")
    files = [POOL, str(FAULTY / "dead_transition.coral"), UNHANDLED, missing]
    assert main([*files, "--format", "json", "-o", str(out)]) == 2
    assert capsys.readouterr().out == ""
    data = json.loads(out.read_text())
    assert data["schema"] == "coral-check" and data["schema_version"] == JSON_SCHEMA_VERSION
    assert data["tool"]["name"] == "coral-check" and data["tool"]["version"]
    assert data["command"] == "check" and data["exit_code"] == 2
    assert [f["file"] for f in data["files"]] == files
    assert [f["status"] for f in data["files"]] == ["proven", "violated", "errors", "unreadable"]
    assert [f["exit_code"] for f in data["files"]] == [0, 1, 1, 2]
    pool, dead, unhandled, unread = data["files"]
    assert pool["report"]["verdict"] == "proven" and pool["report"]["format"] == 1
    assert pool["report"]["structure"]["invariants"]["p_invariants"]
    warning = dead["diagnostics"][1]
    assert warning == {
        "code": "CORAL204",
        "severity": "warning",
        "file": str(FAULTY / "dead_transition.coral"),
        "line": 10,
        "col": 14,
        "end_line": 10,
        "end_col": 28,
        "message": warning["message"],
        "notes": [warning["notes"][0]],
    }
    assert dead["report"]["deadlock"]["verdict"] == "violated"
    assert unhandled["report"] is None and unhandled["diagnostics"][0]["code"] == "CORAL106"
    assert unread["error"] == "no such file" and unread["diagnostics"] == []


# -- colour -----------------------------------------------------------------------------


def test_colour_only_when_asked_in_a_pipe(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([DEADLOCK]) == 1
    assert "\033[" not in capsys.readouterr().out
    assert main([DEADLOCK, "--color", "always"]) == 1
    out = capsys.readouterr().out
    assert "\033[31mVIOLATED" in out and "\033[0m" in out
    assert main([DEADLOCK, "--color", "never"]) == 1
    assert "\033[" not in capsys.readouterr().out


def _run_in_a_terminal(args: list[str], env: dict[str, str]) -> str:
    """coral-check's stdout when it is a terminal (a pseudo-terminal here)."""
    controller, terminal = pty.openpty()
    try:
        completed = subprocess.run(
            [sys.executable, "-m", "analysis.cli", *args],
            stdout=terminal,
            stderr=subprocess.DEVNULL,
            cwd=REPO,
            env=env,
            timeout=120,
            check=False,
        )
    finally:
        os.close(terminal)
    chunks = []
    while True:
        try:
            chunk = os.read(controller, 65536)
        except OSError:  # the terminal side is closed and everything was read
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(controller)
    assert completed.returncode == 1
    return b"".join(chunks).decode()


@pytest.mark.slow
def test_colour_on_a_terminal_unless_no_color() -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("NO_COLOR", "TERM")}
    env["TERM"] = "xterm"
    assert "\033[31mVIOLATED" in _run_in_a_terminal([DEADLOCK], env)
    assert "\033[" not in _run_in_a_terminal([DEADLOCK], {**env, "NO_COLOR": "1"})
    assert "\033[" in _run_in_a_terminal([DEADLOCK, "--color", "always"], {**env, "NO_COLOR": "1"})


# -- verify subcommand ------------------------------------------------------------------


def test_verify_subcommand_keeps_its_report_and_lints_on_stderr(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    report, cert = tmp_path / "r.txt", tmp_path / "c.json"
    path = str(FAULTY / "dead_transition.coral")
    assert main(["verify", path, "-o", str(report), "--certificate", str(cert)]) == 1
    assert "[CORAL204]" in capsys.readouterr().err
    assert report.read_text().startswith("net 'faulty_dead_transition'")
    assert json.loads(cert.read_text())["verdict"] == "violated"
    assert main(["verify", path, "--color", "always"]) == 1
    assert "\033[31mVIOLATED" in capsys.readouterr().out


# -- start-up cost ----------------------------------------------------------------------


@pytest.mark.slow
def test_heavy_modules_load_only_when_needed() -> None:
    """z3, the PNML reader (XML) and matplotlib stay out of a lint-and-verify run of a
    mission: they cost start-up time that a pre-commit hook pays on every commit."""
    code = (
        "import sys\n"
        "from analysis.cli import main\n"
        f"code = main([{POOL!r}, '--format', 'json', '-o', '/dev/null'])\n"
        "heavy = [m for m in ('z3', 'coral_lang.pnml', 'xml.sax', 'matplotlib', 'networkx')"
        " if m in sys.modules]\n"
        "print(code, heavy)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    ).stdout
    assert out.strip() == "0 []"


@pytest.mark.slow
def test_a_closed_pipe_ends_quietly() -> None:
    """`coral-check ... | head -1`: no traceback when the reader goes away."""
    with subprocess.Popen(
        [sys.executable, "-m", "analysis.cli", DEADLOCK, POOL, POOL, POOL],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=REPO,
    ) as process:
        assert process.stdout is not None and process.stderr is not None
        process.stdout.readline()
        process.stdout.close()
        err = process.stderr.read().decode()
    assert process.returncode == 2 and "Traceback" not in err


# -- refused input files: exit 2 with the reason, in every subcommand --------------------

SUBCOMMANDS = {
    "check": lambda f: [f],
    "lint": lambda f: ["lint", f],
    "verify": lambda f: ["verify", f],
    "query": lambda f: ["query", f, "--examination", "ReachabilityDeadlock"],
}


def _refused_file(kind: str, folder: Path, suffix: str) -> tuple[str, str]:
    """A path coral must refuse unread, and the reason it must give."""
    path = folder / f"input{suffix}"
    if kind == "fifo":
        os.mkfifo(path)
        return str(path), "not a regular file (a FIFO)"
    if kind == "device":
        return "/dev/zero", "not a regular file (a character device)"
    if kind == "directory":
        path.mkdir()
        return str(path), "it is a directory"
    if kind == "large":
        with path.open("wb") as handle:  # sparse: no disk or memory spent on it
            handle.truncate(65 * 1024 * 1024)
        return str(path), "too large"
    return str(path), "no such file"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
@pytest.mark.parametrize("kind", ["fifo", "device", "directory", "large", "missing"])
@pytest.mark.parametrize("subcommand", sorted(SUBCOMMANDS))
def test_a_refused_input_file_exits_2_with_the_reason(
    subcommand: str, kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for suffix in (".coral", ".pnml"):
        if subcommand == "query" and suffix == ".coral":
            continue  # query reads PNML only
        folder = tmp_path / suffix[1:]
        folder.mkdir()
        file, reason = _refused_file(kind, folder, suffix)
        assert main(SUBCOMMANDS[subcommand](file)) == 2, (subcommand, kind, suffix)
        err = capsys.readouterr().err
        if kind == "directory" and subcommand == "query":
            reason = "is a folder without model.pnml"  # query also takes an MCC folder
        assert reason in err and file in err, err
        assert "Traceback" not in err


# -- one parser: subcommands, the shorthand, usage errors ---------------------------------


def test_the_shorthand_is_the_check_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([POOL, "--format", "json"]) == 0
    shorthand = json.loads(capsys.readouterr().out)
    assert main(["check", POOL, "--format", "json"]) == 0
    explicit = json.loads(capsys.readouterr().out)
    assert shorthand["command"] == explicit["command"] == "check"
    for key in ("file", "status", "diagnostics"):
        assert shorthand["files"][0][key] == explicit["files"][0][key]


@pytest.mark.parametrize(
    "argv",
    [
        [],
        ["check"],
        ["verify"],
        ["verify", POOL, POOL],
        ["fmt"],
        ["export", POOL],
        ["keygen"],
        ["resign"],
        ["query"],
        ["--bogus"],
        ["lint", POOL, "--select", "CORAL999"],
        ["lint", POOL, "--ignore", ","],
        ["lint", POOL, "--config", "x.toml", "--no-config"],
        ["verify", POOL, "--por", "--max-edges", "-3"],
        ["fmt", POOL, "--check", "--diff"],
        ["query", POOL, "--examination", "Nope"],
        ["query", POOL, "-o", "/no/such/folder/x"],
    ],
)
def test_every_usage_error_returns_2_and_never_raises(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "Traceback" not in err


def test_include_path_is_checked_once_by_its_type(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for command in ("check", "lint", "verify", "export"):
        assert main([command, POOL, "--include-path", str(tmp_path / "nowhere")]) == 2
        err = capsys.readouterr().err
        assert f"argument --include-path: {tmp_path / 'nowhere'}: no such folder" in err


# -- --select / --ignore ----------------------------------------------------------------


def _codes(capsys: pytest.CaptureFixture[str], *argv: str) -> set[str]:
    assert main(["lint", "--format", "json", "--no-config", *argv]) == 0
    data = json.loads(capsys.readouterr().out)
    return {d["code"] for f in data["files"] for d in f["diagnostics"]}


def test_select_and_ignore_take_codes_and_prefixes(capsys: pytest.CaptureFixture[str]) -> None:
    dead = str(FAULTY / "dead_transition.coral")
    assert _codes(capsys, dead) == {"CORAL204", "CORAL205"}
    assert _codes(capsys, dead, "--ignore", "CORAL204") == {"CORAL205"}
    assert _codes(capsys, dead, "--select", "coral204") == {"CORAL204"}
    assert _codes(capsys, dead, "--select", "CORAL2", "--ignore", "CORAL205") == {"CORAL204"}
    assert _codes(capsys, dead, "--ignore", "CORAL204,CORAL205") == set()
    assert _codes(capsys, dead, "--ignore", "CORAL204", "--ignore", "CORAL205") == set()


def test_an_unknown_code_is_named_with_the_known_ones(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", POOL, "--ignore", "CORAL204,CORAL2O4"]) == 2
    err = capsys.readouterr().err
    assert "unknown rule code CORAL2O4 (known: CORAL001" in err and "CORAL209" in err


def test_compile_errors_are_never_ignored(capsys: pytest.CaptureFixture[str]) -> None:
    # 'CORAL' names every lint rule too, so it is accepted; the compile error stays.
    assert main(["lint", UNHANDLED, "--ignore", "CORAL"]) == 1
    assert "[CORAL106]" in capsys.readouterr().out


@pytest.mark.parametrize(
    "option", [["--ignore", "CORAL001"], ["--select", "CORAL0"], ["--ignore", "CORAL1,CORAL204"]]
)
def test_a_selector_of_compile_codes_only_is_refused(
    capsys: pytest.CaptureFixture[str], option: list[str]
) -> None:
    assert main(["lint", UNHANDLED, *option]) == 2
    err = capsys.readouterr().err
    assert "compile errors cannot be selected or ignored" in err
    assert "lint codes: CORAL201" in err and "CORAL209" in err


# -- standard input ---------------------------------------------------------------------


def test_a_dash_reads_the_mission_from_standard_input(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.stdin", io.StringIO(CHAIN))
    assert main(["lint", "-", "--format", "json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["files"][0]["file"] == "<stdin>" and data["files"][0]["status"] == "clean"
    monkeypatch.setattr("sys.stdin", io.StringIO(Path(UNHANDLED).read_text()))
    assert main(["-"]) == 1
    assert "<stdin>:20:20: error:" in capsys.readouterr().out
    assert main(["lint", "-", "-"]) == 2
    assert "'-' (standard input) can be given only once" in capsys.readouterr().err


def test_verify_reads_standard_input_too(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.stdin", io.StringIO(CHAIN))
    assert main(["verify", "-", "--max-states", "3", "--no-structure"]) == 3
    assert "INCONCLUSIVE" in capsys.readouterr().out


# -- verify's JSON is the one document ----------------------------------------------------


def test_verify_json_is_the_one_document_with_command_verify(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["verify", DEADLOCK, "--format", "json", "--no-structure"]) == 1
    captured = capsys.readouterr()
    data = json.loads(captured.out)
    assert data["schema"] == "coral-check" and data["schema_version"] == JSON_SCHEMA_VERSION
    assert data["command"] == "verify" and data["exit_code"] == 1
    (entry,) = data["files"]
    assert entry["file"] == DEADLOCK and entry["status"] == "violated"
    assert entry["report"]["deadlock"]["verdict"] == "violated"
    assert main(["verify", UNHANDLED, "--format", "json"]) == 1
    captured = capsys.readouterr()
    assert "[CORAL106]" in captured.err and "not verified: fix the errors above" in captured.err


def test_verify_of_a_part_names_the_mission_to_verify(capsys: pytest.CaptureFixture[str]) -> None:
    part = str(EXAMPLES / "pool_mission" / "abort.coral")
    assert main(["verify", part]) == 0
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"a part of {POOL}, not verified on its own; verify the mission: " in captured.err
    assert f"coral-check verify {POOL}" in captured.err


# -- review findings: explain, shorthand, parts, outputs over inputs ----------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["lint", "--explain", "CORAL207", POOL],
        ["lint", POOL, "--explain", "CORAL207"],
        ["check", "--explain", "CORAL207", POOL],
        ["verify", POOL, "--explain", "CORAL207"],
    ],
)
def test_explain_with_files_is_a_usage_error(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert "--explain takes no FILE" in captured.err and captured.out == ""


@pytest.mark.parametrize("argv", [["--explain", "CORAL207"], ["verify", "--explain", "CORAL207"]])
def test_explain_alone_prints_the_page(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 0
    assert capsys.readouterr().out.startswith("## CORAL207")


def test_options_before_a_command_name_say_the_right_order(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--no-config", "lint", POOL]) == 2
    err = capsys.readouterr().err
    assert f"options go after the command name: coral-check lint --no-config {POOL}" in err
    assert "cannot read 'lint'" not in err


def test_version_after_a_file_answers_as_at_the_top(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in ([POOL, "--version"], ["lint", "--version"], ["fmt", "--version"]):
        assert main(argv) == 0
        assert re.fullmatch(r"coral-check \(coral \S+\)\n", capsys.readouterr().out)


def test_a_certificate_for_a_part_is_refused_naming_its_mission(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "my mission"
    folder.mkdir()
    (folder / "whole.coral").write_text(
        'mission whole\nvehicle ROMEO\nplace a = 1, b\nfinal {b}\ninclude "step.coral"\n'
    )
    part = folder / "step.coral"
    part.write_text("# coral: part of whole.coral\ntransition t wait {a} signal {b}\n")
    cert = tmp_path / "c.json"
    assert main(["lint", "--no-config", str(part)]) == 0  # a sound part on its own
    capsys.readouterr()
    assert main(["verify", "--no-config", str(part), "--certificate", str(cert)]) == 2
    err = capsys.readouterr().err
    mission = str(folder / "whole.coral")
    assert f"{part} is a part of " in err and "certificates are for whole missions" in err
    assert f"coral-check verify '{mission}' --certificate {cert}" in err
    assert not cert.exists()


def test_the_pool_mission_part_with_a_certificate_is_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    part = str(EXAMPLES / "pool_mission" / "abort.coral")
    cert = tmp_path / "c.json"
    assert main(["verify", part, "--certificate", str(cert)]) == 2
    assert "pool_mission.coral --certificate" in capsys.readouterr().err
    assert not cert.exists()


def test_an_output_over_an_input_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission = tmp_path / "same.coral"
    mission.write_text(CHAIN)
    (tmp_path / "link.coral").symlink_to(mission)
    os.link(mission, tmp_path / "hard.coral")
    for argv in (
        ["verify", str(mission), "-o", str(mission)],
        ["verify", str(mission), "--certificate", str(tmp_path / "link.coral")],
        ["check", str(mission), "-o", str(tmp_path / "hard.coral")],
        ["lint", POOL, str(mission), "--format", "json", "-o", str(mission)],
        ["export", str(mission), "--dot", str(mission)],
        ["export", str(mission), "--pnml", str(tmp_path / "link.coral")],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "is the input file" in err and "refusing to overwrite it" in err, argv
        assert mission.read_text() == CHAIN
    out = tmp_path / "out.txt"
    assert main(["verify", str(mission), "-o", str(out), "--certificate", str(out)]) == 2
    assert "are the same file" in capsys.readouterr().err


@pytest.fixture
def pool_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, bytes]:
    """A copy of the pool mission (its parts and profile) as the current folder; the
    bytes of each file, to show that a refused run wrote nothing."""
    import shutil

    for file in (EXAMPLES / "pool_mission").iterdir():
        if file.is_file():
            shutil.copy(file, tmp_path / file.name)
    monkeypatch.chdir(tmp_path)
    return {file.name: file.read_bytes() for file in tmp_path.iterdir()}


@pytest.mark.parametrize(
    ("argv", "read"),
    [
        (["check", "pool_mission.coral", "-o", "abort.coral"], "'abort.coral', which"),
        (["verify", "pool_mission.coral", "--certificate", "docking.coral"], "'docking.coral'"),
        (
            ["export", "pool_mission.coral", "--dot", "go_to_operating_site.coral"],
            "'go_to_operating_site.coral', which pool_mission.coral reads",
        ),
        (
            [
                "lint",
                "pool_mission.coral",
                "--profile=romeo.yaml",
                "--format=json",
                "-o",
                "romeo.yaml",
            ],
            "the profile 'romeo.yaml'",
        ),
        (["lint", "abort.coral", "-o", "pool_mission.coral"], "'pool_mission.coral', which"),
        (["verify", "pool_mission.coral", "-o", "./waypoint_navigation.coral"], "reads"),
        (["export", "pool_mission.coral", "--pnml", "./abort.coral"], "'abort.coral', which"),
    ],
)
def test_an_output_over_a_file_the_run_reads_is_refused_and_nothing_is_written(
    pool_copy: dict[str, bytes],
    argv: list[str],
    read: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """An include, a part's mission or a profile is known only once the mission is
    compiled (or the settings resolved): refused then, before anything is written."""
    assert main(argv) == 2, argv
    err = capsys.readouterr().err
    assert read in err and "refusing to overwrite it" in err, err
    assert {f.name: f.read_bytes() for f in Path.cwd().iterdir()} == pool_copy


def test_an_output_over_the_config_file_or_the_signing_key_is_refused(
    pool_copy: dict[str, bytes], capsys: pytest.CaptureFixture[str]
) -> None:
    Path("coral.toml").write_text("")  # found from the current folder: read
    assert main(["check", "pool_mission.coral", "-o", "coral.toml"]) == 2
    assert re.search(r"is the configuration file '\S*coral\.toml'", capsys.readouterr().err)
    assert Path("coral.toml").read_text() == ""
    assert main(["keygen", "--out", "key"]) == 0
    capsys.readouterr()
    before = {f.name: f.read_bytes() for f in Path.cwd().iterdir()}
    argv = ["verify", "pool_mission.coral", "--signing-key", "key", "--certificate", "key"]
    assert main(argv) == 2
    assert "the signing key 'key'" in capsys.readouterr().err
    assert {f.name: f.read_bytes() for f in Path.cwd().iterdir()} == before
