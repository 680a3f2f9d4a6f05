"""What an operator can ask of a running mission, and what comes back.

Three actions, from the watch page, from ``coral-run operate`` or from a test:

* ``give NAME``: give the operator input ``NAME`` the mission declares (``input NAME``
  in the mission, e.g. ``abort_requested``): the engine fires its input transition, so
  the mission's own net decides what an abort does, and analysis has verified it;
* ``pause``: the engine fires none of its own transitions (so no new command is sent);
  replies still come in, fire their reply transitions and are logged;
* ``resume``: the engine goes on from where it is.

Every action carries its *origin* (who asked, from where: ``page 10.0.0.7:51234``,
``cli 127.0.0.1:40022``) and is logged with its time and outcome, accepted or not.

Import rule: standard library only, so the server, the controller and the command-line
client share these types without importing one another.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Final, Literal

__all__ = ["ACTIONS", "Action", "Operate", "OperatorAction", "OperatorOutcome"]

Action = Literal["give", "pause", "resume"]
ACTIONS: Final[tuple[Action, ...]] = ("give", "pause", "resume")


@dataclass(frozen=True)
class OperatorAction:
    """One request of an operator: ``action``, the input for ``give``, and its origin."""

    action: Action
    origin: str
    input: str | None = None

    def describe(self) -> str:
        return f"give {self.input}" if self.action == "give" else self.action

    def to_json(self) -> dict[str, object]:
        return {"action": self.action, "input": self.input, "origin": self.origin}


@dataclass(frozen=True)
class OperatorOutcome:
    """Whether the action was taken, and a line saying what happened or why not (the
    input is not declared, already given, the run has ended, not paused...)."""

    accepted: bool
    message: str

    def to_json(self) -> dict[str, object]:
        return {"accepted": self.accepted, "message": self.message}


Operate = Callable[[OperatorAction], Awaitable[OperatorOutcome]]
"""How a server hands an action to the controller running the mission (in its loop)."""
