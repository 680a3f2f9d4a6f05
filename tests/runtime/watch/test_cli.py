"""``coral-run watch``: bad input exits 2 with a message, Ctrl-C ends it with 0."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from runtime.cli import main as coral_run
from runtime.eventlog import EventLog
from runtime.watch.main import parse_address
from tests.conftest import REPO


def test_a_missing_or_foreign_log_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert coral_run(["watch", str(tmp_path / "nothing.sqlite")]) == 2
    assert "nothing.sqlite: no such event log" in capsys.readouterr().err
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    assert coral_run(["watch", str(text)]) == 2
    assert "not a SQLite database" in capsys.readouterr().err
    vehicle = tmp_path / "vehicle.sqlite"
    EventLog.create(vehicle, role="vehicle", mission="1", meta={}).close()
    assert coral_run(["watch", str(vehicle)]) == 2
    assert "a vehicle log; watch the controller's log" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["host:", "host:x", "70000", "h:-1", ""])
def test_a_bad_address_is_bad_usage(bad: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert coral_run(["watch", "log.sqlite", "--watch", bad]) == 2
    assert "[HOST:]PORT" in capsys.readouterr().err


def test_addresses() -> None:
    assert parse_address("0") == ("127.0.0.1", 0)
    assert parse_address("9000") == ("127.0.0.1", 9000)
    assert parse_address("0.0.0.0:80") == ("0.0.0.0", 80)
    assert parse_address("[::1]:8765") == ("::1", 8765)


@pytest.mark.slow
def test_a_taken_port_exits_2(pool_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert coral_run(["watch", str(pool_log), "--watch", str(port)]) == 2
    assert "cannot listen on 127.0.0.1" in capsys.readouterr().err


@pytest.mark.slow
def test_serves_until_ctrl_c_then_exits_0(pool_log: Path) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "runtime.cli", "watch", str(pool_log), "--watch", "0"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        match = re.search(r"\(replay\) at (http://127\.0\.0\.1:\d+/)$", line.strip())
        assert match, line
        with urllib.request.urlopen(f"{match.group(1)}health", timeout=5) as reply:
            assert json.load(reply)["live"] is False
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=10) == 0
        assert process.stderr is not None
        assert "Traceback" not in process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
