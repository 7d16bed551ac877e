"""Pay for an offline search epoch by epoch, as it runs (virtual time).

A plan-then-act robot's search is charged to simulated time at the epoch's expansion
budget: the plan goes out in the epoch by which its expansions are paid off. Running the
whole search inside one epoch would hold that epoch for as long as the search takes on
the wall (minutes on a 30x30 map), past every member's ack timeout. A `Pacer` lets the
search thread (`search.Budget.pace`) expand only what the epochs so far have paid for:
each epoch `pay(n)` releases `n` more expansions and waits until the search has used them
or ended. The plan then goes out in exactly the epoch the whole search would have been
paid off in, and no epoch takes longer than its own budget's expansions.
"""

from __future__ import annotations

import threading

from cbdi_planner.errors import SearchTimeout

__all__ = ["Pacer"]


class Pacer:
    """The expansions a search thread may make, released epoch by epoch."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self.allowed = 0
        self.used = 0
        self.ended = False
        self.cancelled = False

    def pace(self, expanded: int) -> None:
        """Search thread, before expansion number `expanded`: wait until it is paid for;
        raise SearchTimeout once cancelled."""
        with self._cond:
            self.used = expanded - 1
            self._cond.notify_all()
            while expanded > self.allowed and not self.cancelled:
                self._cond.wait()
            if self.cancelled:
                raise SearchTimeout("the search was cancelled")
            self.used = expanded

    def end(self) -> None:
        """Search thread: the search is over (whatever its outcome)."""
        with self._cond:
            self.ended = True
            self._cond.notify_all()

    def pay(self, expansions: int) -> bool:
        """Release `expansions` more and wait (blocking: call from a worker thread) until
        the search used them all or ended; return whether it ended."""
        with self._cond:
            self.allowed += expansions
            self._cond.notify_all()
            while not self.ended and self.used < self.allowed:
                self._cond.wait()
            return self.ended

    def cancel(self) -> None:
        """Stop the search at its next expansion."""
        with self._cond:
            self.cancelled = True
            self._cond.notify_all()
