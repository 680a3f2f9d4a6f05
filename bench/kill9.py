"""``kill -9`` campaign: kill ``coral-run`` at random moments, ``--resume``, count commands.

Run: ``.venv/bin/python bench/kill9.py [--trials N] [--seed S] [--kills K]
[--missions pool survey] [--out DIR]``.

Why: the runtime's promise (README, ``docs/runtime.md``) is that after ``kill -9`` of
the controller, ``coral-run --resume`` continues with no command lost and none carried
out twice. The tests kill at one chosen command; this bench kills at random wall-clock
moments (during start-up, the handshake, a command in flight, a commit...), up to
``--kills`` times per trial, and counts from the vehicle's own record.

Each trial serves a simulated vehicle (``coral-vehicle serve``, with its event log
``--log``, a key file of mode 0600 and a watchdog long enough for the restarts), runs
``coral-run --vehicle HOST:PORT`` on the mission with a signed certificate, kills it
with SIGKILL after a random delay, resumes with ``coral-run --resume`` (or starts again
when the kill came before the log existed), and finally lets it finish. Counted:

* ``executed twice``: a command id of a mission the vehicle carried out more than once
  (its ``command-received`` events with ``repeat`` false; a repeat is answered from the
  reply ledger, not carried out, and is not counted). Must be 0.
* ``lost``: a command the controller logged as sent (``command-sent``) that the vehicle
  never carried out. Must be 0.
* ``completed``: the last run exited 0 with the mission in a declared final marking.

The vehicle's own summary line (``N commands (R repeats)``) is printed per trial too.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run as a script: make the project importable
    sys.path.insert(0, str(REPO))

BIN = Path(sys.executable).parent


@dataclass(frozen=True)
class Mission:
    """A mission the bench can run, and how to serve its vehicle."""

    name: str
    path: Path
    vehicle_args: tuple[str, ...]  # which vehicle coral-vehicle serves
    run_args: tuple[str, ...]  # what coral-run needs besides the vehicle
    sim_config: str  # the simulator's settings: a long watchdog
    speed: float  # vehicle seconds per wall second
    wall_s: float  # about how long one uninterrupted run takes, for the kill times
    commands: int  # commands one run sends


def missions() -> dict[str, Mission]:
    romeo_cfg = (REPO / "romeo_sim" / "romeo_vehicle.yaml").read_text()
    minnow = REPO / "examples" / "profiles" / "minnow.yaml"
    return {
        "pool": Mission(
            "pool",
            REPO / "examples" / "pool_mission" / "pool_mission.coral",
            ("--vehicle", "ROMEO"),
            (),
            re.sub(r"(?m)^watchdog_s:.*$", "watchdog_s: 100000.0", romeo_cfg),
            20.0,
            10.0,
            23,
        ),
        "survey": Mission(
            "survey",
            REPO / "examples" / "survey_auv" / "survey.coral",
            ("--profile", str(minnow)),
            ("--profile", str(minnow)),
            "watchdog_s: 100000\nvariation: 0.1\n",
            100.0,
            6.0,
            11,
        ),
    }


@dataclass
class Trial:
    mission: str
    kills: int = 0  # SIGKILLs that hit a live coral-run
    restarts_fresh: int = 0  # kills before the log existed: started again, not resumed
    sent: int = 0
    executed: int = 0
    twice: int = 0
    lost: int = 0
    completed: bool = False
    vehicle_summary: str = ""
    notes: list[str] = field(default_factory=list)


def _check(argv: list[str], what: str) -> None:
    done = subprocess.run(argv, capture_output=True, text=True, cwd=REPO)
    if done.returncode != 0:
        raise SystemExit(f"kill9: {what} failed ({done.returncode}): {done.stdout}{done.stderr}")


def prepare(folder: Path, mission: Mission) -> tuple[Path, Path]:
    """A signing key pair and the mission's signed certificate (made with coral-check)."""
    key = folder / "signing.key"
    certificate = folder / f"{mission.name}.certificate.json"
    _check(
        [
            str(BIN / "coral-check"),
            "verify",
            str(mission.path),
            *mission.run_args,
            "--certificate",
            str(certificate),
            "--signing-key",
            str(key),
        ],
        "coral-check verify --certificate",
    )
    return certificate, folder / "signing.key.pub"


