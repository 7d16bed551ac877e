"""The world's request trace: what every agent asked for, epoch by epoch (`RequestTrace`).

Two runs are the same run when their traces are equal. Requests of one epoch are sorted
(agents act side by side, so their arrival order is not part of the run); the digest is a
SHA-256 chained epoch by epoch (each epoch's hash covers the digest before it and that
epoch's sorted entries), so a whole run compares by one string. The trace is plain data
(the running digest as bytes, not a hash object), so it goes into the world's state file
(`cbdi_world.recovery`) and a restarted world carries it on.

Actions a robot's own process performs (`cbdi.robot`) never reach the world as requests:
their outcomes (epoch, agent, action, how it ended) are folded in at the end, sorted, so
a run whose actions are all performed outside the world still has a digest that tells
two runs apart. A run without them has the digest of its requests alone, as before.
"""

from __future__ import annotations

import hashlib
import json

from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest

__all__ = ["RequestTrace"]


class RequestTrace:
    """Fold each served request into a running digest, epoch by epoch."""

    def __init__(self) -> None:
        self._digest = b""
        self._epoch = -1
        self._pending: list[str] = []
        self._performed: list[str] = []  # outcomes of actions performed outside the world
        self.count = 0

    def record(self, epoch: int, req: ActionRequest, reply: ActionReply) -> None:
        """Note one request (served in `epoch`) and whether the world accepted it."""
        if epoch != self._epoch:
            self._flush()
            self._epoch = epoch
        target = list(req.target) if req.target is not None else None
        entry = [epoch, req.agent, req.action, target, req.item, reply.accepted]
        self._pending.append(json.dumps(entry))
        self.count += 1

    def performed(self, outcome: ActionOutcome) -> None:
        """Note how an action a robot's own process performed ended."""
        entry = [outcome.epoch, outcome.agent, outcome.action, outcome.status, outcome.reason]
        self._performed.append(json.dumps(entry))

    def _flush(self) -> None:
        if not self._pending:
            return
        h = hashlib.sha256(self._digest)
        for line in sorted(self._pending):
            h.update(line.encode() + b"\n")
        self._digest = h.digest()
        self._pending = []

    def digest(self) -> str:
        """Return the digest of everything recorded so far."""
        self._flush()
        performed = getattr(self, "_performed", [])  # a state file from before them
        if performed:
            h = hashlib.sha256(self._digest)
            for line in sorted(performed):
                h.update(line.encode() + b"\n")
            return h.hexdigest()
        return self._digest.hex() if self._digest else hashlib.sha256().hexdigest()
