"""Telling a peer that (re)appeared from one that came back with our own session (`Peers`).

A liveliness token vanishes when its holder dies, and also, for a client, when the
client's own link to the router goes: then every token vanishes at once, ours too, and
comes back when the session reconnects. What a peer sent meanwhile is recovered (the
bus's advanced pub/sub), so a peer back with our session must not be treated as one
that restarted (planned again, sent everything again).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from cbdi.bus.base import AliveEvent

__all__ = ["Appearance", "Peers"]

# first: seen for the first time; again: back after it vanished on its own (restarted);
# reconnected: back after our own token vanished too (the bus went, not the peer).
Appearance = Literal["first", "again", "reconnected"]


@dataclass
class Peers:
    """Follow liveliness events of peers and of our own token `me`."""

    me: str
    seen: set[str] = field(default_factory=set)
    lost: set[str] = field(default_factory=set)  # vanished with our session

    def observe(self, event: AliveEvent) -> Appearance | None:
        """Return how a peer appeared, or None (a token vanished, or ours)."""
        if event.key == self.me:
            if not event.alive:
                self.lost = set(self.seen)
            return None
        if not event.alive:
            return None
        if event.key in self.lost:
            self.lost.discard(event.key)
            return "reconnected"
        appearance: Appearance = "again" if event.key in self.seen else "first"
        self.seen.add(event.key)
        return appearance
