"""The simulated ROMEO: commands in, replies and telemetry out, time injected.

`Vehicle` is what the runtime talks to (through the wire protocol) and what the tests
drive directly. It never reads a clock: `Vehicle.advance` and `Vehicle.advance_to` move
its time forward, in fixed internal steps; a real-time server calls them with wall-clock
deltas, tests call them with whatever they like. The same seed and the same calls give a
bit-identical run.

Decisions the paper leaves open (see docs/sim.md for the full list):

* Tasks reply ``ack`` when accepted, ``error`` when refused: a depth below the reachable
  bottom; a horizontal target (LRM, SRM, GOTO) closer to a wall than the vehicle's
  radius; LRM, SRM, GOTO or DOCKING before FIX_XY has given a position estimate; DOCKING
  before GET_DOCK. GET_DOCK replies ``error`` with no estimate. INIT replies ``done``.
* FIX_XY replies ``done`` or ``error`` after one sonar revolution; if another command
  takes ``horizontal`` before that, it replies ``error`` (interrupted) at once.
* A command on a busy resource stops the whole task holding it; every pending query
  watching one of that task's resources replies ``timeout`` at once, with a detail
  naming the replacement. Queries are observers and never replace each other.
* Queries reply only ``done`` or ``timeout`` (as the profile says); they are never
  refused for the vehicle's state: a query that cannot succeed (XY? before FIX_XY, DOCKING?
  with no dock, a target out of reach) times out.
* Malformed input (unknown command, missing, extra, mistyped or out-of-range parameter,
  a command id reused for another command) gets ``error`` with a detail; it never raises.
* The watchdog arms at the first command (or `heard_from_controller`); after
  ``watchdog_s`` without either, the vehicle stops every task, pending queries reply
  ``timeout``, and it surfaces by itself. It logs that as an event. The controller's
  make-safe request (`Vehicle.make_safe`) does the same at once.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache

import numpy as np

from coral_lang.profile import CommandSpec, VehicleProfile, load_bundled_profile
from romeo_sim.config import VehicleConfig, VehicleConfigError, default_config
from romeo_sim.control import AxisController
from romeo_sim.dynamics import Dynamics, wrap_angle
from romeo_sim.navigation import Navigation
from romeo_sim.pool import Pool
from romeo_sim.queries import MEASURES, Dock, SpaceTrapQuery, make_evaluator
from romeo_sim.sensors import Compass, DepthGauge, NoiseStream, ScanningSonar
from romeo_sim.tasks import (
    DepthTask,
    DockingTask,
    FixTask,
    GotoTask,
    HeadingTask,
    HorizontalTask,
    LrmTask,
    SrmTask,
    Task,
)
from runtime.telemetry import TelemetryRecord
from runtime.vehicle.model import Reply

__all__ = ["SUPPORTED_COMMANDS", "Reply", "Telemetry", "Vehicle", "VehicleEvent"]

SUPPORTED_COMMANDS: tuple[str, ...] = (
    "INIT",
    "DEPTH",
    "DEPTH?",
    "HEADING",
    "HEADING?",
    "LRM",
    "XY?",
    "SRM",
    "GOTO",
    "XYPSI?",
    "DOCKING",
    "DOCKING?",
    "FIX_XY",
    "GET_DOCK",
    "SURFACE",
    "SURFACE?",
)
_RESOURCES: tuple[str, ...] = ("depth", "heading", "horizontal")
_PI = math.pi
WATCHDOG_ID = -1


@dataclass(frozen=True)
class VehicleEvent:
    """Something the vehicle did on its own account (a mode switch, the watchdog, ...)."""

    time: float
    text: str


@dataclass(frozen=True)
class Telemetry(TelemetryRecord):
    """A snapshot of the vehicle: the telemetry record, plus the simulator's own truth.

    The fields of `runtime.telemetry.TelemetryRecord` (what a datagram carries, and what
    the vehicle server sends and logs of it) come first; ROMEO adds its depth and heading
    estimates, speeds, thrusts and the task holding each resource, for plots and tests.
    Positions in m (x north, y east, z depth), headings in degrees in [0, 360) clockwise
    from north, speeds in m/s and deg/s. ``est_x``/``est_y`` are None before FIX_XY.
    """

    est_z: float = 0.0
    est_psi: float = 0.0
    u: float = 0.0
    v: float = 0.0
    w: float = 0.0
    r: float = 0.0
    thrust_surge: float = 0.0
    thrust_sway: float = 0.0
    thrust_heave: float = 0.0
    thrust_yaw: float = 0.0
    depth_task: str = ""
    heading_task: str = ""
    horizontal_task: str = ""


class Vehicle:
    """ROMEO in its pool, answering the commands of its profile.

    Args:
        config: vehicle file; the bundled ROMEO defaults if None.
        profile: command profile; the bundled ROMEO profile if None.
        seed: seeds every noise source.
        start_time: the vehicle clock at construction, s.

    Raises:
        VehicleConfigError: the profile declares a command this vehicle cannot carry
            out, or a space-trap criterion it cannot evaluate.
    """

    def __init__(
        self,
        config: VehicleConfig | None = None,
        profile: VehicleProfile | None = None,
        *,
        seed: int = 0,
        start_time: float = 0.0,
    ) -> None:
        if not math.isfinite(start_time):
            raise ValueError(f"start_time must be finite, got {start_time}")
        self.config = config = default_config() if config is None else config
        self.profile = profile = _bundled_profile() if profile is None else profile
        self._check_profile(profile)
        heading_query = profile.command("HEADING?")
        trap = None if heading_query is None else heading_query.space_trap
        self._heading_eps = (
            (trap.eps[0], trap.eps[1] if trap.order >= 1 else math.inf)
            if trap is not None
            else (3.0, 1.0)
        )
        streams = np.random.SeedSequence(seed).spawn(3)
        h = config.step_s
        self._h = h
        self.pool = pool = Pool(config.pool)
        init = config.initial
        self.body = body = Dynamics(
            config.dynamics, pool, h, init.x_m, init.y_m, init.z_m, math.radians(init.psi_deg)
        )
        self._gauge = DepthGauge(config.sensors, NoiseStream(streams[0]))
        self._compass = Compass(config.sensors, NoiseStream(streams[1]))
        self.sonar = ScanningSonar(config.sensors, pool, h, NoiseStream(streams[2]))
        self.nav = Navigation(body, config.navigation, config.sensors, pool, h)
        d, ctl = config.dynamics, config.control
        m, k, kq, lim = d.mass, d.linear_damping, d.quadratic_damping, d.thrust_limit
        self._surge = AxisController(ctl.horizontal, m.surge, k.surge, kq.surge, lim.surge, 0.0, h)
        self._sway = AxisController(ctl.horizontal, m.sway, k.sway, kq.sway, lim.sway, 0.0, h)
        self._heave = AxisController(
            ctl.depth, m.heave, k.heave, kq.heave, lim.heave, d.net_buoyancy_n, h
        )
        self._yaw = AxisController(
            ctl.heading,
            m.yaw,
            k.yaw,
            kq.yaw,
            lim.yaw,
            0.0,
            h,
            v_max=math.radians(ctl.heading.v_max),
        )
        self._start = float(start_time)
        self._steps = 0
        self._clock = float(start_time)
        self._owners: dict[str, Task] = {}
        self._queries: list[SpaceTrapQuery] = []
        self._replies: dict[int, list[Reply]] = {}
        self._signatures: dict[int, tuple[str, str]] = {}
        self._outbox: list[Reply] = []
        self._events: list[VehicleEvent] = []
        self.dock: Dock | None = None
        self._armed = False
        self._last_heard = self._clock
        self._watchdog_tripped = False
        self._release = config.control.surface_release_m
        self._plan_dirty = True
        self._plan_fix: FixTask | None = None
        self._plan_docking: DockingTask | None = None
        self._plan_horizontal: HorizontalTask | None = None
        self._plan_owns_yaw = False
        self._plan_psi: float | None = None
        self._plan_depth: float | None = None
        self._plan_surfacing = False

    # ----------------------------------------------------------------- clock

    @property
    def time(self) -> float:
        """The vehicle clock, s."""
        return self._clock

    @property
    def watchdog_s(self) -> float:
        """Vehicle seconds without a word from the controller before ROMEO surfaces by
        itself (``watchdog_s`` of its vehicle file); the server reports it to the
        controller (`runtime.vehicle.model.VehicleModel.watchdog_s`)."""
        return self.config.watchdog_s

    @property
    def state_time(self) -> float:
        """Time of the simulated state: the last internal step at or before `time`."""
        return self._start + self._steps * self._h

    def advance(self, dt: float) -> list[Reply]:
        """Move the clock ``dt`` seconds on; returns the replies that fell due meanwhile.

        Raises:
            ValueError: ``dt`` negative or not finite.
        """
        if not math.isfinite(dt) or dt < 0.0:
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        return self.advance_to(self._clock + dt)

    def advance_to(self, t: float) -> list[Reply]:
        """Move the clock to ``t``, integrating in fixed steps; returns replies that fell due.

        Raises:
            ValueError: ``t`` earlier than `time` or not finite.
        """
        if not math.isfinite(t) or t < self._clock - 1e-9:
            raise ValueError(f"cannot move the vehicle clock from {self._clock} back to {t}")
        start, h = self._start, self._h
        limit = t + 1e-9
        steps = self._steps
        # Step k runs at start + k * h, and runs when start + (k + 1) * h <= limit: the
        # time tested for one step is the time of the next (the same expression).
        due = start + (steps + 1) * h
        if due <= limit:
            step = self._step
            now = start + steps * h
            while due <= limit:
                step(now)
                steps += 1
                self._steps = steps
                now = due
                due = start + (steps + 1) * h
        if t >= self._clock:  # max(t, clock), which keeps t when the two are equal
            self._clock = t
        out = self._outbox
        self._outbox = []
        return out

    # -------------------------------------------------------------- commands

    def heard_from_controller(self) -> None:
        """Reset the watchdog (the controller is alive: e.g. a telemetry request arrived)."""
        self._armed = True
        self._last_heard = self._clock
        self._watchdog_tripped = False

    def command(
        self, command_id: int, name: str, params: Mapping[str, float | int | str]
    ) -> list[Reply]:
        """Carry out one command; returns its immediate replies.

        Tasks reply ``ack`` or ``error`` at once; INIT and GET_DOCK ``done`` or ``error``;
        queries and FIX_XY reply later, from `advance`. A command id seen before returns
        the replies that id has produced so far (an idempotent resend after a reconnect).
        Replies this command causes for *other* commands (the queries of a task it
        replaces, a FIX_XY it interrupts) come from the next `advance` (``advance(0)``
        will do), stamped with this command's time.

        Raises:
            ValueError: ``command_id`` is not an int, or ``name`` not a str (a bug in the
                caller, not input from the wire).
        """
        if isinstance(command_id, bool) or not isinstance(command_id, int):
            raise ValueError(f"command_id must be an int, got {command_id!r}")
        if not isinstance(name, str):
            raise ValueError(f"command name must be a str, got {name!r}")
        self.heard_from_controller()
        if isinstance(params, Mapping):
            signature = (name, repr(sorted((str(k), repr(v)) for k, v in params.items())))
        else:
            signature = (name, repr(params))
        if command_id in self._signatures:
            if self._signatures[command_id] == signature:
                return list(self._replies[command_id])
            first = self._signatures[command_id][0]
            return [
                Reply(
                    command_id,
                    name,
                    "error",
                    self._clock,
                    f"command id {command_id} was already used for {first}; not carried out",
                )
            ]
        self._signatures[command_id] = signature
        self._replies[command_id] = []
        before = len(self._outbox)
        self._dispatch(command_id, name, params)
        # Replies to other commands that this one caused (a replaced task's queries, an
        # interrupted FIX_XY) stay queued for the next advance, stamped with this time.
        new = self._outbox[before:]
        del self._outbox[before:]
        immediate = [r for r in new if r.command_id == command_id]
        self._outbox.extend(r for r in new if r.command_id != command_id)
        return immediate

    def _emit(
        self, command_id: int, name: str, kind: str, detail: str = "", time: float | None = None
    ) -> None:
        reply = Reply(command_id, name, kind, self._clock if time is None else time, detail)
        self._replies.setdefault(command_id, []).append(reply)
        self._outbox.append(reply)

    def _log(self, time: float, text: str) -> None:
        self._events.append(VehicleEvent(time, text))

    def _dispatch(self, cid: int, name: str, params: Mapping[str, float | int | str]) -> None:
        spec = self.profile.command(name)
        if spec is None:
            close = difflib.get_close_matches(name, self.profile.command_names, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            self._emit(cid, name, "error", f"unknown command '{name}'{hint}")
            return
        values, problem = _parse_params(spec, params)
        if problem:
            self._emit(cid, name, "error", problem)
            return
        now = self._clock
        cfg = self.config
        if spec.kind == "query":
            self._start_query(cid, spec, values)
            return
        if name == "INIT":
            self._emit(cid, name, "done", f"{self.profile.name} simulator ready at {now:.3f} s")
        elif name == "DEPTH":
            bottom = cfg.pool.depth_m - cfg.dynamics.half_height_m
            if values["z"] > bottom:
                self._emit(
                    cid,
                    name,
                    "error",
                    f"depth {values['z']:g} m is below the reachable bottom "
                    f"({bottom:g} m in a {cfg.pool.depth_m:g} m pool)",
                )
                return
            self._start_task(DepthTask(cid, name, now, values["z"]))
        elif name == "SURFACE":
            self._start_task(DepthTask(cid, name, now, 0.0, surfacing=True))
        elif name == "HEADING":
            self._start_task(HeadingTask(cid, name, now, values["psi"]))
        elif name in ("LRM", "SRM", "GOTO"):
            refusal = self._horizontal_refusal(values["x"], values["y"])
            if refusal:
                self._emit(cid, name, "error", refusal)
                return
            ctl = cfg.control
            task: Task
            if name == "LRM":
                task = LrmTask(cid, now, ctl, values["x"], values["y"])
            elif name == "SRM":
                task = SrmTask(cid, now, ctl, values["x"], values["y"], values["psi"])
            else:
                task = GotoTask(cid, now, ctl, values["x"], values["y"], values["psi"])
            self._start_task(task)
        elif name == "DOCKING":
            if not self.nav.has_fix:
                self._emit(cid, name, "error", "no horizontal position estimate: send FIX_XY first")
            elif self.dock is None:
                self._emit(cid, name, "error", "no docking point recorded: send GET_DOCK first")
            else:
                x, y, psi = self.dock
                self._start_task(DockingTask(cid, now, cfg.control, x, y, psi))
        elif name == "FIX_XY":
            ends = now + self.sonar.revolution_s
            self._start_task(FixTask(cid, now, cfg.control, ends), ack=False)
            self.nav.start_fix()
        elif name == "GET_DOCK":
            if not self.nav.has_fix:
                self._emit(cid, name, "error", "no horizontal position estimate: send FIX_XY first")
            else:
                ekf = self.nav.ekf
                self.dock = (ekf.x, ekf.y, self.nav.psi)
                self._emit(
                    cid,
                    name,
                    "done",
                    f"docking point ({ekf.x:.2f}, {ekf.y:.2f}) m, heading "
                    f"{math.degrees(self.nav.psi) % 360:.1f} deg",
                )
        else:  # pragma: no cover - _check_profile refuses profiles naming other commands
            self._emit(cid, name, "error", f"command '{name}' is not implemented")

    def _horizontal_refusal(self, x: float, y: float) -> str:
        if not self.nav.has_fix:
            return "no horizontal position estimate: send FIX_XY first"
        margin = self.config.dynamics.radius_m
        if not self.pool.contains(x, y, margin):
            return (
                f"target ({x:g}, {y:g}) m is not reachable: it must lie {margin:g} m inside "
                f"the {self.pool.length:g} x {self.pool.width:g} m pool"
            )
        return ""

    def _start_query(self, cid: int, spec: CommandSpec, values: dict[str, float]) -> None:
        trap = spec.space_trap
        assert trap is not None  # _check_profile refuses a query without one
        evaluate = make_evaluator(trap, values, self._heading_eps)
        self._queries.append(
            SpaceTrapQuery(
                cid,
                spec.name,
                spec.resources,
                self._clock,
                values["time_out"],
                trap,
                evaluate,
                MEASURES[trap.signal],
            )
        )

    def _start_task(self, task: Task, ack: bool = True) -> None:
        self._take(task, task.resources, self._clock)
        if ack:
            self._emit(task.command_id, task.name, "ack", "")

    def _take(self, task: Task, resources: tuple[str, ...], now: float) -> None:
        """Give ``resources`` to ``task``, stopping whatever held them."""
        replaced: list[Task] = []
        for resource in resources:
            old = self._owners.get(resource)
            if old is not None and old is not task and old not in replaced:
                replaced.append(old)
        for old in replaced:
            self._stop(old, f"replaced by {task.label()}", now)
        for resource in resources:
            self._owners[resource] = task
        self._plan_dirty = True
        if "depth" in resources:
            self._heave.reset()
        if "heading" in resources:
            self._yaw.reset()
        if "horizontal" in resources:
            self._surge.reset()
            self._sway.reset()

    def _stop(self, task: Task, why: str, now: float) -> None:
        for resource in _RESOURCES:
            if self._owners.get(resource) is task:
                del self._owners[resource]
        self._plan_dirty = True
        self._log(now, f"{task.label()} stopped: {why}")
        if isinstance(task, FixTask):
            self.nav.cancel_fix()
            self._emit(task.command_id, task.name, "error", f"interrupted: {why}", now)
        watched = set(task.resources)
        for query in [q for q in self._queries if watched.intersection(q.resources)]:
            self._queries.remove(query)
            self._emit(
                query.command_id,
                query.name,
                "timeout",
                f"its task {task.label()} was {why}",
                now,
            )

    # ----------------------------------------------------------------- step

    def _step(self, now: float) -> None:
        body, nav = self.body, self.nav
        psi_m, r_m = self._compass.read(body)
        nav.step(self._gauge.read(body), psi_m, r_m, self.sonar.sense(body, now))
        if self._plan_dirty:
            self._make_plan()
        fix = self._plan_fix
        if fix is not None:
            if now >= fix.ends - 1e-9:
                self._finish_fix(fix, now)
        else:
            docking = self._plan_docking
            if docking is not None and docking.ready_to_emerge(nav, now):
                docking.emerging = True
                docking.resources = (*docking.resources, "depth")
                self._log(now, f"{docking.label()}: over the docking point, emerging")
                self._take(docking, ("depth",), now)
        queries = self._queries
        if queries:
            dock = self.dock
            finished: list[SpaceTrapQuery] = []
            for query in queries:  # a loop, not a comprehension: no function call per step
                if query.step(nav, dock, now) is not None:
                    finished.append(query)
            for query in finished:
                queries.remove(query)
                kind = query.outcome
                self._emit(query.command_id, query.name, kind, _query_detail(query, kind), now)
        # Control.
        if self._plan_dirty:
            self._make_plan()
        cu = cv = cr = cw = 0.0
        task = self._plan_horizontal
        psi_ref = self._plan_psi
        if task is not None:
            owns_yaw = self._plan_owns_yaw
            wish = task.guide(nav, owns_yaw)
            if task.switches:
                for text in task.switches:
                    self._log(now, text)
                task.switches.clear()
            ekf = nav.ekf
            if wish.hover:
                # Hold ground, not water: cancel the estimated current in body axes.
                psi = nav.psi
                c, s = math.cos(psi), math.sin(psi)
                cn, ce = ekf.cn, ekf.ce
                drift_u = c * cn + s * ce
                drift_v = -s * cn + c * ce
                cu = self._surge.position(wish.a, ekf.u, drift_u)
                cv = self._sway.position(wish.b, ekf.v, drift_v)
            else:
                cu = self._surge.velocity(wish.a, ekf.u)
                cv = self._sway.velocity(wish.b, ekf.v)
            if owns_yaw:
                psi_ref = wish.psi
        if psi_ref is not None:
            error = psi_ref - nav.psi
            if error >= _PI or error < -_PI:
                error = wrap_angle(error)
            cr = self._yaw.position(error, nav.r)
        depth_ref = self._plan_depth
        if depth_ref is not None:
            z = nav.z
            if not (self._plan_surfacing and z < self._release):
                cw = self._heave.position(depth_ref - z, nav.w)
        body.step(cu, cv, cw, cr)
        if (
            self._armed
            and not self._watchdog_tripped
            and now - self._last_heard >= self.config.watchdog_s
        ):
            self._trip_watchdog(now)

    def _make_plan(self) -> None:
        """Work out, once per change of owners, which task drives which axis.

        Also which task on ``horizontal`` each step must watch: a FIX_XY for its end, a
        DOCKING for its arrival over the dock.
        """
        owners = self._owners
        horizontal = owners.get("horizontal")
        heading = owners.get("heading")
        depth = owners.get("depth")
        self._plan_fix = horizontal if isinstance(horizontal, FixTask) else None
        self._plan_docking = horizontal if isinstance(horizontal, DockingTask) else None
        self._plan_horizontal = (
            horizontal
            if isinstance(horizontal, HorizontalTask) and not isinstance(horizontal, FixTask)
            else None
        )
        self._plan_owns_yaw = horizontal is not None and (
            heading is horizontal or (heading is None and isinstance(horizontal, LrmTask))
        )
        self._plan_psi = heading.target if isinstance(heading, HeadingTask) else None
        self._plan_depth = None
        self._plan_surfacing = False
        if isinstance(depth, DepthTask):
            self._plan_depth = depth.target
            self._plan_surfacing = depth.surfacing
        elif isinstance(depth, DockingTask):
            self._plan_depth = 0.0
            self._plan_surfacing = True
        self._plan_dirty = False

    def _finish_fix(self, task: FixTask, now: float) -> None:
        result = self.nav.finish_fix()
        del self._owners["horizontal"]
        self._plan_dirty = True
        self._emit(task.command_id, task.name, "done" if result.ok else "error", result.detail, now)
        self._log(now, f"{task.label()}: {'done' if result.ok else 'failed'}: {result.detail}")

    def make_safe(self, reason: str) -> list[Reply]:
        """The controller's make-safe request: what the watchdog does, at once.

        Every task stops, pending queries reply ``timeout``, FIX_XY ``error``, and ROMEO
        surfaces by itself; the watchdog then stays tripped until the controller speaks
        again. Returns every reply due now, those included. Logged as an event.
        """
        now = self._clock
        self._watchdog_tripped = True
        self._log(
            now, f"make-safe requested by the controller ({reason or 'no reason given'}); surfacing"
        )
        self._surface_now("stopped: the controller asked the vehicle to make itself safe", now)
        out = self._outbox
        self._outbox = []
        return out

    def _trip_watchdog(self, now: float) -> None:
        self._watchdog_tripped = True
        silence = now - self._last_heard
        self._log(
            now,
            f"watchdog: no word from the controller for {silence:.1f} s; surfacing",
        )
        self._surface_now("stopped by the watchdog", now)

    def _surface_now(self, why: str, now: float) -> None:
        """Stop every task and query with the watchdog's replies, and surface."""
        for task in {id(t): t for t in self._owners.values()}.values():
            self._stop(task, why, now)
        for query in list(self._queries):
            self._queries.remove(query)
            self._emit(query.command_id, query.name, "timeout", f"{why} (vehicle surfacing)", now)
        self._take(DepthTask(WATCHDOG_ID, "SURFACE", now, 0.0, surfacing=True), ("depth",), now)

    # ------------------------------------------------------------ reporting

    def telemetry(self) -> Telemetry:
        """Snapshot of the simulated state (truth and estimate) at `state_time`."""
        body, nav = self.body, self.nav
        ekf = nav.ekf
        owners = self._owners

        def label(resource: str) -> str:
            task = owners.get(resource)
            return "" if task is None else task.label()

        return Telemetry(
            vehicle_time=self.state_time,
            x=body.x,
            y=body.y,
            z=body.z,
            psi=math.degrees(body.psi) % 360.0,
            est_x=ekf.x if nav.has_fix else None,
            est_y=ekf.y if nav.has_fix else None,
            est_z=nav.z,
            est_psi=math.degrees(nav.psi) % 360.0,
            u=body.u,
            v=body.v,
            w=body.w,
            r=math.degrees(body.r),
            thrust_surge=body.tu,
            thrust_sway=body.tv,
            thrust_heave=body.tw,
            thrust_yaw=body.tr,
            depth_task=label("depth"),
            heading_task=label("heading"),
            horizontal_task=label("horizontal"),
        )

    def status(self) -> list[str]:
        """One line per running task and pending query."""
        now = self._clock
        lines: list[str] = []
        seen: list[Task] = []
        for resource in _RESOURCES:
            task = self._owners.get(resource)
            if task is not None and task not in seen:
                seen.append(task)
                lines.append(task.describe(self.nav, now))
        lines.extend(q.describe(now) for q in self._queries)
        return lines

    @property
    def events(self) -> tuple[VehicleEvent, ...]:
        """What the vehicle did on its own account, oldest first."""
        return tuple(self._events)

    def replies_for(self, command_id: int) -> tuple[Reply, ...]:
        """Every reply produced so far for ``command_id``."""
        return tuple(self._replies.get(command_id, ()))

    @staticmethod
    def _check_profile(profile: VehicleProfile) -> None:
        for spec in profile.commands:
            path = f"commands.{spec.name}"
            if spec.name not in SUPPORTED_COMMANDS:
                raise VehicleConfigError(
                    profile.file,
                    path,
                    f"the simulated vehicle cannot carry out '{spec.name}' "
                    f"(it knows {', '.join(SUPPORTED_COMMANDS)})",
                )
            if spec.kind == "query" and spec.space_trap is None:
                raise VehicleConfigError(
                    profile.file,
                    path,
                    f"query '{spec.name}' declares no space_trap: the simulated vehicle "
                    "answers a query only by its tracking criterion",
                )
            if spec.space_trap is not None:
                try:
                    make_evaluator(spec.space_trap, {"x": 0.0, "y": 0.0, "z": 0.0, "psi": 0.0})
                except ValueError as exc:
                    raise VehicleConfigError(profile.file, f"{path}.space_trap", str(exc)) from None
                if "time_out" not in {p.name for p in spec.params}:
                    raise VehicleConfigError(profile.file, path, "a query needs time_out")


