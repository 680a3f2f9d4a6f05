"""The live operations page in a real browser, during a real-time simulated run.

What the issue asks of it, end to end through ``coral-run``'s own command line:

* headless Chromium loads the page while the mission runs and sees the marking, a
  command's status and the telemetry change;
* an operator abort given from the page (its button, with the operate token) ends the
  mission through the mission's abort path, in a declared final marking, logged with
  the page as its origin;
* a viewer without the token is refused when the server is bound off loopback, and a
  view-only page shows no operator controls.

The browser needs Chromium (``.ci/run`` installs it): skipped on a developer's machine
without it, a failure under CI.
"""

from __future__ import annotations

import asyncio
import re
import shutil
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from runtime.eventlog import EventLog
from tests.conftest import EXAMPLES
from tests.runtime.watch.cdp import Browser, open_browser

CORAL_RUN = [sys.executable, "-m", "runtime.cli"]
URL = re.compile(r"(http://\S+)")


class LiveRun:
    """``coral-run MISSION --realtime --watch ...`` in a subprocess, its output read by a
    thread so the test can wait for a line while the run goes on."""

    def __init__(self, args: list[str]) -> None:
        self.process = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=Path(__file__).resolve().parents[3],
        )
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    def line_with(self, text: str, timeout: float = 60.0) -> str:
        """The first output line holding ``text``, waiting for it."""
        with self._changed:
            found = self._changed.wait_for(
                lambda: any(text in line for line in self.lines) or self.process.poll() is not None,
                timeout=timeout,
            )
            for line in self.lines:
                if text in line:
                    return line
        output = "\n".join(self.lines)
        raise AssertionError(f"no line with {text!r} (found={found}); output:\n{output}")

    def wait(self, timeout: float = 120.0) -> int:
        code = self.process.wait(timeout=timeout)
        self._reader.join(timeout=5)
        return code

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


@pytest.fixture
def abort_mission(tmp_path: Path) -> Path:
    """The operator example, copied so ``--verify`` writes its certificate in tmp."""
    folder = tmp_path / "mission"
    shutil.copytree(EXAMPLES / "operator", folder)
    return folder / "abort.coral"


@pytest.fixture
def live_run(abort_mission: Path, tmp_path: Path) -> Iterator[tuple[LiveRun, Path]]:
    out = tmp_path / "run"
    run = LiveRun(
        [
            *CORAL_RUN,
            str(abort_mission),
            "--verify",
            "--realtime",
            "--speed",
            "4",
            "--link",
            "lan",
            "--seed",
            "3",
            "--watch",
            "127.0.0.1:0",
            "--out",
            str(out),
            "--no-plots",
        ]
    )
    try:
        yield run, out
    finally:
        run.stop()


async def _text(browser: Browser, selector: str) -> str:
    value = await browser.evaluate(
        f"(document.querySelector({selector!r}) || {{textContent: ''}}).textContent"
    )
    return str(value)


@pytest.mark.slow
def test_page_follows_a_live_run_and_aborts_it(
    chromium: str, live_run: tuple[LiveRun, Path], tmp_path: Path
) -> None:
    run, out = live_run
    operate_line = run.line_with("watch: operate it at")
    operate_url = URL.findall(operate_line)[0]
    assert "token=" in operate_url

    async def drive() -> None:
        async with open_browser(chromium, tmp_path / "profile") as browser:
            await browser.goto(operate_url)
            await browser.wait_for("document.querySelector('#marking tr') !== null")
            first_marking = await _text(browser, "#marking")
            # The marking, a command's status and the telemetry change as the run goes.
            await browser.wait_for(
                f"document.querySelector('#marking').textContent !== {first_marking!r}"
            )
            await browser.wait_for("document.querySelector('#commands tr') !== null")
            first_telemetry = await browser.wait_for(
                "(() => { const t = document.querySelector('#telemetry').textContent;"
                " return /[0-9]/.test(t) ? t : ''; })()"
            )
            await browser.wait_for(
                f"document.querySelector('#telemetry').textContent !== {first_telemetry!r}"
            )
            commands = await _text(browser, "#commands")
            assert "DEPTH" in commands or "INIT" in commands, commands
            # The operator panel is there (operate token) and aborts the mission.
            button = "#operator button[data-action=give][data-input=abort_requested]"
            await browser.wait_for(f"document.querySelector({button!r}) !== null")
            await browser.evaluate("window.confirm = () => true; true")
            await browser.evaluate(f"document.querySelector({button!r}).click(); true")
            end = await browser.wait_for(
                "(() => { const e = document.querySelector('#end').textContent;"
                " return e.length ? e : ''; })()",
                timeout=90,
            )
            assert "final" in end, end

    asyncio.run(drive())
    assert run.wait() == 0, "\n".join(run.lines)
    with EventLog.open(out / "controller.sqlite") as log:
        operator = [e for e in log.events(["operator"])]
        end = [e for e in log.events(["mission-end"])]
    assert [e.data["action"] for e in operator if e.data["accepted"]] == ["give"]
    assert operator[0].data["input"] == "abort_requested"
    assert str(operator[0].data["origin"]).startswith("page 127.0.0.1:")
    assert end[-1].data["end"] == "final"
    assert end[-1].data["marking"] == {"aborted": 1}, end[-1].data


@pytest.mark.slow
def test_viewer_without_the_token_is_refused(
    chromium: str, abort_mission: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    run = LiveRun(
        [
            *CORAL_RUN,
            str(abort_mission),
            "--verify",
            "--realtime",
            "--speed",
            "2",
            "--watch",
            "127.0.0.2:0",
            "--out",
            str(out),
            "--no-plots",
        ]
    )
    try:
        view_line = run.line_with("watch: view the mission at")
        view_url = URL.findall(view_line)[0]
        assert "token=" in view_url
        bare = view_url.split("?")[0]
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(bare + "snapshot", timeout=10)
        assert refused.value.code == 401

        async def drive() -> None:
            async with open_browser(chromium, tmp_path / "profile") as browser:
                await browser.goto(bare)
                body = await browser.wait_for("document.body && document.body.textContent")
                assert "mission" not in str(body).lower() or "401" in str(body), body
                # The view token shows the mission but no operator controls.
                await browser.goto(view_url)
                await browser.wait_for("document.querySelector('#marking tr') !== null")
                shown = await browser.evaluate(
                    "(() => { const p = document.querySelector('#operator');"
                    " return !!p && !p.hidden && p.offsetParent !== null; })()"
                )
                assert shown is False

        asyncio.run(drive())
    finally:
        run.stop()
