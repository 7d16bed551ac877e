"""How late a paced world had its epochs out (`Lateness`), for the run's summary.

A world paced on the wall clock (`--speed` above 0) owes epoch k at its start plus k
epochs' wall duration. What reaches the agents late is what they act on late: each
epoch's lateness is the wall time from its due time to the end of its publication. A
world that keeps pace has them near 0; one starved of CPU (or waiting for lockstep acks)
shows it here. Pure: the service hands in the times.
"""

from __future__ import annotations

import math
import statistics

from cbdi.wire.common import EpochLateness

__all__ = ["BOUND", "Lateness"]

BOUND = 0.1  # an epoch later than this share of its wall duration counts as `over`


class Lateness:
    """The lateness of every epoch of a run paced at `epoch_wall` wall seconds each."""

    def __init__(self, epoch_wall: float) -> None:
        if not (math.isfinite(epoch_wall) and epoch_wall >= 0):
            raise ValueError(f"an epoch's wall duration must be finite and >= 0, got {epoch_wall}")
        self.epoch_wall = epoch_wall
        self.late: list[float] = []

    def observe(
        self, due: float, out: float, woke: float | None = None, begin: float | None = None
    ) -> dict[str, float] | None:
        """Note an epoch due at wall time `due` whose publication ended at `out`. If it
        is over the bound (`BOUND` of an epoch), return its lateness (`seconds`) and,
        given when the world woke to step it (`woke`) and began to publish (`begin`),
        where the time went: `woke` late, the simulator's `step`, the `publish`."""
        if self.epoch_wall <= 0:
            return None
        late = max(0.0, out - due)
        self.late.append(late)
        if late <= BOUND * self.epoch_wall:
            return None
        parts = {"seconds": late}
        if woke is not None and begin is not None:
            parts |= {"woke": woke - due, "step": begin - woke, "publish": out - begin}
        return {k: round(v, 4) for k, v in parts.items()}

    def summary(self) -> EpochLateness | None:
        """The distribution so far; None for a run not paced (flat out) or no epoch yet."""
        late = sorted(self.late)
        if not late:
            return None
        bound = BOUND * self.epoch_wall
        p95 = late[min(len(late) - 1, math.ceil(0.95 * len(late)) - 1)]
        return EpochLateness(
            epochs=len(late),
            median=round(statistics.median(late), 6),
            p95=round(p95, 6),
            max=round(late[-1], 6),
            bound=round(bound, 6),
            over=sum(1 for t in late if t > bound),
        )
