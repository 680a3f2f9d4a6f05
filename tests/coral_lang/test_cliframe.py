"""The command-line frame every coral command is built on (coral_lang/cliframe.py)."""

from __future__ import annotations

import argparse
import math
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from coral_lang import cliframe
from coral_lang.cliframe import (
    EXIT_OK,
    EXIT_USAGE,
    command_parser,
    host_port,
    positive_float,
    positive_int,
    run_main,
    subcommands,
)


def _parser() -> argparse.ArgumentParser:
    parser = command_parser("tool", "A tool.")
    commands = subcommands(parser)
    check = commands.add_parser("check")
    check.add_argument("files", nargs="+")
    check.add_argument("--fast", action="store_true")
    check.add_argument("--limit", type=positive_int, default=1)
    check.add_argument("-o", "--out")
    check.add_argument("--tags", nargs="*", default=[])
    check.add_argument("--level", nargs="?", const="all")
    commands.add_parser("lint").add_argument("files", nargs="+")
    return parser


def _run(argv: list[str]) -> tuple[int, argparse.Namespace | None]:
    seen: list[argparse.Namespace] = []

    def dispatch(args: argparse.Namespace) -> int:
        seen.append(args)
        return 7

    code = run_main(_parser(), argv, dispatch, default_command="check")
    return code, (seen[0] if seen else None)


def test_the_usage_line_lists_the_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["--help"]) == (EXIT_OK, None)
    assert "usage: tool [-h] [--version] {check,lint} ..." in capsys.readouterr().out


def test_version_names_the_program_and_coral(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["--version"]) == (EXIT_OK, None)
    assert capsys.readouterr().out.startswith(f"tool (coral {cliframe.tool_version()})")


def test_a_first_argument_naming_no_command_means_the_default_one() -> None:
    code, args = _run(["a.coral", "--fast"])
    assert code == 7 and args is not None
    assert (args.command, args.files, args.fast) == ("check", ["a.coral"], True)
    code, args = _run(["--fast", "a.coral"])
    assert code == 7 and args is not None and args.command == "check"
    code, args = _run(["lint", "a.coral"])
    assert code == 7 and args is not None and args.command == "lint"


@pytest.mark.parametrize(
    "argv",
    [["check"], ["--limit", "0", "a.coral"], ["lint"], ["--bogus", "a"], ["check", "--limit", "x"]],
)
def test_usage_errors_return_2_and_never_raise(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run(argv) == (EXIT_USAGE, None)
    assert "tool" in capsys.readouterr().err


def test_options_before_a_command_name_are_refused_with_the_right_order(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert _run(["--fast", "lint", "a.coral"]) == (EXIT_USAGE, None)
    err = capsys.readouterr().err
    assert "options go after the command name: tool lint --fast a.coral" in err
    # after "--" a name is a file
    code, args = _run(["--fast", "--", "lint"])
    assert code == 7 and args is not None and args.files == ["lint"]


@pytest.mark.parametrize(
    "argv",
    [
        ["--out", "lint", "a.coral"],
        ["-o", "lint", "a.coral"],
        ["--fast", "--out", "lint", "a.coral"],
        ["--ou", "lint", "a.coral"],  # an abbreviation argparse accepts
        ["--out=lint", "a.coral"],
        ["-olint", "a.coral"],
        ["--level", "lint", "a.coral"],
    ],
)
def test_an_option_s_value_naming_a_command_is_a_value(argv: list[str]) -> None:
    code, args = _run(argv)
    assert code == 7 and args is not None, argv
    assert args.command == "check" and args.files == ["a.coral"], argv
    assert "lint" in (args.out, args.level), argv


@pytest.mark.parametrize(
    ("argv", "fixed"),
    [
        (["--out", "x", "lint", "a.coral"], "tool lint --out x a.coral"),
        (["--level", "--fast", "lint", "a.coral"], "tool lint --level --fast a.coral"),
        (["--tags", "--out=x", "lint", "a"], "tool lint --tags --out=x a"),
    ],
)
def test_a_command_name_after_options_and_their_values_is_refused(
    argv: list[str], fixed: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run(argv) == (EXIT_USAGE, None)
    assert f"options go after the command name: {fixed}" in capsys.readouterr().err


def test_only_the_first_positional_can_be_a_command() -> None:
    """``tool --fast a.coral lint``: the first file decides; ``lint`` is a second file."""
    code, args = _run(["--fast", "a.coral", "lint"])
    assert code == 7 and args is not None and args.files == ["a.coral", "lint"]
    code, args = _run(["--tags", "t1", "t2", "--fast", "a.coral"])
    assert code == 7 and args is not None and args.tags == ["t1", "t2"]


def test_a_reader_that_goes_away_is_exit_2_not_a_traceback(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def dispatch(args: argparse.Namespace) -> int:
        raise BrokenPipeError

    dup2: list[int] = []
    monkeypatch.setattr("os.dup2", lambda fd, target: dup2.append(target))
    monkeypatch.setattr(sys.stdout, "fileno", lambda: 1, raising=False)
    assert run_main(_parser(), ["a.coral"], dispatch, default_command="check") == EXIT_USAGE
    assert dup2 == [1]


@given(st.integers())
def test_positive_int_takes_exactly_the_whole_numbers_from_1(value: int) -> None:
    if value >= 1:
        assert positive_int(str(value)) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError):
            positive_int(str(value))


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_positive_float_refuses_zero_negatives_nan_and_infinity(value: float) -> None:
    if math.isfinite(value) and value > 0:
        assert positive_float(repr(value)) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError):
            positive_float(repr(value))


@pytest.mark.parametrize(
    ("text", "default", "expected"),
    [
        ("localhost:8080", None, ("localhost", 8080)),
        ("[::1]:9", None, ("::1", 9)),
        ("8765", "127.0.0.1", ("127.0.0.1", 8765)),
        ("host:65535", None, ("host", 65535)),
    ],
)
def test_host_port_reads_host_and_port(
    text: str, default: str | None, expected: tuple[str, int]
) -> None:
    assert host_port(text, default_host=default) == expected


@pytest.mark.parametrize("text", ["8080", "host:", ":80", "host:0", "host:65536", "host:８０"])
def test_host_port_refuses_what_is_not_one(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected HOST:PORT"):
        host_port(text)
