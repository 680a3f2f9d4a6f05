"""A fuzz campaign on a Ray cluster: ``coral-run fuzz --ray [ADDRESS]``.

Why Ray: the issue asks for campaigns beyond one machine, and Ray retries a task whose
worker process dies. Each run is one task keyed by its index, so a retried run is
counted once and none is lost: the report is the serial campaign's, run for run (a run
depends on its run seed alone).

Ray is imported in this module only, and only when a campaign asks for it, so a plain
install (without the ``ray`` extra) works, and ``--ray`` there is a clear error
(`RayError`, exit 2) naming the extra.

What crosses to the workers: the net, its approval and the options, put into the object
store once (`ray.put`). The options name the simulator's settings file by path, which
a worker on another machine cannot read, so the driver reads its bytes and each task
writes them to a scratch file of the same name. Workers keep no logs (their file system
is not the user's): after the campaign the driver runs each failed seed again here to
keep its log, and checks that the re-run did the same thing (`ReplayMismatch`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import socket
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.certificate import CertificateCheck
from coral_lang.diagnostics import CoralError
from coral_lang.net import Net
from runtime.fuzz.one_run import FuzzOptions, FuzzRun, failed_log_path, run_one, run_seed

if TYPE_CHECKING:
    from types import ModuleType

    from ray import ObjectRef

__all__ = [
    "MAX_RETRIES",
    "RAY_EXTRA",
    "TEST_DIE_ENV",
    "RayCampaign",
    "RayError",
    "RayTarget",
    "ReplayMismatch",
    "import_ray",
    "run_on_ray",
    "session",
]

RAY_EXTRA = "pip install 'coral[ray]'"
"""How to get Ray along with coral (the ``ray`` extra of ``pyproject.toml``)."""

MAX_RETRIES = 3
"""How often Ray runs a task again whose worker process died (not when the run itself
raises: that is a bug to see, not to retry)."""

TEST_DIE_ENV = "CORAL_FUZZ_RAY_TEST_DIE"
"""For tests only: names a file holding ``SEED MARKER``. A worker about to run run seed
SEED while no file MARKER exists creates MARKER and dies at once (`os._exit`), so a test
can check that a dead worker's run is retried, and counted once. Read by the workers,
which inherit it from the environment the cluster was started in."""


LOCAL_OBJECT_STORE = 256 * 1024 * 1024
"""The object store of a local cluster, bytes: the campaign's one shipment and the runs
(a few kB each) need little, and Ray's default takes 30 % of the machine's memory."""


class RayError(CoralError):
    """Ray is not installed, the cluster cannot be reached, or it lost a run for good."""


@dataclass(frozen=True)
class RayTarget:
    """Where to run a campaign on Ray.

    Attributes:
        address: the cluster to connect to (``HOST:PORT`` of its head, or ``auto`` for
            the one ``ray start`` started on this machine); None: start a private local
            cluster for the campaign, shut down after it.
        cpus: the CPUs of that local cluster (None: one per core of this machine); a
            cluster at an address has its own.

    A process already connected to Ray (``ray.init`` called by the caller) uses that
    connection whatever the target, and leaves it as it was.
    """

    address: str | None = None
    cpus: int | None = None


@dataclass(frozen=True)
class ReplayMismatch:
    """A failed run whose re-run on the driver (to keep its log) did something else.

    A run depends on its run seed alone, so this is a bug (something in a run read the
    machine, the clock or a global), reported loudly: the kept log is the driver's
    re-run, not what the worker did.
    """

    seed: int
    worker_digest: str
    driver_digest: str

    def to_json(self) -> dict[str, object]:
        """JSON-ready form (``nondeterministic`` in ``fuzz-report.json``)."""
        return {
            "seed": self.seed,
            "worker_events_digest": self.worker_digest,
            "driver_events_digest": self.driver_digest,
        }


@dataclass
class RayCampaign:
    """What the Ray side of a campaign says besides its runs.

    Attributes:
        where: e.g. ``on Ray at 10.0.0.5:6379 (64 CPUs)`` (filled in once connected).
        mismatches: failed runs whose logs' re-runs differed (`ReplayMismatch`).
    """

    where: str = ""
    mismatches: list[ReplayMismatch] = dataclasses.field(default_factory=list)


def import_ray() -> ModuleType:
    """The ``ray`` module, or `RayError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise RayError(f"--ray needs Ray, which is not installed here: {RAY_EXTRA}") from None
    return ray


@dataclass(frozen=True)
class _Shipment:
    """Everything every task needs, put into the object store once."""

    net: Net
    approval: CertificateCheck
    options: FuzzOptions
    sim_config_name: str | None
    sim_config: bytes | None


def _shipment(net: Net, approval: CertificateCheck, options: FuzzOptions) -> _Shipment:
    """The shipment, with the settings file's bytes read here (OSError: unreadable)."""
    config = options.sim_config
    if config is None:
        return _Shipment(net, approval, options, None, None)
    plain = dataclasses.replace(options, sim_config=None)
    return _Shipment(net, approval, plain, config.name, config.read_bytes())


def _run_task(shipment: _Shipment, seed: int, index: int) -> FuzzRun:
    """One run on a worker: the settings file re-created in scratch space, no log kept."""
    _die_if_asked(seed)
    options = shipment.options
    with tempfile.TemporaryDirectory(prefix="coral-fuzz-ray-") as scratch:
        if shipment.sim_config is not None and shipment.sim_config_name is not None:
            path = Path(scratch) / shipment.sim_config_name
            path.write_bytes(shipment.sim_config)
            options = dataclasses.replace(options, sim_config=path)
        return run_one(shipment.net, shipment.approval, seed, options, index=index)


def _die_if_asked(seed: int) -> None:
    """The test hook of `TEST_DIE_ENV` (nothing at all unless it is set)."""
    spec = os.environ.get(TEST_DIE_ENV)
    if not spec:
        return
    try:
        victim, marker = Path(spec).read_text(encoding="utf-8").split(maxsplit=1)
    except (OSError, ValueError):
        return
    if victim != str(seed):
        return
    try:
        fd = os.open(marker.strip(), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.close(fd)
    os._exit(70)


Progress = Callable[[int, int, int], None]


def run_on_ray(
    net: Net,
    approval: CertificateCheck,
    options: FuzzOptions,
    target: RayTarget,
    runs: list[FuzzRun],
    campaign: RayCampaign,
    *,
    failed_logs: Path | None = None,
    progress: Progress | None = None,
) -> None:
    """The campaign's runs as Ray tasks, appended to ``runs`` as they finish.

    ``campaign`` is filled in as it goes (where it runs; replays that differed). On
    Ctrl-C the tasks not finished are cancelled, the runs done kept, and the
    KeyboardInterrupt goes on to the caller. A cluster started here is shut down; one
    connected to is only disconnected from; a connection the caller made is left.

    Raises:
        RayError: Ray missing, the cluster unreachable, or a run lost with its worker
            more than `MAX_RETRIES` times.
        OSError: the simulator's settings file cannot be read.
    """
    ray = import_ray()
    shipment = _shipment(net, approval, options)
    with session(ray, target) as started:
        cpus = int(ray.cluster_resources().get("CPU", 0))
        if started:
            campaign.where = f"on a local Ray cluster ({cpus} CPUs)"
        else:
            address = ray.get_runtime_context().gcs_address
            campaign.where = f"on Ray at {address} ({cpus} CPUs)"
        _run_tasks(ray, ray.put(shipment), options, runs, max(16, 4 * cpus), progress)
    if failed_logs is not None:
        campaign.mismatches.extend(_keep_failed_logs(net, approval, options, runs, failed_logs))


@contextlib.contextmanager
def session(ray: ModuleType, target: RayTarget) -> Iterator[bool]:
    """Ray, connected for the block; yields whether it started a cluster of its own.

    A cluster started here is shut down after the block; one at ``target.address`` is
    only disconnected from (``ray.shutdown`` in a driver that connected stops nothing of
    the cluster); a connection the caller already made is left as it is.

    Raises:
        RayError: the cluster at ``target.address`` cannot be reached.
    """
    if ray.is_initialized():
        yield False
        return
    _connect(ray, target)
    try:
        yield target.address is None
    finally:
        ray.shutdown()


def _connect(ray: ModuleType, target: RayTarget) -> None:
    """Start a private local cluster, or connect to ``target.address``; Ray's own log
    lines stay out of the user's terminal (warnings and errors still show)."""
    # coral never reports usage on its users' behalf (and a fuzz machine may have no network).
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    quiet = {"logging_level": logging.WARNING, "log_to_driver": False}
    if target.address is None:
        # Ray guards a new local cluster with a token (kept in ~/.ray) and warns that it
        # does on every start: the guard is right, the warning noise in a report.
        auth = logging.getLogger("ray._private.authentication.authentication_token_setup")
        level = auth.level
        auth.setLevel(logging.ERROR)
        try:
            ray.init(
                address="local",
                num_cpus=target.cpus or os.cpu_count() or 1,
                include_dashboard=False,
                object_store_memory=LOCAL_OBJECT_STORE,
                **quiet,
            )
        finally:
            auth.setLevel(level)
        return
    if target.address != "auto":
        _probe(target.address)
    try:
        ray.init(address=target.address, **quiet)
    except (ConnectionError, ValueError, RuntimeError, TimeoutError) as exc:
        raise RayError(f"cannot connect to the Ray cluster at {target.address}: {exc}") from None


PROBE_SECONDS = 5.0
"""How long to wait for the head's port to answer: Ray itself retries a cluster that does
not answer for about a quarter of an hour before it gives up."""


def _probe(address: str) -> None:
    """Fail fast, in one line, when nothing listens at ``address`` (``HOST:PORT``)."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise RayError(f"--ray {address}: give the cluster's head as HOST:PORT, or 'auto'")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=PROBE_SECONDS).close()
    except OSError as exc:
        raise RayError(f"cannot connect to the Ray cluster at {address}: {exc}") from None


def _run_tasks(
    ray: ModuleType,
    shipment: ObjectRef[_Shipment],
    options: FuzzOptions,
    runs: list[FuzzRun],
    window: int,
    progress: Progress | None,
) -> None:
    """Submit the runs, at most ``window`` in flight (a million pending tasks would cost
    the driver memory and every `ray.wait` time), and collect each once, by index."""
    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(_run_task)
    pending: dict[ObjectRef[FuzzRun], int] = {}
    done: dict[int, FuzzRun] = {}
    failed = 0
    submitted = 0
    try:
        while len(done) < options.runs:
            while submitted < options.runs and len(pending) < window:
                seed = run_seed(options.seed, submitted)
                pending[task.remote(shipment, seed, submitted)] = submitted
                submitted += 1
            ready, rest = ray.wait(list(pending), num_returns=1)
            if rest:  # and whatever else is done by now: one wait per batch, not per run
                ready += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
            for ref in ready:
                index = pending.pop(ref)
                run = _result(ray, ref, run_seed(options.seed, index), index)
                if run.index != index or index in done:  # cannot happen: say so if it does
                    raise RayError(f"Ray returned run {run.index} twice or for run {index}")
                done[index] = run
                runs.append(run)
                failed += not run.ok
                if progress is not None:
                    progress(len(done), options.runs, failed)
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref)
        raise


def _result(ray: ModuleType, ref: ObjectRef[FuzzRun], seed: int, index: int) -> FuzzRun:
    """A finished task's run; a run's own error as it was raised (a bad simulator
    setting on a worker is bad input there too), a lost one as `RayError`."""
    try:
        run: FuzzRun = ray.get(ref)
    except ray.exceptions.RayTaskError as exc:
        if isinstance(exc.cause, CoralError):
            raise exc.cause from None
        if isinstance(exc.cause, ImportError):
            raise RayError(
                f"a Ray worker cannot run coral ({exc.cause}): every machine of the cluster "
                f"needs this coral version, installed with {RAY_EXTRA}"
            ) from None
        raise  # a bug in the run: its traceback is what to see
    except ray.exceptions.RayError as exc:
        raise RayError(
            f"Ray could not run run {index} (run seed {seed}; a worker that dies is "
            f"retried {MAX_RETRIES} times): {exc}"
        ) from None
    return run


def _keep_failed_logs(
    net: Net,
    approval: CertificateCheck,
    options: FuzzOptions,
    runs: list[FuzzRun],
    folder: Path,
) -> list[ReplayMismatch]:
    """Run each failed run again here, keeping its log as ``seed-SEED.sqlite`` (as a
    local campaign does), and name those whose events differ from the worker's."""
    mismatches: list[ReplayMismatch] = []
    for position in sorted(range(len(runs)), key=lambda p: runs[p].index):
        run = runs[position]
        if run.ok:
            continue
        path = failed_log_path(folder, run.seed)
        again = run_one(net, approval, run.seed, options, index=run.index, keep_log=path)
        runs[position] = dataclasses.replace(run, log=path)
        if again.events_digest != run.events_digest:
            mismatches.append(ReplayMismatch(run.seed, run.events_digest, again.events_digest))
    return mismatches
