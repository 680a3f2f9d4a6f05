"""``coral-run`` on the one CLI frame: subcommands in the usage line, ``--version``, and
every misuse answered with exit 2 and a message, returned from `main`, never raised.

Each bad argument list below fails before anything runs (argparse's checks, or the checks
across options of ``run``), so these tests are fast and touch no file or socket beyond
binding one for ``--telemetry-host``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.cliframe import run_main
from runtime.cli import build_parser, build_run_parser, main

COMMANDS = ("run", "fuzz", "watch", "timeline", "operate")


def test_the_usage_line_lists_the_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    usage = capsys.readouterr().out.splitlines()[0]
    assert usage.startswith("usage: coral-run")
    assert "{" + ",".join(COMMANDS) + "}" in usage


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("coral-run (coral ")


@pytest.mark.parametrize("command", COMMANDS)
def test_each_subcommand_has_its_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([command, "--help"]) == 0
    assert capsys.readouterr().out.startswith(f"usage: coral-run {command} ")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--bogus"], "unrecognized arguments: --bogus"),
        (["m.coral", "--vehicle", "nowhere"], "expected HOST:PORT, got 'nowhere'"),
        (["m.coral", "--vehicle", "h:70000"], "expected HOST:PORT"),
        (["m.coral", "--speed", "0", "--realtime"], "argument --speed: must be more than 0"),
        (["m.coral", "--speed", "fast"], "argument --speed: not a number: 'fast'"),
        (["m.coral", "--time-limit", "inf"], "not a finite number: 'inf'"),
        (["m.coral", "--seed", "-1"], "a seed is 0 .. 2**63-1, got -1"),
        (["m.coral", "--seed", "x"], "not a whole number: 'x'"),
        (["m.coral", "--include-path", "/no/such/folder"], "/no/such/folder: no such folder"),
        (["m.coral", "--key-hex", "00", "--key-file", "k"], "not allowed with argument"),
        (["m.coral", "--vehicle", "h:1", "--sim"], "not allowed with argument"),
        (["m.coral", "--telemetry-host", "vehicle-lan"], "expected an IP address"),
        (["m.coral", "--watch", "host:"], "[HOST:]PORT"),
        (["--out", "o"], "give a MISSION to run, or --resume LOG"),
        (["m.coral", "--speed", "2"], "--speed applies to a simulator in real time"),
        (["m.coral", "--vehicle", "h:1", "--realtime"], "a --vehicle always runs in real time"),
        (["m.coral", "--vehicle", "h:1", "--fault", "A=error"], "shape a simulated vehicle"),
        (["m.coral", "--tui"], "--tui needs a run in real time"),
        (["m.coral", "--watch", "0"], "--watch needs a run in real time"),
        (["run"], "give a MISSION to run, or --resume LOG"),
        (["timeline"], "the following arguments are required: LOG"),
        (["watch"], "the following arguments are required: LOG"),
        (["watch", "log.sqlite", "--watch", "70000"], "[HOST:]PORT"),
        (["watch", "log.sqlite", "--watch", "0", "--tui"], "not allowed with argument"),
        (["operate", "9", "stop"], "invalid choice: 'stop'"),
        (["operate", "9", "give"], "coral-run operate: error: give needs the NAME of an input"),
        (["operate", "9", "pause", "now"], "coral-run operate: error: pause takes no NAME"),
        (["operate", "0", "pause"], "expected [HOST:]PORT, got '0'"),
        (["operate", "h:x", "pause"], "expected [HOST:]PORT"),
        (["fuzz"], "the following arguments are required: MISSION"),
        (["fuzz", "m.coral", "--runs", "0"], "--runs"),
        (["fuzz", "m.coral", "--vehicle", "10.0.0.1:5000"], "unrecognized arguments"),
    ],
)
def test_misuse_returns_2_with_a_message(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2  # returned: a SystemExit would fail this test
    err = capsys.readouterr().err
    assert message in err
    assert "error:" in err and "Traceback" not in err


def test_no_arguments_say_what_to_give(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: coral-run [-h] [--version] {run,")
    assert "coral-run: error: give a MISSION to run, or --resume LOG" in err
    assert "required: command" not in err


def test_the_shorthand_is_the_run_command() -> None:
    """``coral-run MISSION`` and ``coral-run --resume LOG`` parse as ``coral-run run``."""
    parsed: list[argparse.Namespace] = []

    def keep(args: argparse.Namespace) -> int:
        parsed.append(args)
        return 0

    for argv in (["m.coral", "--seed", "3"], ["run", "m.coral", "--seed", "3"]):
        assert run_main(build_parser(), argv, keep, default_command="run") == 0
    assert run_main(build_parser(), ["--resume", "c.sqlite"], keep, default_command="run") == 0
    first, second, resume = parsed
    assert vars(first) == vars(second)
    assert (first.command, first.mission, first.seed) == ("run", "m.coral", 3)
    assert (resume.command, resume.resume) == ("run", Path("c.sqlite"))
    assert build_run_parser().epilog == build_parser().epilog  # one text of the exit codes


@pytest.mark.parametrize("value", ["run", "timeline", "fuzz"])
def test_an_option_value_naming_a_command_is_a_value_in_the_shorthand(value: str) -> None:
    """``coral-run --sim --out run m.coral``: ``run`` is the output folder, not a
    misplaced command (the options are read with the run command's option table)."""
    parsed: list[argparse.Namespace] = []

    def keep(args: argparse.Namespace) -> int:
        parsed.append(args)
        return 0

    argv = ["--sim", "--out", value, "m.coral"]
    assert run_main(build_parser(), argv, keep, default_command="run") == 0
    (args,) = parsed
    assert (args.command, args.mission, args.out) == ("run", "m.coral", Path(value))


def test_a_command_after_run_options_is_still_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--sim", "--out", "x", "timeline", "log.jsonl"]) == 2
    assert "options go after the command name: coral-run timeline" in capsys.readouterr().err


FLAGS = ["--seed", "--speed", "--time-limit", "--vehicle", "--watch", "--out", "--link", "-q"]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.sampled_from([*COMMANDS, *FLAGS, "--help", "--version", "m.coral"]),
            st.text(alphabet="0123456789-:.abh[]", max_size=6),
        ),
        max_size=5,
    )
)
def test_parsing_any_arguments_never_raises(argv: Sequence[str]) -> None:
    """Whatever the arguments, parsing them ends in exit 0 (help, version, or a command
    that parsed) or 2 (bad usage): no exception escapes the frame."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = run_main(build_parser(), argv, lambda args: 0, default_command="run")
    assert code in (0, 2)


def test_listing_the_subcommands_loads_no_campaign_nor_engine() -> None:
    """``coral-run --help`` (and every subcommand's start) must not pay for fuzzing: the
    fuzz parser comes from `runtime.fuzz.options`, which imports no part of a campaign."""
    import subprocess
    import sys

    probe = (
        "import sys, runtime.cli; runtime.cli.build_parser(); "
        "print(sorted(m for m in ('runtime.engine', 'runtime.fuzz.one_run', "
        "'analysis.certificate', 'numpy') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
