"""The simple temporal network of a partial plan, extended one step at a time.

Each step of the totally ordered snap-action plan is a time point. A step must follow
(by epsilon) every earlier step it interferes with; an end follows its start by the
duration; a timed literal sits at its fixed time. Steps that do not interfere get no
ordering, so the earliest times computed here are the plan lifted to a partial order
and compressed. The network is consistent iff the longest-path propagation settles;
a positive cycle (for instance an end pushed past its maximum duration) makes it
inconsistent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cbdi_planner.task import Snap

__all__ = ["END", "INST", "START", "TIL", "Step", "Timeline"]

START, END, INST, TIL = 0, 1, 2, 3
_TOL = 1e-9
ORIGIN = -1


@dataclass(frozen=True, slots=True)
class Step:
    """One happening of a plan; `partner` is the start step of an end (else -1).

    `low`/`high` bound the distance from `partner` (the duration); for a timed literal
    both are its time and the partner is the origin.
    """

    kind: int
    action: int
    snap: Snap
    partner: int = ORIGIN
    low: float = 0.0
    high: float = math.inf


def interferes(a: Snap, b: Snap) -> bool:
    """Tell whether two happenings must be ordered (PDDL 2.1 mutex, conservatively)."""
    return bool(
        (a.writes & b.reads)
        or (a.reads & b.writes)
        or (a.add & b.dele)
        or (a.dele & b.add)
        or (a.num_writes & (b.num_reads | b.num_writes))
        or (a.num_reads & b.num_writes)
    )


@dataclass(frozen=True, slots=True)
class Timeline:
    """Steps, their incoming ordering edges and their earliest consistent times."""

    steps: tuple[Step, ...] = ()
    edges: tuple[tuple[tuple[int, float], ...], ...] = ()
    times: tuple[float, ...] = ()
    epsilon: float = 0.001

    @property
    def makespan(self) -> float:
        """Return the latest time of an action step (a lower bound for any extension)."""
        return max(
            (t for t, s in zip(self.times, self.steps, strict=True) if s.kind != TIL), default=0.0
        )

    def extend(self, step: Step) -> Timeline | None:
        """Return the timeline with `step` appended, or None if it is inconsistent."""
        eps = self.epsilon
        incoming = [(i, eps) for i, old in enumerate(self.steps) if interferes(old.snap, step.snap)]
        if step.kind == END:
            incoming.append((step.partner, step.low))
        edges = (*self.edges, tuple(incoming))
        steps = (*self.steps, step)
        times = [*self.times, 0.0]
        n = len(steps) - 1
        times[n] = self._base(step, incoming, times)
        if not _settle(steps, edges, times, n):
            return None
        return Timeline(steps, edges, tuple(times), eps)

    @staticmethod
    def _base(step: Step, incoming: list[tuple[int, float]], times: list[float]) -> float:
        value = step.low if step.kind == TIL else 0.0
        for i, w in incoming:
            if times[i] + w > value:
                value = times[i] + w
        return value


def _settle(
    steps: tuple[Step, ...],
    edges: tuple[tuple[tuple[int, float], ...], ...],
    times: list[float],
    first: int,
) -> bool:
    """Propagate earliest times from step `first` on; False on a positive cycle."""
    for _ in range(len(steps) + 1):
        for k in range(first, len(steps)):
            value = times[k]
            for i, w in edges[k]:
                if times[i] + w > value:
                    value = times[i] + w
            times[k] = value
        lowest = len(steps)
        for k, step in enumerate(steps):
            if step.kind == TIL:
                if times[k] > step.high + _TOL:
                    return False
            elif step.kind == END and times[k] - times[step.partner] > step.high + _TOL:
                times[step.partner] = times[k] - step.high
                lowest = min(lowest, step.partner)
        if lowest == len(steps):
            return True
        first = lowest
    return False