@cache
def _bundled_profile() -> VehicleProfile:
    """ROMEO's bundled profile, parsed once (it is frozen, so sharing it is safe)."""
    return load_bundled_profile("ROMEO")


def _query_detail(query: SpaceTrapQuery, kind: str) -> str:
    what, unit = MEASURES[query.trap.signal]
    if kind == "done":
        return f"tracked for {query.trap.window_s:g} s ({what} {query.error:.2f} {unit})"
    error = "unknown" if math.isinf(query.error) else f"{query.error:.2f} {unit}"
    return f"time-out passed; {what} {error}"


def _parse_params(
    spec: CommandSpec, params: Mapping[str, float | int | str]
) -> tuple[dict[str, float], str]:
    """Check ``params`` against ``spec``; numbers come back in SI units (deg -> rad)."""
    if not isinstance(params, Mapping):
        return {}, f"parameters must be a mapping, got {type(params).__name__}"
    known = {p.name for p in spec.params}
    extra = sorted(str(k) for k in params if k not in known)
    if extra:
        return {}, (
            f"{spec.name} takes no parameter {', '.join(repr(e) for e in extra)} "
            f"(signature: {spec.signature()})"
        )
    values: dict[str, float] = {}
    for p in spec.params:
        if p.name not in params:
            return {}, f"{spec.name} needs parameter '{p.name}' (signature: {spec.signature()})"
        raw = params[p.name]
        if p.type == "string":
            if not isinstance(raw, str):
                return {}, f"parameter '{p.name}' must be text, got {raw!r}"
            continue
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            return {}, f"parameter '{p.name}' must be a number, got {raw!r}"
        if p.type == "int" and not isinstance(raw, int):
            return {}, f"parameter '{p.name}' must be a whole number, got {raw!r}"
        number = float(raw)
        if not math.isfinite(number):
            return {}, f"parameter '{p.name}' must be finite, got {raw!r}"
        if (p.minimum is not None and number < p.minimum) or (
            p.maximum is not None and number > p.maximum
        ):
            return {}, f"parameter {p.describe()}: {number:g} is out of range"
        values[p.name] = math.radians(number) if p.unit == "deg" else number
    return values, ""
