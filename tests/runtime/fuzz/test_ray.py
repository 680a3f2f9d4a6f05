"""``coral-run fuzz --ray``: a Ray cluster gives the serial campaign's report, run for run.

One local Ray cluster (2 CPUs) serves the whole module: starting one takes seconds. A
pytest-xdist worker that runs any of these tests starts its own (Ray gives each its own
session folder and ports), so two can run side by side.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import socket
import sys
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import ray

from coral_lang.diagnostics import CoralError
from runtime.controller import RunEnd
from runtime.fuzz import FuzzOptions, FuzzReport, format_report, fuzz, run_one
from runtime.fuzz.on_ray import (
    RAY_EXTRA,
    TEST_DIE_ENV,
    RayError,
    RayTarget,
    ReplayMismatch,
    _keep_failed_logs,
    _result,
    session,
)
from runtime.fuzz.options import RAY_EXTRA_HINT
from runtime.link import BUILTIN_PROFILES
from tests.conftest import session_signing_key
from tests.runtime.fuzz.common import POOL, RACY, cli
from tests.runtime.test_properties import mission
from tests.runtime.test_racy import HOSTILE_RACE_SEED, RACE_MARKINGS

GENOA = BUILTIN_PROFILES["genoa-lisbon"]
SEEDS = 40


@pytest.fixture(scope="module")
def die_file(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A local Ray cluster for the module, started as ``--ray`` starts one; its workers
    read `TEST_DIE_ENV`, which names the returned file (absent: no worker dies)."""
    path = tmp_path_factory.mktemp("ray") / "die.txt"
    before = os.environ.get(TEST_DIE_ENV)
    os.environ[TEST_DIE_ENV] = str(path)  # the cluster's processes inherit it
    try:
        with session(ray, RayTarget(cpus=2)) as started:
            assert started
            yield path
        assert not ray.is_initialized()
    finally:
        if before is None:
            del os.environ[TEST_DIE_ENV]
        else:
            os.environ[TEST_DIE_ENV] = before


@pytest.fixture(scope="module")
def serial() -> FuzzReport:
    """The reference: 40 runs of the pool mission over genoa-lisbon, in this process."""
    pool = mission("pool")
    return fuzz(pool.net, pool.approval, FuzzOptions(runs=SEEDS, seed=0, link=GENOA), workers=1)


def _runs(report: FuzzReport) -> list[tuple[object, ...]]:
    return [
        (r.index, r.seed, r.ending(), r.duration, r.events_digest, dict(r.fired))
        for r in report.runs
    ]


def test_a_local_cluster_gives_the_serial_report(die_file: Path, serial: FuzzReport) -> None:
    pool = mission("pool")
    seen: list[tuple[int, int, int]] = []
    report = fuzz(
        pool.net,
        pool.approval,
        FuzzOptions(runs=SEEDS, seed=0, link=GENOA),
        ray=RayTarget(cpus=2),
        progress=lambda *args: seen.append(args),
    )
    assert _runs(report) == _runs(serial)
    assert report.coverage() == serial.coverage()
    assert _runs(FuzzReport("", "", serial.options, report.failures, 1.0)) == _runs(
        FuzzReport("", "", serial.options, serial.failures, 1.0)
    )
    assert [done for done, _, _ in seen] == list(range(1, SEEDS + 1))
    assert {total for _, total, _ in seen} == {SEEDS}
    assert seen[-1][2] == len(serial.failures)
    assert report.ran_on.startswith("on Ray at ") and "(2 CPUs)" in report.ran_on
    assert report.ran_on in format_report(report, "coral-run fuzz x")
    assert ray.is_initialized()  # a connection the caller made is left as it was


def test_a_worker_killed_mid_campaign_still_yields_every_run_once(
    die_file: Path, serial: FuzzReport
) -> None:
    marker = die_file.with_name("died")
    die_file.write_text(f"5 {marker}", encoding="utf-8")  # run seed 5 kills its worker once
    try:
        pool = mission("pool")
        report = fuzz(
            pool.net, pool.approval, FuzzOptions(runs=8, seed=0, link=GENOA), ray=RayTarget()
        )
    finally:
        die_file.unlink()
    assert marker.exists()  # a worker did die running seed 5
    assert [r.index for r in report.runs] == list(range(8))
    assert _runs(report) == _runs(serial)[:8]
    assert not report.interrupted


