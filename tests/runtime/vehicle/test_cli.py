"""``coral-vehicle`` on the one CLI frame: ``list`` and ``serve`` in the usage line,
``--version``, and misuse answered with exit 2, returned from `main`, never raised."""

from __future__ import annotations

from pathlib import Path

import pytest

from runtime.vehicle.cli import build_parser, main


def test_the_usage_line_lists_the_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: coral-vehicle [-h] [--version] {list,serve}")
    assert build_parser().prog == "coral-vehicle"


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("coral-vehicle (coral ")


def test_list_names_the_registered_simulators(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list"]) == 0
    names = {line.split()[0] for line in capsys.readouterr().out.splitlines()}
    assert {"generic", "romeo"} <= names


SERVE = ["serve", "--vehicle", "ROMEO"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "the following arguments are required: command"),
        (["--bogus"], "error:"),
        (["serve"], "one of the arguments --profile --vehicle is required"),
        ([*SERVE, "--port", "70000"], "expected a port in 0..65535, got '70000'"),
        ([*SERVE, "--port", "-1"], "expected a port in 0..65535"),
        ([*SERVE, "--speed", "0"], "argument --speed: must be more than 0"),
        ([*SERVE, "--speed", "nan"], "not a finite number: 'nan'"),
        ([*SERVE, "--duration", "-1"], "argument --duration: must be 0 or more"),
        ([*SERVE, "--seed", "-5"], "a seed is 0 .. 2**63-1"),
        ([*SERVE, "--key-hex", "00", "--key-file", "k"], "not allowed with argument"),
        ([*SERVE, "--profile", "p.yaml"], "not allowed with argument"),
        (["list", "extra"], "unrecognized arguments: extra"),
    ],
)
def test_misuse_returns_2_with_a_message(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_bad_fault_rule_is_bad_input(capsys: pytest.CaptureFixture[str]) -> None:
    """Read after parsing, before serving: exit 2 naming the option, nothing listens."""
    argv = [*SERVE, "--key-hex", "0123456789abcdef" * 2, "--fault", "DEPTH=nonsense"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("coral-vehicle: --fault") and "listening" not in err


def test_a_log_that_cannot_take_its_last_commit_is_one_line(tmp_path: Path) -> None:
    """Closing the vehicle's log after serving can fail (a full disk): a message and
    exit 2, never a traceback out of ``serve``."""
    from runtime.eventlog import EventLogError
    from runtime.vehicle.cli import VehicleLogFile, _close_log

    class FullDisk(VehicleLogFile):
        def close(self) -> None:
            raise EventLogError(f"{self.path}: cannot commit to the log: disk full")

    lines: list[str] = []
    assert not _close_log(FullDisk(tmp_path / "v.sqlite", {}), lines.append)
    assert lines == [
        f"the vehicle log was not closed cleanly: {tmp_path / 'v.sqlite'}: "
        "cannot commit to the log: disk full"
    ]
    assert _close_log(VehicleLogFile(tmp_path / "w.sqlite", {}), lines.append)  # never opened
