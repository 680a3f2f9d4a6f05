"""The vehicle's reply ledger: the delivery rules of ``docs/protocol.md`` in one class.

Every vehicle server keeps one `ReplyLedger` per mission, so each gets the rules right the
same way: run a command id once, number replies, keep them until acknowledged, re-send.
"""

from __future__ import annotations

from runtime.protocol.messages import Reply

__all__ = ["ReplyLedger"]


class ReplyLedger:
    """The vehicle's record of one mission: which commands ran, which replies are unacked.

    It implements the delivery rules of docs/protocol.md so that every vehicle server gets
    them right: run each command id once; number replies 1, 2, 3...; keep each until the
    controller's cumulative `ReplyAck` covers it; re-send the unacknowledged ones after a
    resume, and a command's replies again when its id arrives twice.

    Args:
        mission_id: the `Hello.mission_id` this ledger belongs to.
    """

    def __init__(self, mission_id: int) -> None:
        self.mission_id = mission_id
        self._seen: set[int] = set()
        self._unacked: dict[int, Reply] = {}  # reply_seq -> reply, in issue order
        self.last_reply_seq = 0
        """Highest reply sequence number issued."""
        self.acked_seq = 0
        """Highest reply sequence number the controller has acknowledged."""

    def first_time(self, command_id: int) -> bool:
        """Record ``command_id``; True if it is new (run it), False if a repeat (do not)."""
        if command_id in self._seen:
            return False
        self._seen.add(command_id)
        return True

    def issue(self, command_id: int, kind: str, vehicle_time: float, detail: str = "") -> Reply:
        """A new reply with the next sequence number, kept until acknowledged."""
        self.last_reply_seq += 1
        reply = Reply(self.last_reply_seq, command_id, kind, vehicle_time, detail)
        self._unacked[reply.reply_seq] = reply
        return reply

    def acknowledge(self, reply_seq: int) -> None:
        """Forget every reply up to ``reply_seq`` (cumulative; stale acks are harmless)."""
        reply_seq = min(reply_seq, self.last_reply_seq)
        if reply_seq <= self.acked_seq:
            return
        self.acked_seq = reply_seq
        for seq in [s for s in self._unacked if s <= reply_seq]:
            del self._unacked[seq]

    def unacknowledged(self, after: int = 0) -> list[Reply]:
        """Replies still unacknowledged with a sequence number above ``after``, in order.

        After a resume, call ``acknowledge(hello.last_reply_seq)`` and re-send these.
        """
        return [r for s, r in self._unacked.items() if s > after]

    def replies_for(self, command_id: int) -> list[Reply]:
        """The unacknowledged replies already issued for ``command_id`` (re-send on a repeat)."""
        return [r for r in self._unacked.values() if r.command_id == command_id]