def test_ctrl_c_cancels_the_rest_and_keeps_the_runs_done(
    die_file: Path, serial: FuzzReport
) -> None:
    def interrupt_after_two(done: int, total: int, failed: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    pool = mission("pool")
    options = FuzzOptions(runs=SEEDS, seed=0, link=GENOA)
    report = fuzz(pool.net, pool.approval, options, ray=RayTarget(), progress=interrupt_after_two)
    assert report.interrupted and len(report.runs) == 2
    by_index = {run[0]: run for run in _runs(serial)}
    assert all(run == by_index[run[0]] for run in _runs(report))
    assert "(interrupted: 38 runs not done)" in format_report(report, "coral-run fuzz x")


def test_failed_runs_logs_are_kept_on_the_driver_and_the_settings_file_is_shipped(
    die_file: Path, tmp_path: Path, heading_90: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The race needs the vehicle file (facing 90 degrees) on the workers; the failure's
    log is re-created here, from its seed, with the worker's very events."""
    base = ["--unverified", "--link", "hostile", "--vehicle-config", str(heading_90), "-q"]
    out = tmp_path / "out"
    argv = [RACY, *base, "--runs", "3", "--seed", str(HOSTILE_RACE_SEED - 1), "--out", str(out)]
    code, text, err = cli([*argv, "--ray"], capsys)
    assert code == 1, text + err
    assert f"seed {HOSTILE_RACE_SEED}: deadlock" in text and "NOT REPRODUCIBLE" not in text
    log = out / "failures" / f"seed-{HOSTILE_RACE_SEED}.sqlite"
    assert log.exists()
    data = json.loads((out / "fuzz-report.json").read_text())
    failed = next(r for r in data["runs"] if r["seed"] == HOSTILE_RACE_SEED)
    assert failed["marking"] in RACE_MARKINGS and failed["log"] == str(log)
    assert data["nondeterministic"] == [] and data["ran_on"].startswith("on Ray at ")
    code, _, _ = cli([*argv, "--out", str(tmp_path / "local"), "--workers", "1"], capsys)
    assert code == 1
    local = json.loads((tmp_path / "local" / "fuzz-report.json").read_text())
    assert [r["events_digest"] for r in local["runs"]] == [r["events_digest"] for r in data["runs"]]


def test_a_re_run_that_differs_is_reported_loudly(tmp_path: Path) -> None:
    racy = mission("racy")
    options = FuzzOptions(runs=1, seed=0, link=BUILTIN_PROFILES["ideal"])
    run = run_one(racy.net, racy.approval, 0, options)
    odd = dataclasses.replace(run, end=RunEnd.DEADLOCK, events_digest="sha256:worker")
    runs = [odd]
    found = _keep_failed_logs(racy.net, racy.approval, options, runs, tmp_path)
    assert found == [ReplayMismatch(0, "sha256:worker", run.events_digest)]
    assert runs[0].log == tmp_path / "seed-0.sqlite" and runs[0].log.exists()
    report = FuzzReport("racy_mission", RACY, options, runs, 1.0, mismatches=found)
    text = format_report(report, "coral-run fuzz x")
    assert "NOT REPRODUCIBLE (1)" in text and "sha256:worker on the worker" in text
    assert report.to_json()["nondeterministic"] == [
        {
            "seed": 0,
            "worker_events_digest": "sha256:worker",
            "driver_events_digest": run.events_digest,
        }
    ]


def test_the_command_runs_on_ray(
    die_file: Path, tmp_path: Path, pool_certificate: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    trust = ["--certificate", str(pool_certificate)]
    trust += ["--trusted-keys", str(session_signing_key().public)]
    code, out, err = cli([POOL, *trust, "--runs", "4", "--out", str(tmp_path), "--ray"], capsys)
    assert code == 0, out + err
    assert "reached a declared final marking: 4/4 (100.0 %)" in out
    assert "schedules/s, on Ray at " in out
    assert json.loads((tmp_path / "fuzz-report.json").read_text())["seed"] == 0

    code, out, err = cli([POOL, *trust, "--replay", "2", "--out", str(tmp_path), "--ray"], capsys)
    assert code == 0, out + err
    assert "replay of run seed 2:" in out and "--replay runs here, not on Ray" in err


def test_without_ray_installed_ray_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as when not installed
    code, out, err = cli([RACY, "--unverified", "--out", str(tmp_path), "--ray"], capsys)
    assert code == 2 and out == ""
    assert RAY_EXTRA in err and "Traceback" not in err
    assert RAY_EXTRA_HINT == RAY_EXTRA  # the help text says the same
    assert not (tmp_path / "fuzz-report.json").exists()


def test_workers_size_only_a_local_cluster(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [RACY, "--unverified", "--out", str(tmp_path), "--workers", "2", "--ray", "h:6379"]
    code, _, err = cli(argv, capsys)
    assert code == 2 and "--workers sizes a local Ray cluster" in err
    racy = mission("racy")
    options = FuzzOptions(runs=2, seed=0, link=GENOA)
    with pytest.raises(ValueError, match="workers or ray, not both"):
        fuzz(racy.net, racy.approval, options, workers=2, ray=RayTarget())


class _FakeRay(SimpleNamespace):
    """What `session` asks of Ray, recorded."""

    def __init__(self, connected: bool, refuse: bool = False) -> None:
        super().__init__(calls=[], connected=connected, refuse=refuse)

    def is_initialized(self) -> bool:
        return bool(self.connected)

    def init(self, **kwargs: Any) -> None:
        self.calls.append(("init", kwargs.get("address"), kwargs.get("num_cpus")))
        if self.refuse:
            raise ConnectionError("no cluster there")

    def shutdown(self) -> None:
        self.calls.append(("shutdown", None, None))


@pytest.fixture
def head() -> Iterator[str]:
    """``HOST:PORT`` where something listens, as a cluster's head would."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        yield f"127.0.0.1:{server.getsockname()[1]}"


@pytest.mark.parametrize(
    ("at", "connected", "started", "calls"),
    [
        (None, False, True, [("init", "local", 3), ("shutdown", None, None)]),
        ("head", False, False, [("init", "head", None), ("shutdown", None, None)]),
        ("head", True, False, []),
        (None, True, False, []),
    ],
)
def test_a_session_shuts_down_only_what_it_started_or_connected(
    at: str | None,
    connected: bool,
    started: bool,
    calls: list[tuple[object, ...]],
    head: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A cluster at an address is only disconnected from (Ray's shutdown in a driver that
    connected stops nothing of the cluster); a caller's own connection is left alone."""
    monkeypatch.delenv("RAY_USAGE_STATS_ENABLED", raising=False)
    fake = _FakeRay(connected)
    target = RayTarget(cpus=3) if at is None else RayTarget(head)
    with session(fake, target) as ours:  # type: ignore[arg-type]
        assert ours is started
    assert fake.calls == [(c, head if a == "head" else a, n) for c, a, n in calls]
    if not connected:
        assert os.environ["RAY_USAGE_STATS_ENABLED"] == "0"


def test_an_unreachable_cluster_is_a_clear_error_at_once() -> None:
    """Ray would retry for minutes; nothing listening at the address is said at once."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        closed = f"127.0.0.1:{server.getsockname()[1]}"
    for address, message in [
        (closed, f"cannot connect to the Ray cluster at {closed}: "),
        ("head-without-port", "give the cluster's head as HOST:PORT, or 'auto'"),
    ]:
        fake = _FakeRay(connected=False)
        with (
            pytest.raises(RayError, match=re.escape(message)),
            session(fake, RayTarget(address)),  # type: ignore[arg-type]
        ):
            pass
        assert fake.calls == []


def test_a_refused_connection_is_a_clear_error(head: str) -> None:
    fake = _FakeRay(connected=False, refuse=True)
    with (
        pytest.raises(RayError, match=f"cannot connect to the Ray cluster at {head}: no cluster"),
        session(fake, RayTarget(head)),  # type: ignore[arg-type]
    ):
        pass
    assert fake.calls == [("init", head, None)]


TASK_ERROR = ray.exceptions.RayTaskError("_run_task", "tb", CoralError("no sim"))  # type: ignore[no-untyped-call]
IMPORT_ERROR = ray.exceptions.RayTaskError("_run_task", "tb", ImportError("no runtime"))  # type: ignore[no-untyped-call]


@pytest.mark.parametrize(
    ("raised", "expected", "message"),
    [
        # A run's own error on a worker, bad input there too (e.g. a simulator the worker
        # lacks): as it was raised, for the command's one-line error.
        (TASK_ERROR, CoralError, "no sim"),
        # A worker without coral: what to install there.
        (IMPORT_ERROR, RayError, "a Ray worker cannot run coral (no runtime): every machine"),
        # A run whose worker died more often than Ray retries: named, with its seed.
        (
            ray.exceptions.WorkerCrashedError(),
            RayError,
            "Ray could not run run 7 (run seed 12; a worker that dies is retried 3 times)",
        ),
    ],
)
def test_a_task_error_says_what_it_is(
    raised: Exception, expected: type[Exception], message: str
) -> None:
    def get(ref: object) -> None:
        raise raised

    fake = SimpleNamespace(get=get, exceptions=ray.exceptions)
    with pytest.raises(expected, match=re.escape(message)) as caught:
        _result(fake, object(), 12, 7)  # type: ignore[arg-type]
    assert not isinstance(caught.value, ray.exceptions.RayError)