def serve(
    folder: Path, mission: Mission, seed: int, speed: float
) -> tuple[subprocess.Popen[str], str, Path]:
    """Start ``coral-vehicle serve``; returns it, its address and its stderr file."""
    psk = folder / "psk.hex"
    fd = os.open(psk, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(os.urandom(32).hex())
    settings = folder / "sim.yaml"
    settings.write_text(mission.sim_config)
    err = folder / "vehicle.stderr"
    with err.open("w") as err_file:
        vehicle = subprocess.Popen(
            [
                str(BIN / "coral-vehicle"),
                "serve",
                *mission.vehicle_args,
                "--key-file",
                str(psk),
                "--speed",
                str(speed),
                "--sim-config",
                str(settings),
                "--seed",
                str(seed),
                "--log",
                str(folder / "vehicle.sqlite"),
            ],
            stdout=subprocess.PIPE,
            stderr=err_file,
            text=True,
            start_new_session=True,
        )
    assert vehicle.stdout is not None
    line = vehicle.stdout.readline()
    match = re.match(r"listening on (\S+:\d+)", line)
    if not match:
        vehicle.kill()
        raise SystemExit(f"kill9: the vehicle did not start: {line!r} {err.read_text()}")
    return vehicle, match.group(1), err


def kill_at_random(
    proc: subprocess.Popen[bytes],
    output: Path,
    rng: random.Random,
    mission: Mission,
    args: argparse.Namespace,
) -> bool:
    """SIGKILL ``proc`` at a random moment; False when it ended first.

    With ``--kill-mode mixed`` (the default) half the kills fall at a random wall-clock
    time (start-up and the handshake included), half a random delay (up to 0.3 s) after
    the run printed its N-th command (N random, before the last), so that kills in the
    middle of the mission are common however fast the machine is; ``time`` and
    ``commands`` take one kind only.
    """
    by_time = rng.random() < 0.5
    if args.kill_mode == "time" or (args.kill_mode == "mixed" and by_time):
        deadline = time.monotonic() + rng.uniform(0.1, mission.wall_s / args.speed_factor**0.5)
        nth = None
    else:
        deadline = time.monotonic() + args.run_timeout
        nth = rng.randint(1, mission.commands - 1)
    settle = rng.uniform(0.0, 0.3)
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        if nth is not None:
            text = output.read_text(errors="replace")
            if len(re.findall(r"(?m)^t=\S+ #\d+ \w+:", text)) >= nth:
                time.sleep(settle)
                break
        time.sleep(0.02)
    if proc.poll() is not None:
        return False
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    return True


def stop(vehicle: subprocess.Popen[str]) -> None:
    """Stop the vehicle with Ctrl-C, so it commits its log and prints its summary."""
    if vehicle.poll() is None:
        vehicle.send_signal(signal.SIGINT)
        try:
            vehicle.wait(timeout=30)
        except subprocess.TimeoutExpired:
            vehicle.kill()
            vehicle.wait()
    if vehicle.stdout is not None:
        vehicle.stdout.close()


def run_trial(index: int, mission: Mission, args: argparse.Namespace, rng: random.Random) -> Trial:
    folder: Path = args.out / f"trial-{index:02d}-{mission.name}"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    run_dir = folder / "run"
    certificate, trusted = args.gates[mission.name]
    trial = Trial(mission.name)
    speed = mission.speed * args.speed_factor
    vehicle, address, vehicle_err = serve(folder, mission, rng.randrange(1000), speed)
    log = run_dir / "controller.sqlite"
    common = [
        "--vehicle",
        address,
        "--key-file",
        str(folder / "psk.hex"),
        "--certificate",
        str(certificate),
        "--trusted-keys",
        str(trusted),
        "--no-plots",
        *mission.run_args,
    ]
    fresh = [str(BIN / "coral-run"), str(mission.path), "--verify", "--out", str(run_dir)]
    resume = [str(BIN / "coral-run"), "--resume", str(log)]
    wanted = rng.randint(1, args.kills)
    attempt = 0
    try:
        while True:
            if log.exists() and log.stat().st_size == 0:
                # Killed while creating its log: nothing was sent (a command is committed
                # before it goes), and --resume refuses an empty file; an operator starts
                # the mission again, and so does the bench.
                log.unlink()
                trial.notes.append(f"attempt {attempt}: the kill left an empty log; started again")
            argv = (resume if log.exists() else fresh) + common
            if attempt > 0 and not log.exists():
                trial.restarts_fresh += 1
            output = folder / f"attempt-{attempt}.out"
            with output.open("w") as out_file:
                proc = subprocess.Popen(argv, stdout=out_file, stderr=subprocess.STDOUT)
                if trial.kills < wanted:
                    if kill_at_random(proc, output, rng, mission, args):
                        trial.kills += 1
                        attempt += 1
                        continue
                    code = proc.wait()
                else:
                    try:
                        code = proc.wait(timeout=args.run_timeout)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
                        trial.notes.append(f"attempt {attempt} timed out")
                        code = -1
            text = output.read_text(errors="replace")
            trial.completed = code == 0 and "mission ended: final" in text
            if code != 0:
                trial.notes.append(f"attempt {attempt} exit {code}: {text.strip()[-300:]}")
            break
    finally:
        stop(vehicle)
    summary = re.search(r"\d+ commands \(\d+ repeats\)", vehicle_err.read_text(errors="replace"))
    trial.vehicle_summary = summary.group(0) if summary else "no summary"
    try:
        count_commands(trial, log, folder / "vehicle.sqlite")
    except Exception as exc:  # a log the bench cannot read is a finding, not a crash
        trial.notes.append(f"cannot count the commands: {exc}")
        trial.completed = False
    return trial


def _int(value: object) -> int:
    """An id read from a log: an integer, or -1 when the log holds something else."""
    return value if isinstance(value, int) else -1


def count_commands(trial: Trial, controller: Path, vehicle: Path) -> None:
    """Commands sent (controller log) against commands carried out (vehicle log)."""
    from runtime.eventlog import EventLog

    sent: dict[int, set[int]] = {}
    if controller.exists():
        with EventLog.open(controller) as log:
            starts = list(log.events("mission-start"))
            mission_id = _int(starts[0].data["mission_id"]) if starts else -1
            sent[mission_id] = {_int(e.data["command_id"]) for e in log.events("command-sent")}
    executed: Counter[tuple[int, int]] = Counter()
    names: dict[tuple[int, int], str] = {}
    with EventLog.open(vehicle) as log:
        current = -1
        for event in log.events():
            if event.kind == "adopt":
                current = _int(event.data["mission_id"])
            elif event.kind == "command-received" and not event.data.get("repeat"):
                key = (current, _int(event.data["command_id"]))
                executed[key] += 1
                names[key] = str(event.data.get("name"))
    for (mission, command), n in sorted(executed.items()):
        if n > 1:
            trial.notes.append(
                f"command #{command} ({names[(mission, command)]}) of mission {mission} "
                f"carried out {n} times"
            )
    trial.sent = sum(len(ids) for ids in sent.values())
    trial.executed = sum(executed.values())
    trial.twice = sum(n - 1 for n in executed.values() if n > 1)
    trial.lost = sum(1 for m, ids in sent.items() for c in ids if (m, c) not in executed)
    for m, ids in sent.items():
        for c in sorted(ids):
            if (m, c) not in executed:
                trial.notes.append(f"command #{c} of mission {m} sent but never carried out")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--kills", type=int, default=3, help="at most this many kills a trial")
    parser.add_argument(
        "--missions",
        nargs="+",
        choices=("pool", "survey"),
        default=["pool", "survey"],
        help="missions, taken in turn by the trials (default both)",
    )
    parser.add_argument("--out", type=Path, default=REPO / "out" / "kill9")
    parser.add_argument(
        "--kill-mode",
        choices=("mixed", "time", "commands"),
        default="mixed",
        help="kill at a random time, a random delay after a random command, or either",
    )
    parser.add_argument(
        "--speed-factor",
        type=float,
        default=1.0,
        help="multiply the simulators' speeds (pool 20, survey 100) by this",
    )
    parser.add_argument(
        "--run-timeout", type=float, default=180.0, help="wall seconds for the final run"
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out = args.out.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    table = missions()
    rng = random.Random(args.seed)
    key = args.out / "signing.key"
    for old in (key, args.out / "signing.key.pub"):
        old.unlink(missing_ok=True)
    _check([str(BIN / "coral-check"), "keygen", "--out", str(key)], "coral-check keygen")
    args.gates = {name: prepare(args.out, table[name]) for name in set(args.missions)}
    started = time.monotonic()
    trials: list[Trial] = []
    print(
        f"{'trial':>5} {'mission':<8} {'kills':>5} {'fresh':>5} {'sent':>5} {'executed':>8} "
        f"{'twice':>5} {'lost':>4} {'completed':>9}  vehicle"
    )
    for i in range(args.trials):
        mission = table[args.missions[i % len(args.missions)]]
        trial = run_trial(i, mission, args, rng)
        trials.append(trial)
        print(
            f"{i:>5} {trial.mission:<8} {trial.kills:>5} {trial.restarts_fresh:>5} "
            f"{trial.sent:>5} {trial.executed:>8} {trial.twice:>5} {trial.lost:>4} "
            f"{'yes' if trial.completed else 'NO':>9}  {trial.vehicle_summary}",
            flush=True,
        )
        for note in trial.notes:
            print(f"      {note}")
    kills = sum(t.kills for t in trials)
    twice = sum(t.twice for t in trials)
    lost = sum(t.lost for t in trials)
    done = sum(t.completed for t in trials)
    print(
        f"total: {len(trials)} trials, {kills} kills, {sum(t.sent for t in trials)} commands "
        f"sent, executed twice {twice}, lost {lost}, completed after --resume "
        f"{done}/{len(trials)}; seed {args.seed}, {time.monotonic() - started:.0f} s wall"
    )
    with contextlib.suppress(OSError):
        (args.out / "signing.key").unlink()  # the bench's own key: no use after the run
    return 0 if twice == 0 and lost == 0 and done == len(trials) else 1


if __name__ == "__main__":
    raise SystemExit(main())
