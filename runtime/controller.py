"""The controller: the CORAL Engine connected to a vehicle over a link, with its event log.

`Controller.run` keeps one mission going through whatever the link does:

* It connects, runs the handshake (``Hello`` / ``HelloReply``: the paper's INIT, which
  gives the clock offset), proves the connection live with a ``Heartbeat``, and sends
  every command in flight (after a reconnect: the same ids again; the vehicle carries out
  each id once).
* Each reply goes to the engine; the engine's firings and new commands, the reply's
  sequence number and the new engine state are committed to the event log in ONE
  transaction before anything is sent. So a crash can lose only work that was never
  acknowledged to the vehicle: after a restart (`Controller.resume`) the vehicle re-sends
  the replies after the last consumed one, and the commands are re-sent by id.
* It sends a heartbeat when it has been quiet, and takes a silent or misbehaving link
  (no valid frame for ``silence_limit`` seconds, too many rejected frames, a peer that
  disagrees about the handshake) as lost: close, wait, reconnect.
* Telemetry datagrams are checked (`DatagramReceiver`) and logged.
* A step of the engine that never stops firing (`runtime.engine.EngineSpin`: a cycle of
  engine transitions that never waits for the vehicle) ends the run as ``spin``: the spin
  is logged with its cycle, nothing more is sent, and the connection is closed, so the
  vehicle's own watchdog (the ``silence_timeout`` of the handshake) stops its tasks and
  surfaces it.
* `Controller.request_stop` (``coral-run`` calls it on SIGINT and SIGTERM) ends the run
  as ``stopped``: nothing new is sent, the vehicle is asked to make itself safe
  (``MakeSafe``; on the current connection, or on a new one when there is none), the
  controller waits up to ``make_safe_timeout`` seconds for its ``MakeSafeAck``, and the
  log is committed. Replies that arrive meanwhile are not consumed: the vehicle keeps
  them unacknowledged, so ``coral-run --resume`` consumes them. A second request gives
  up the wait at once.

`Controller.operate` takes the operator's actions (``runtime.operator``: give an input
the mission declares, pause, resume) from the live page or ``coral-run operate``, in the
controller's own loop: each is logged as an ``operator`` event with its origin and whether
it was accepted; the step it causes is logged, committed and sent exactly as a reply's.

Console lines show the mission time, seconds since this run started (``t=12.3``), not
the loop's raw clock.

Time is the running event loop's clock, so the same code runs in real time on sockets
and instantly under `runtime.vclock.VirtualTimeLoop`.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import os
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TypeVar

from runtime.engine import (
    Engine,
    EngineSpin,
    Firing,
    OperatorRefused,
    Outcome,
    SentCommand,
    StepResult,
)
from runtime.eventlog import EventLog
from runtime.link import Connection, Link
from runtime.operator import ACTIONS, OperatorAction, OperatorOutcome
from runtime.protocol import (
    NONCE_SIZE,
    ClockSync,
    Command,
    DatagramReceiver,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    Rejected,
    RejectReason,
    Reply,
    ReplyAck,
    Role,
    StreamCodec,
    StreamMessage,
    TelemetryRecord,
)

__all__ = ["Controller", "ControllerOptions", "RunEnd", "RunResult"]

T = TypeVar("T")


class RunEnd(enum.Enum):
    """How a run ended."""

    FINAL = "final"  # a declared final marking: the mission is over as designed
    DEADLOCK = "deadlock"  # nothing can happen and the marking is not final
    VEHICLE_LOST_MISSION = "vehicle-lost-mission"  # the vehicle no longer knows it
    TIME_LIMIT = "time-limit"  # the run's time limit passed first
    SPIN = "spin"  # the engine fired without end, never waiting for the vehicle (a cycle)
    LOG_BEHIND = "log-behind"  # the vehicle is ahead of the log: it lost its last commits
    STOPPED = "stopped"  # the operator stopped the run (a signal); resume it later


@dataclass(frozen=True)
class ControllerOptions:
    """Timings of the controller, in seconds of the loop's clock.

    Attributes:
        heartbeat_interval: send a heartbeat after this much quiet (also capped at a
            quarter of the vehicle's silence time-out).
        handshake_timeout: how long to wait for the ``HelloReply``; the paper's link
            stalled for up to 7 s each way.
        silence_limit: no valid frame from the vehicle for this long: the connection is
            taken as dead and re-established.
        reconnect_delays: waits between connection attempts, the last one repeated.
        max_rejections: more rejected frames than this within ``rejection_window``
            closes the connection (docs/protocol.md's recommendation).
        rejection_window: see ``max_rejections``.
        status_interval: print the status of the commands in flight this often.
        time_limit: end the run after this long (None: no limit).
        make_safe_timeout: when the run is stopped, how long to wait for the vehicle to
            acknowledge the make-safe request (connecting first if need be).
    """

    heartbeat_interval: float = 1.0
    handshake_timeout: float = 20.0
    silence_limit: float = 15.0
    reconnect_delays: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0)
    max_rejections: int = 16
    rejection_window: float = 60.0
    status_interval: float = 30.0
    time_limit: float | None = None
    make_safe_timeout: float = 5.0


@dataclass
class RunResult:
    """What a run did, for the operator and the tests."""

    end: RunEnd
    marking: dict[str, int]
    started_at: float
    ended_at: float
    commands_sent: int = 0
    commands_resent: int = 0
    replies: int = 0
    duplicate_replies: int = 0
    unexpected_replies: int = 0
    connections: int = 0
    rejected_frames: int = 0
    telemetry: int = 0
    telemetry_rejected: int = 0
    clock_syncs: list[ClockSync] = field(default_factory=list)
    detail: str = ""
    """Why the mission ended so, when there is more to say (a spin: its cycle)."""
    stopped_by: str = ""
    """What stopped the run (``SIGTERM``...), when it ended as ``stopped``."""
    made_safe: bool | None = None
    """Whether the vehicle acknowledged the make-safe request; None when none was sent."""
    mission_time: float = 0.0
    """Seconds from the start of this run to its end (what the console's ``t=`` counts)."""
    deferred_replies: int = 0
    """Replies received while stopping, left unconsumed for ``--resume``."""
    stop_requests: int = 0
    """How many stop requests came (a second one gives up waiting for the vehicle)."""

    @property
    def ok(self) -> bool:
        """True when the mission reached a declared final marking."""
        return self.end is RunEnd.FINAL

    def summary(self) -> str:
        """A few lines for the terminal."""
        return (
            f"mission ended: {self.end.value} in {self.ended_at - self.started_at:.1f} s, "
            f"marking {self.marking}\n"
            f"  {self.commands_sent} commands sent ({self.commands_resent} re-sent), "
            f"{self.replies} replies consumed ({self.duplicate_replies} duplicates ignored, "
            f"{self.unexpected_replies} unexpected), {self.connections} connections, "
            f"{self.rejected_frames} frames rejected, {self.telemetry} telemetry samples"
            + (f"\n  {self.detail}" if self.detail else "")
        )


class _ConnectionLost(Exception):
    """The current connection is gone or must be dropped; the reason is the message."""


class _Interrupted(Exception):
    """The operator asked the run to stop while the controller waited (`request_stop`)."""


class _Woken(Exception):
    """An operator action ended the mission (or spun the engine) while the controller
    waited: the wait is abandoned so the run sees it at once (`Controller.operate`)."""


class _Stopped(Exception):
    """The run was stopped during a live session, and make-safe was tried on it."""


class _MissionLost(Exception):
    """The vehicle no longer knows the mission."""


class _LogBehind(Exception):
    """A reply skipped sequence numbers: the vehicle saw acknowledgements this log lost.

    The controller acknowledges a reply only after committing it, so a gap means the
    log lost commits it had made (a truncated write-ahead log, a restored backup). The
    replies in the gap are gone from the vehicle's ledger: going on would drive the
    mission from a marking the vehicle has left behind."""


#: Rejected telemetry datagrams logged one by one per connection; after that, one
#: summary event per `REJECTION_SUMMARY_S` (a flood of junk must not flood the log).
REJECTIONS_LOGGED = 10
REJECTION_SUMMARY_S = 10.0


def _print(line: str) -> None:
    print(line, flush=True)


class Controller:
    """One mission run: an engine, a link to the vehicle, and the event log.

    Use `Controller.start_new` for a new mission and `Controller.resume` after a crash.

    Args:
        engine: the engine, started (`Engine.start`) or restored.
        link: how to reach the vehicle.
        psk: the pre-shared key.
        log: the event log; the controller commits to it.
        mission_id: the mission's id on the wire (kept in the log).
        consumed: the last reply sequence number consumed (0 for a new mission).
        mission_known: whether the vehicle has already taken this mission (a ``resume``
            it then refuses means it lost the mission).
        hello_sent: whether a `Hello` of this mission may already have reached the
            vehicle: from then on every `Hello` asks to resume, so a vehicle that took
            the mission keeps its reply ledger (and runs no command twice) even if the
            controller died before hearing back.
        options: timings.
        nonces: source of the handshake nonces.
        console: receives human-readable progress lines.
    """

    def __init__(
        self,
        engine: Engine,
        link: Link,
        psk: bytes,
        log: EventLog,
        *,
        mission_id: int,
        consumed: int = 0,
        mission_known: bool = False,
        hello_sent: bool = False,
        options: ControllerOptions | None = None,
        nonces: Callable[[int], bytes] = os.urandom,
        console: Callable[[str], None] = _print,
    ) -> None:
        self.engine = engine
        self.link = link
        self._psk = bytes(psk)
        self.log = log
        self.mission_id = mission_id
        self.consumed = consumed
        self.mission_known = mission_known
        self.hello_sent = hello_sent
        self.options = options or ControllerOptions()
        self._nonces = nonces
        self._console = console
        self._telemetry: DatagramReceiver | None = None
        self._rejections_seen = 0
        self._rejections_unlogged = 0
        self._rejections_since = 0.0
        self._rejections: deque[float] = deque()
        self._last_sent = 0.0
        self._heartbeat_interval = self.options.heartbeat_interval
        self._result: RunResult | None = None
        self._written: set[int] = set()  # command ids written on some connection already
        self._spin: EngineSpin | None = None  # the engine spun: the run is over
        self._epoch: float | None = None  # loop time at which this run started
        self._telemetry_port = 0
        # Stopping: the reason, the wait a stop request cancels, a request not yet acted on.
        self._stop_reason: str | None = None
        self._stop_requests = 0
        self._make_safe_end: float | None = None  # when the make-safe budget runs out
        self._resend_due = 0  # the vehicle's last reply number, until its re-sends begin
        self._waiting: asyncio.Future[object] | None = None
        self._interrupt_pending = False
        self._woken = 0  # operator actions that ended the mission while the run waited
        self._failure: Exception | None = None  # an operator step the log could not take
        self._live: tuple[Connection, StreamCodec] | None = None  # where commands go now
        self._over = False  # `run` is past its end: no operator action is taken

    # ------------------------------------------------------------------ construction

    @classmethod
    def start_new(
        cls,
        engine: Engine,
        link: Link,
        psk: bytes,
        log: EventLog,
        *,
        mission_id: int,
        now: float,
        **kwargs: object,
    ) -> Controller:
        """Start ``engine``'s mission at ``now`` and commit its first step to ``log``."""
        controller = cls(engine, link, psk, log, mission_id=mission_id, **kwargs)  # type: ignore[arg-type]
        controller._epoch = now
        marking = engine.marking_dict()
        try:
            step = engine.start(now)
        except EngineSpin as spin:
            # Nothing was sent: `run` ends at once, and the vehicle never hears of it.
            log.event(now, "mission-start", mission_id=mission_id, marking=marking)
            controller._on_spin(now, spin)
            return controller
        log.event(now, "mission-start", mission_id=mission_id, marking=marking)
        controller._log_step(now, step)
        controller._commit()
        return controller

    @classmethod
    def resume(
        cls,
        engine_factory: Callable[[dict[str, object]], Engine],
        link: Link,
        psk: bytes,
        log: EventLog,
        **kwargs: object,
    ) -> Controller:
        """Continue the mission of ``log`` from its last committed state.

        Args:
            engine_factory: rebuilds the engine from the saved engine state (usually
                ``lambda s: Engine.restore(net, approval, s)``).

        Raises:
            runtime.engine.EngineError: the saved state does not fit the net.
            ValueError: the log has no committed state.
        """
        state = log.checkpoint()
        if state is None:
            raise ValueError(f"{log.path}: no committed state to resume from")
        engine_state = state.get("engine")
        if not isinstance(engine_state, dict):
            raise ValueError(f"{log.path}: the committed state has no engine state")
        engine = engine_factory(engine_state)
        mission_id = state.get("mission_id")
        consumed = state.get("consumed")
        if not isinstance(mission_id, int) or not isinstance(consumed, int):
            raise ValueError(f"{log.path}: the committed state lacks mission_id/consumed")
        controller = cls(
            engine,
            link,
            psk,
            log,
            mission_id=mission_id,
            consumed=consumed,
            mission_known=bool(state.get("mission_known", True)),
            hello_sent=bool(state.get("hello_sent", True)),
            **kwargs,  # type: ignore[arg-type]
        )
        # The dead controller may have written these already: sending them again is a
        # re-send (the vehicle runs each id once either way).
        controller._written = {c.command_id for c in engine.in_flight()}
        return controller

    # ------------------------------------------------------------------ the run

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    def _t(self, when: float) -> float:
        """``when`` (the loop's clock) as mission time: seconds since this run started."""
        if self._epoch is None:
            self._epoch = self._now()
        return when - self._epoch

    def request_stop(self, reason: str) -> None:
        """Stop the run cleanly: no new command, make-safe, commit, end as ``stopped``.

        For signal handlers (``loop.add_signal_handler``): it only records the request
        and cancels the controller's current wait, so it is safe from any callback. A
        second request while stopping gives up waiting for the vehicle's acknowledgement.

        Args:
            reason: what asked (``SIGTERM``...), for the log, the vehicle and the result.
        """
        if self._stop_reason is None:
            self._stop_reason = reason
        self._stop_requests += 1
        waiting = self._waiting
        if waiting is not None and not waiting.done():
            waiting.cancel()
        else:
            self._interrupt_pending = True

    # ------------------------------------------------------------------ operator

    async def operate(self, action: OperatorAction) -> OperatorOutcome:
        """Take one operator action (give an input, pause, resume); says what happened.

        Called in the controller's loop (the live server's handler awaits it), between
        two steps of the run, never inside one. Each action is logged as an ``operator``
        event with its origin and outcome, refused ones too; an accepted ``give`` or
        ``resume`` is then handled as a reply is: its firings and commands are logged and
        committed before any command is written, on the live connection, or, while the
        link is down, on the next one (the commands are in flight in the engine's state).
        An action that ends the mission wakes the run, which ends it the usual way.

        A pause holds only the engine: replies are still consumed, acknowledged and
        logged, heartbeats go on, and a command in flight may still time out.
        """
        if self._over:
            return OperatorOutcome(False, "the run has ended")
        now = self._now()
        step: StepResult | None = None
        spin: EngineSpin | None = None
        try:
            if self._stop_reason is not None:
                raise OperatorRefused("the run is stopping; nothing more is done")
            if self._spin is not None:
                raise OperatorRefused("the engine spun: the run is ending")
            if action.action not in ACTIONS:
                raise OperatorRefused(
                    f"unknown action {action.action!r} (expected {', '.join(ACTIONS)})"
                )
            if action.action == "give":
                if not action.input:
                    raise OperatorRefused("give needs the name of an input")
                was_paused = self.engine.paused
                step = self.engine.give(action.input, now)
                message = f"input {action.input} given" + (
                    "; the engine was paused: resumed, so the mission's response runs"
                    if was_paused
                    else ""
                )
            elif action.action == "pause":
                self.engine.pause()
                message = (
                    "paused: no new command is sent until resume; replies are still "
                    "consumed and logged"
                )
            else:
                step = self.engine.resume(now)
                message = "resumed"
            accepted = True
        except OperatorRefused as refused:
            accepted, message = False, str(refused)
        except EngineSpin as exc:
            accepted, message, spin = True, f"{action.describe()} taken; {exc}", exc
        self.log.event(
            now,
            "operator",
            action=action.action,
            input=action.input,
            origin=action.origin,
            accepted=accepted,
            message=message,
        )
        self._console(
            f"t={self._t(now):.1f} operator {action.describe()} from {action.origin}: "
            + (message if accepted else f"refused: {message}")
        )
        if spin is not None:
            self._on_spin(now, spin)  # logs the spin and commits; nothing is sent
            self._wake()
        elif step is None:
            # A pause is part of the state a resumed run restores (`Engine.restore`).
            self._commit() if accepted else self.log.commit(None)
        else:
            try:
                self._log_step(now, step)
                self._commit()
            except Exception as error:
                # The log cannot take the step (disk full, damaged file): as on a reply,
                # the run must end on it, not go on with a state nobody can resume from.
                # Nothing is sent; the run's loop raises it (`_goes_on`).
                self._failure = error
                self._wake()
                return OperatorOutcome(False, f"the log cannot be written: {error}")
            self._send_step(step)
            if step.outcome is not Outcome.RUNNING:
                self._wake()
        return OperatorOutcome(accepted, message)

    def _send_step(self, step: StepResult) -> None:
        """Write an operator step's commands on the live connection, if there is one.

        Without one (reconnecting, or mid-handshake) they stay in flight and the next
        session sends them with the others; a write that fails leaves them so too."""
        live = self._live
        if live is None or self._result is None:
            return
        conn, codec = live
        for sent in step.commands:
            try:
                self._send_command(conn, codec, sent, resend=sent.command_id in self._written)
            except (ConnectionError, OSError):
                # Close it so the session's reader sees the loss now (a half-dead socket
                # may still read): the next session re-sends every command in flight.
                conn.close()
                return

    def _wake(self) -> None:
        """End the run's current wait: the mission ended (or spun) on an operator action."""
        self._woken += 1
        waiting = self._waiting
        if waiting is not None and not waiting.done() and self._stop_reason is None:
            waiting.cancel()

    def _goes_on(self) -> bool:
        """Whether the run goes on: the engine is running and has not spun; an operator
        step the log could not take ends it with that error."""
        if self._failure is not None:
            raise self._failure
        return self._spin is None and self.engine.outcome() is Outcome.RUNNING

    async def _interruptible(self, aw: Awaitable[T], timeout: float | None = None) -> T:
        """Await ``aw`` (within ``timeout``), or raise `_Interrupted` on a stop request.

        Why a wrapper rather than cancelling the run: the controller must keep its
        connection to send the make-safe request on it, so a stop only ends the wait.
        """
        if self._interrupt_pending:
            self._interrupt_pending = False
            if asyncio.iscoroutine(aw):
                aw.close()
            raise _Interrupted
        fut: asyncio.Future[T] = asyncio.ensure_future(aw)
        self._waiting = fut  # type: ignore[assignment]
        requests = self._stop_requests
        woken = self._woken
        try:
            if timeout is None:
                return await fut
            return await asyncio.wait_for(fut, max(timeout, 0.0))
        except asyncio.CancelledError:
            task = asyncio.current_task()
            outer = task is not None and task.cancelling() > 0
            if fut.cancelled() and not outer:
                if self._stop_requests > requests:
                    raise _Interrupted from None
                if self._woken > woken:
                    raise _Woken from None
            raise
        finally:
            if self._waiting is fut:
                self._waiting = None

    async def run(self) -> RunResult:
        """Drive the mission to its end; returns what happened."""
        now = self._now()
        if self._epoch is None:
            self._epoch = now
        result = self._result = RunResult(RunEnd.FINAL, {}, now, now)
        if self._spin is None:
            await self._run(result, now)
        self._over = True
        if self._spin is not None:
            result.end = RunEnd.SPIN
            result.detail = str(self._spin)
        if result.end is RunEnd.STOPPED:
            if result.made_safe is None:
                result.made_safe = await self._make_safe_anew()
            result.stopped_by = self._stop_reason or "stop request"
        result.stop_requests = self._stop_requests
        result.ended_at = self._now()
        result.mission_time = self._t(result.ended_at)
        result.marking = self.engine.marking_dict()
        self.log.event(
            result.ended_at,
            "mission-end",
            end=result.end.value,
            final=result.end is RunEnd.FINAL,
            marking=result.marking,
            **(
                {"stopped_by": result.stopped_by, "made_safe": result.made_safe}
                if result.end is RunEnd.STOPPED
                else {}
            ),
        )
        if self._spin is None:
            self._commit()
        else:
            # The engine stopped in the middle of a step: its state is no checkpoint. The
            # last one (before the step) stays, with the reply that began it unconsumed.
            self.log.commit(None)
        self._console(result.summary())
        return result

    async def _run(self, result: RunResult, now: float) -> None:
        """Connect, and reconnect, until the mission ends; sets ``result.end``."""
        deadline = None if self.options.time_limit is None else now + self.options.time_limit
        try:
            port = await self.link.open_telemetry(self._on_datagram)
        except OSError as exc:
            # Telemetry is for the operators; the mission runs without it rather than
            # not at all (e.g. --telemetry-host removed from this machine since start-up).
            port = 0
            why = f"no telemetry: cannot open its socket ({exc.strerror or exc})"
            self._note("note", why, detail=why)
        self._telemetry_port = port
        attempt = 0
        try:
            while self._goes_on():
                if deadline is not None and self._now() >= deadline:
                    result.end = RunEnd.TIME_LIMIT
                    break
                try:
                    conn = await self._interruptible(self.link.connect())
                except _Woken:
                    continue  # an operator action ended the mission
                except ConnectionError as exc:
                    delay = self.options.reconnect_delays[
                        min(attempt, len(self.options.reconnect_delays) - 1)
                    ]
                    attempt += 1
                    self._note(
                        "connect-failed",
                        f"cannot reach the vehicle ({exc}); retry in {delay:.1f} s",
                        reason=str(exc),
                    )
                    with contextlib.suppress(_Woken):
                        await self._interruptible(asyncio.sleep(delay))
                    continue
                result.connections += 1
                try:
                    await self._session(conn, port, deadline)
                    attempt = 0
                except _Woken:
                    pass  # an operator action ended the mission during this session
                except _ConnectionLost as exc:
                    self._note("connection-lost", f"connection lost: {exc}", reason=str(exc))
                    attempt += 1
                    delay = self.options.reconnect_delays[
                        min(attempt - 1, len(self.options.reconnect_delays) - 1)
                    ]
                    with contextlib.suppress(_Woken):
                        await self._interruptible(asyncio.sleep(delay))
                finally:
                    conn.close()
            else:
                if self._spin is None:
                    outcome = self.engine.outcome()
                    result.end = RunEnd.FINAL if outcome is Outcome.FINAL else RunEnd.DEADLOCK
        except _MissionLost as exc:
            result.end = RunEnd.VEHICLE_LOST_MISSION
            self._note("mission-lost", str(exc))
        except _LogBehind as exc:
            result.end = RunEnd.LOG_BEHIND
            result.detail = str(exc)
            self._note("log-behind", str(exc))
        except EngineSpin:
            pass  # logged by `_on_reply`; `run` ends the mission as a spin
        except _Stopped:
            result.end = RunEnd.STOPPED  # make-safe was tried on the live connection
        except _Interrupted:
            result.end = RunEnd.STOPPED  # between connections: `run` makes safe anew

    async def _session(self, conn: Connection, port: int, deadline: float | None) -> None:
        """One connection: handshake, re-send, then replies until the mission ends."""
        codec = StreamCodec(self._psk, Role.CONTROLLER, self._nonces(NONCE_SIZE))
        resume = self._asks_resume()
        hello = Hello(codec.nonce, self._now(), self.mission_id, resume, self.consumed, port)
        self._write(conn, codec, hello)
        reply = await self._await_hello_reply(conn, codec)
        now = self._now()
        sync = ClockSync.from_handshake(hello, reply, now)
        assert self._result is not None
        self._result.clock_syncs.append(sync)
        self.log.event(
            now,
            "handshake",
            offset=sync.vehicle_ahead,
            delay=sync.delay,
            resumed=reply.resumed,
            asked_resume=resume,
            vehicle_last_reply_seq=reply.last_reply_seq,
        )
        if resume and not reply.resumed and self.mission_known:
            raise _MissionLost(
                f"the vehicle no longer knows mission {self.mission_id} (it restarted or "
                "ended it, e.g. surfaced after losing the controller): not resuming blind"
            )
        # The vehicle re-sends every reply after ours that is not acknowledged, first thing
        # once it adopts this connection. Had it issued more than we consumed, the next
        # of them must come before anything else: if not, it was acknowledged, so this
        # log lost the commits that consumed it (`_receive`).
        self._resend_due = reply.last_reply_seq if reply.resumed else 0
        assert codec.session_key is not None
        self._telemetry = DatagramReceiver(codec.session_key)
        self._rejections_seen = self._rejections_unlogged = 0
        self._heartbeat_interval = max(
            0.05, min(self.options.heartbeat_interval, reply.silence_timeout / 4)
        )
        self._write(conn, codec, Heartbeat(now))  # proves the connection live
        self._commit()
        for sent in self.engine.in_flight():
            self._send_command(conn, codec, sent, resend=sent.command_id in self._written)
        # From here on, commands an operator action causes go out on this connection at
        # once; before (no connection, or the handshake), they wait in flight and the
        # loop above sends them on the next connection: none is lost.
        self._live = (conn, codec)
        self._console(
            f"t={self._t(now):.1f} connected (one-way delay {sync.delay * 1000:.0f} ms, "
            f"vehicle clock at {sync.to_vehicle(now):.3f} s); "
            f"{len(self.engine.in_flight())} commands in flight"
        )
        heartbeats = asyncio.create_task(self._heartbeats(conn, codec))
        try:
            await self._receive(conn, codec, deadline)
        except _Interrupted:
            self._live = None
            assert self._result is not None
            self._result.made_safe = await self._make_safe(
                conn, codec, self.options.make_safe_timeout
            )
            raise _Stopped from None
        finally:
            self._live = None
            heartbeats.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await heartbeats

    async def _await_hello_reply(self, conn: Connection, codec: StreamCodec) -> HelloReply:
        end = self._now() + self.options.handshake_timeout
        while True:
            left = end - self._now()
            if left <= 0:
                raise _ConnectionLost("no HelloReply in time")
            try:
                data = await self._interruptible(conn.read(), left)
            except TimeoutError:
                raise _ConnectionLost("no HelloReply in time") from None
            if not data:
                raise _ConnectionLost("closed during the handshake")
            for item in codec.feed(data):
                if isinstance(item, HelloReply):
                    return item
                self._rejected_or_early(item)

    def _rejected_or_early(self, item: StreamMessage | Rejected) -> None:
        if isinstance(item, Rejected):
            self._on_rejected(item)

    async def _receive(self, conn: Connection, codec: StreamCodec, deadline: float | None) -> None:
        silence = self.options.silence_limit
        status_every = self.options.status_interval
        next_status = self._now() + status_every
        while self._goes_on():
            now = self._now()
            if deadline is not None and now >= deadline:
                return
            wait = silence if deadline is None else min(silence, deadline - now)
            try:
                data = await self._interruptible(conn.read(), wait)
            except TimeoutError:
                if deadline is not None and self._now() >= deadline:
                    return
                raise _ConnectionLost(
                    f"nothing valid from the vehicle for {silence:.0f} s"
                ) from None
            if not data:
                raise _ConnectionLost("closed by the peer or the network")
            valid = False
            for item in codec.feed(data):
                if isinstance(item, Rejected):
                    self._on_rejected(item)
                    continue
                valid = True
                if isinstance(item, Reply):
                    self.mission_known = True
                    self._resend_due = 0
                    self._on_reply(conn, codec, item)
                elif isinstance(item, Heartbeat):
                    self.mission_known = True
                    if self._resend_due > self.consumed:
                        raise _LogBehind(
                            f"the vehicle has issued replies up to #{self._resend_due} but "
                            f"re-sent none after #{self.consumed}: it had them acknowledged, "
                            "so the log lost its last commits; the mission's state is unknown "
                            "here: take over the vehicle by hand, do not resume from this log"
                        )
            if not valid:
                # Only garbage arrived: it must not keep a dead connection alive forever.
                continue
            if self._now() >= next_status:
                next_status = self._now() + status_every
                for line in self.status():
                    self._console(f"  {line}")

    def _on_reply(self, conn: Connection, codec: StreamCodec, reply: Reply) -> None:
        assert self._result is not None
        now = self._now()
        if reply.reply_seq > self.consumed + 1:
            raise _LogBehind(
                f"the vehicle sent reply #{reply.reply_seq} but this log consumed replies "
                f"only up to #{self.consumed}: the vehicle had #{self.consumed + 1}.."
                f"#{reply.reply_seq - 1} acknowledged, so the log lost its last commits; "
                "the mission's state is unknown here: take over the vehicle by hand, do not "
                "resume from this log"
            )
        if reply.reply_seq <= self.consumed:
            self._result.duplicate_replies += 1
            self._write(conn, codec, ReplyAck(self.consumed))
            return
        try:
            step = self.engine.on_reply(reply.command_id, reply.kind, now)
        except EngineSpin as spin:
            # The reply is logged, not acknowledged: the checkpoint keeps it unconsumed.
            self.log.event(
                now,
                "reply",
                command_id=reply.command_id,
                reply_seq=reply.reply_seq,
                kind=reply.kind,
                vehicle_time=reply.vehicle_time,
                detail=reply.detail,
                transition=spin.prefix[0].transition if spin.prefix else None,
            )
            self._result.replies += 1
            self._on_spin(now, spin)
            raise
        transition = step.firings[0].transition if step.firings else None
        self.log.event(
            now,
            "reply",
            command_id=reply.command_id,
            reply_seq=reply.reply_seq,
            kind=reply.kind,
            vehicle_time=reply.vehicle_time,
            detail=reply.detail,
            transition=transition,
        )
        self._result.replies += 1
        if step.unexpected is not None:
            self._result.unexpected_replies += 1
            self._note(
                "reply-unexpected",
                f"reply #{reply.reply_seq} '{reply.kind}' for command {reply.command_id} "
                f"ignored: {step.unexpected.reason}",
                command_id=reply.command_id,
            )
        else:
            self._console(
                f"t={self._t(now):.1f} #{reply.command_id} replied {reply.kind}"
                + (f" ({reply.detail})" if reply.detail else "")
            )
        self.consumed = reply.reply_seq
        self._log_step(now, step)
        self._commit()
        self._write(conn, codec, ReplyAck(self.consumed))
        for sent in step.commands:
            self._send_command(conn, codec, sent, resend=sent.command_id in self._written)

    def _send_command(
        self, conn: Connection, codec: StreamCodec, sent: SentCommand, *, resend: bool
    ) -> None:
        assert self._result is not None
        params = dict(sent.command.params)
        self._write(conn, codec, Command(sent.command_id, sent.command.name, sent.sent_at, params))
        self._written.add(sent.command_id)
        if resend:
            self._result.commands_resent += 1
            self.log.event(self._now(), "command-resent", command_id=sent.command_id)
        else:
            self._result.commands_sent += 1
            self._console(
                f"t={self._t(sent.sent_at):.1f} #{sent.command_id} {sent.transition}: "
                f"{sent.command.header()}"
            )

    def _log_step(self, now: float, step: StepResult) -> None:
        self._log_firings(now, step.firings)
        for sent in step.commands:
            self.log.event(
                now,
                "command-sent",
                command_id=sent.command_id,
                transition=sent.transition,
                name=sent.command.name,
                params=dict(sent.command.params),
                resources=list(sent.command.resources),
                timeout_at=sent.timeout_at,
            )

    def _log_firings(self, now: float, firings: tuple[Firing, ...]) -> None:
        for firing in firings:
            self.log.event(now, "fire", transition=firing.transition, command_id=firing.command_id)

    def _on_spin(self, now: float, spin: EngineSpin) -> None:
        """The engine spun: log how it got into the cycle, and the cycle; nothing is sent.

        The commands the step emitted before the engine gave up are never sent; the
        vehicle carries on with what it was told, until its watchdog surfaces it.
        """
        self._spin = spin
        self._log_firings(now, spin.prefix)
        self.log.event(now, "engine-spin", **spin.to_json())
        self.log.commit(None)
        self._console(f"t={self._t(now):.1f} {spin}")

    # ------------------------------------------------------------------ stopping

    async def _make_safe(self, conn: Connection, codec: StreamCodec, timeout: float) -> bool | None:
        """Ask the vehicle to make itself safe; True once it acknowledged within ``timeout``,
        False when it did not (or a second stop request ended the wait), None when the
        connection was lost first: then `run` asks again on a new one, within what is
        left of the same ``make_safe_timeout``.

        Replies that arrive meanwhile (the stopped commands' ``timeout`` and ``error``
        among them) are neither consumed nor acknowledged: the vehicle keeps them, and
        ``--resume`` consumes them in order. A second stop request ends the wait.
        """
        assert self._result is not None
        reason = self._stop_reason or "stop request"
        request_id = int.from_bytes(self._nonces(4), "big")
        now = self._now()
        end = now + timeout
        if self._make_safe_end is None:
            self._make_safe_end = end
        try:
            self._write(conn, codec, MakeSafe(request_id, now, reason))
        except (ConnectionError, OSError) as exc:
            self._note("make-safe-failed", f"make-safe not sent: {exc}", reason=str(exc))
            return None
        self.log.event(now, "make-safe-sent", request_id=request_id, reason=reason)
        self.log.commit(None)
        self._console(
            f"t={self._t(now):.1f} stopping ({reason}): asked the vehicle to make itself safe; "
            f"waiting up to {timeout:.1f} s for its acknowledgement"
        )
        while (left := end - self._now()) > 0:
            try:
                data = await self._interruptible(conn.read(), left)
            except TimeoutError:
                break
            except _Interrupted:
                self._note("make-safe-abandoned", "second stop request: not waiting any longer")
                return False
            if not data:
                self._note(
                    "make-safe-failed", "connection lost before the make-safe acknowledgement"
                )
                return None
            for item in codec.feed(data):
                if isinstance(item, MakeSafeAck) and item.request_id == request_id:
                    self.log.event(
                        self._now(),
                        "make-safe-acked",
                        request_id=request_id,
                        vehicle_time=item.vehicle_time,
                        first=item.first,
                    )
                    return True
                if isinstance(item, Reply):
                    self._result.deferred_replies += 1
                elif isinstance(item, Rejected):
                    self._result.rejected_frames += 1
                    self.log.event(
                        self._now(), "rejected", reason=item.reason.value, detail=item.detail
                    )
        self._note(
            "make-safe-unacknowledged",
            f"the vehicle did not acknowledge make-safe within {timeout:.1f} s",
        )
        return False

    async def _make_safe_anew(self) -> bool:
        """Make-safe when the stop came between connections: connect, shake hands, ask.

        All within ``make_safe_timeout``. The request goes only on a connection the
        vehicle resumed the mission on (or a mission it never had): a vehicle that lost
        the mission is left alone, so as not to start a new one under its id.
        """
        budget = self.options.make_safe_timeout
        if self._make_safe_end is not None:  # a first try lost its connection
            budget = max(0.0, self._make_safe_end - self._now())
        end = self._now() + budget
        conn: Connection | None = None
        try:
            conn = await self._interruptible(self.link.connect(), budget)
            codec = StreamCodec(self._psk, Role.CONTROLLER, self._nonces(NONCE_SIZE))
            resume = self._asks_resume()
            hello = Hello(
                codec.nonce,
                self._now(),
                self.mission_id,
                resume,
                self.consumed,
                self._telemetry_port,
            )
            self._write(conn, codec, hello)
            reply = await self._interruptible(
                self._await_hello_reply(conn, codec), end - self._now()
            )
            if resume and not reply.resumed and self.mission_known:
                self._note(
                    "make-safe-failed",
                    "make-safe not sent: the vehicle no longer knows the mission",
                )
                return False
            return await self._make_safe(conn, codec, max(0.0, end - self._now())) is True
        except (ConnectionError, OSError, TimeoutError, _ConnectionLost) as exc:
            self._note(
                "make-safe-failed",
                f"make-safe not sent: cannot reach the vehicle ({exc or 'no answer in time'})",
                reason=str(exc),
            )
            return False
        except _Interrupted:
            self._note("make-safe-abandoned", "second stop request: not trying any longer")
            return False
        finally:
            if conn is not None:
                conn.close()

    def _asks_resume(self) -> bool:
        """Whether the next `Hello` asks to resume; commits that one is on its way.

        A `Hello` that does not ask makes the vehicle start the mission afresh, with a new
        reply ledger. Once a `Hello` may have reached it, that would run again every
        command the vehicle already carried out: a controller killed after sending INIT
        but before any reply or heartbeat came back (so before ``mission_known``) used to
        do exactly that on ``--resume``. So the first `Hello` of a mission is committed as
        sent before it is written, and every later one asks; a vehicle that never took
        the mission answers "not resumed" and starts it, which is then right.
        """
        resume = self.mission_known or self.consumed > 0 or self.hello_sent
        if not self.hello_sent:
            self.hello_sent = True
            self._commit()
        return resume

    def _commit(self) -> None:
        self.log.commit(
            {
                "engine": self.engine.snapshot(),
                "mission_id": self.mission_id,
                "consumed": self.consumed,
                "mission_known": self.mission_known,
                "hello_sent": self.hello_sent,
            }
        )

    async def _heartbeats(self, conn: Connection, codec: StreamCodec) -> None:
        # Sleep until the heartbeat is due; "due" allows a millisecond of slack, because a
        # sleep of the remaining 1e-16 s does not move a clock that reads 1e3 s.
        while not conn.closed:
            due = self._last_sent + self._heartbeat_interval
            if self._now() >= due - 1e-3:
                self._write(conn, codec, Heartbeat(self._now()))
                due = self._last_sent + self._heartbeat_interval
            await asyncio.sleep(due - self._now())
            self.log.commit(None)  # telemetry and notes reach the disk once a beat

    def _write(self, conn: Connection, codec: StreamCodec, msg: StreamMessage) -> None:
        conn.write(codec.encode(msg))
        self._last_sent = self._now()

    # ------------------------------------------------------------------ bad input

    def _on_rejected(self, item: Rejected) -> None:
        assert self._result is not None
        self._result.rejected_frames += 1
        now = self._now()
        self.log.event(now, "rejected", reason=item.reason.value, detail=item.detail)
        if item.reason in (RejectReason.NO_SESSION, RejectReason.UNEXPECTED):
            raise _ConnectionLost(
                f"the vehicle disagrees about the handshake ({item.reason.value})"
            )
        window = self._rejections
        window.append(now)
        while window and window[0] < now - self.options.rejection_window:
            window.popleft()
        if len(window) > self.options.max_rejections:
            window.clear()
            raise _ConnectionLost(
                f"more than {self.options.max_rejections} rejected frames within "
                f"{self.options.rejection_window:.0f} s"
            )

    def _on_datagram(self, data: bytes) -> None:
        receiver = self._telemetry
        result = self._result
        if receiver is None or result is None:
            return
        item = receiver.accept(data)
        if isinstance(item, TelemetryRecord):
            result.telemetry += 1
            self.log.telemetry(item)  # the record decoded is the record logged
        else:
            result.telemetry_rejected += 1
            if item.reason is not RejectReason.LATE:
                self._log_rejected_datagram(item.reason.value)

    def _log_rejected_datagram(self, reason: str) -> None:
        """The first few rejections one by one, then a count every few seconds."""
        now = self._now()
        self._rejections_seen += 1
        if self._rejections_seen <= REJECTIONS_LOGGED:
            self.log.event(now, "telemetry-rejected", reason=reason)
            self._rejections_since = now
            return
        self._rejections_unlogged += 1
        if now - self._rejections_since >= REJECTION_SUMMARY_S:
            self.log.event(
                now, "telemetry-rejected", reason=reason, count=self._rejections_unlogged
            )
            self._rejections_unlogged = 0
            self._rejections_since = now

    # ------------------------------------------------------------------ status

    def status(self) -> list[str]:
        """One line per command in flight: sent when, awaiting what, time-out when."""
        now = self._now()
        return [s.line(now) for s in self.engine.status()]

    def _note(self, kind: str, text: str, **data: object) -> None:
        now = self._now()
        self.log.event(now, kind, **data)
        self._console(f"t={self._t(now):.1f} {text}")
