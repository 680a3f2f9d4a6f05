"""``romeo-sim serve``: its own event log (``--log``), and the key rules of runtime/keys.py."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from romeo_sim.cli import main
from runtime.eventlog import EventLog, log_key
from runtime.keys import write_key_file
from tests.romeo_sim.test_server import PSK, Controller, within

ROMEO_SIM = Path(sys.executable).parent / "romeo-sim"


@pytest.fixture
def key(tmp_path: Path) -> Path:
    path = tmp_path / "psk.hex"
    write_key_file(path, PSK)
    return path


def test_an_existing_log_file_is_refused_and_kept(
    tmp_path: Path, key: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    existing = tmp_path / "vehicle.sqlite"
    existing.write_bytes(b"an earlier run")
    code = main(["serve", "--key-file", str(key), "--duration", "0", "--log", str(existing)])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{existing}: already exists" in err and "never overwritten" in err
    assert existing.read_bytes() == b"an earlier run"


def test_a_log_in_a_missing_folder_is_refused(
    tmp_path: Path, key: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    where = tmp_path / "nowhere" / "vehicle.sqlite"
    assert main(["serve", "--key-file", str(key), "--log", str(where)]) == 2
    assert "no such folder" in capsys.readouterr().err


@pytest.mark.skipif(os.name != "posix", reason="file modes are POSIX")
def test_a_key_file_others_can_read_is_refused(
    key: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key.chmod(0o644)
    assert main(["serve", "--key-file", str(key), "--duration", "0"]) == 2
    assert f"fix with 'chmod 600 {key}'" in capsys.readouterr().err


def test_help_says_to_prefer_the_key_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "prefer --key-file" in out and "--log FILE" in out


def test_the_usage_line_lists_the_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: romeo-sim [-h] [--version] {mission,serve}")
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("romeo-sim (coral ")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--bogus"], "error:"),  # argparse's SystemExit escaped main before the frame
        ([], "the following arguments are required: command"),
        (["mission", "--bogus"], "unrecognized arguments: --bogus"),
        (["mission", "--seed", "-1"], "a seed is 0 .. 2**63-1, got -1"),  # numpy's refusal
        (["serve", "--port", "x"], "expected a port in 0..65535, got 'x'"),
        (["serve", "--port", "65536"], "expected a port in 0..65535"),
        (["serve", "--speed", "0"], "argument --speed: must be more than 0"),
        (["serve", "--speed", "inf"], "not a finite number: 'inf'"),
        (["serve", "--duration", "-0.5"], "argument --duration: must be 0 or more"),
        (["serve", "--key-hex", "00", "--key-file", "k"], "not allowed with argument"),
    ],
)
def test_misuse_returns_2_with_a_message(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2  # returned, never raised
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_an_out_folder_that_cannot_be_made_is_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert main(["mission", "--out", str(blocker / "sub"), "--no-plots"]) == 2
    assert f"romeo-sim: cannot write to {blocker / 'sub'}" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_serve_writes_its_log_named_after_the_mission_id(
    tmp_path: Path, key: Path, stop: signal.Signals
) -> None:
    """A real ``romeo-sim serve --log``: nothing is written until a controller is adopted;
    then the log's mission is its wire mission id, and the command is recorded. SIGTERM
    (systemd, ``kill``) stops it as Ctrl-C does, the log committed and closed (the review
    found it died with the last events unwritten)."""
    path = tmp_path / "vehicle.sqlite"
    vehicle = subprocess.Popen(
        [
            *(str(ROMEO_SIM), "serve", "--key-file", str(key), "--speed", "20"),
            *("--duration", "20", "--log", str(path)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert vehicle.stdout is not None
        line = vehicle.stdout.readline()
        assert line.startswith("listening on 127.0.0.1:"), line
        assert not path.exists()

        async def mission() -> None:
            ctl = await Controller.connect(int(line.rsplit(":", 1)[1]), nonce=b"m" * 16)
            await ctl.command(1, "DEPTH", z=1.0)
            await ctl.reply(1, "ack")
            await ctl.close()

        asyncio.run(within(mission(), 10.0))
    finally:
        vehicle.send_signal(stop)
        _, err = vehicle.communicate(timeout=15)
    assert vehicle.returncode == 0, err
    assert ("stopped (SIGTERM)" if stop is signal.SIGTERM else "stopped (Ctrl-C)") in err
    with EventLog.open(path, mac_key=log_key(PSK)) as log:  # authenticated under the key
        assert (log.role, log.mission) == ("vehicle", "7")
        assert log.meta["mission_id"] == 7 and log.meta["speed"] == 20.0
        assert log.meta["vehicle"] == "ROMEO"
        kinds = [event.kind for event in log.events()]
    assert kinds[:2] == ["adopt", "command-received"] and "reply-issued" in kinds
