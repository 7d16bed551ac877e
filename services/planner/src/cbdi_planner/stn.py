"""The simple temporal network of a partial plan, extended one step at a time.

Each step of the totally ordered snap-action plan is a time point. A step must follow
(by epsilon) every earlier step it interferes with; an end follows its start by the
duration; a timed literal sits at its fixed time. Steps that do not interfere get no
ordering, so the earliest times computed here are the plan lifted to a partial order
and compressed. The network is consistent iff the longest-path propagation settles;
a positive cycle (for instance an end pushed past its maximum duration) makes it
inconsistent.

Happenings that are certain to come later are checked too, so that a dead end shows
as soon as it is made rather than when the search finally appends them: the end of
every running action (it must follow each step it interferes with, yet come within
its maximum duration of its start) and every timed literal still to happen (each step
it interferes with must come before its fixed time).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, cast

from cbdi_planner.task import Snap, bit_positions

__all__ = ["END", "INST", "START", "TIL", "Future", "Oracle", "Step", "Timeline"]

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


def _interfering(steps: tuple[Step, ...], b: Snap) -> list[int]:
    """Return the indexes of the steps that interfere with `b` (`interferes`, inlined)."""
    reads, writes, add, dele = b.reads, b.writes, b.add, b.dele
    num_reads, num_writes = b.num_reads, b.num_writes
    num_any = num_reads | num_writes
    out = []
    for k, old in enumerate(steps):
        a = old.snap
        if (
            (a.writes & reads)
            or (a.reads & writes)
            or (a.add & dele)
            or (a.dele & add)
            or (a.num_writes & num_any)
            or (a.num_reads & num_writes)
        ):
            out.append(k)
    return out


class Oracle:
    """The compiled core's simple temporal networks (`cbdi_planner.core`).

    Each snap gets a code the first time a step of it is scheduled (looked up by its
    identity: the task's snaps live as long as the search).
    """

    def __init__(self, core: ModuleType) -> None:
        self.core = core.Interference()
        self._schedule = core.Schedule
        self._codes: dict[int, int] = {}
        self._snaps: list[Snap] = []  # kept alive, so that no other snap takes an id

    def empty(self) -> Any:
        """Return the compiled network of no step."""
        return self._schedule()

    def code(self, snap: Snap) -> int:
        """Return the code of `snap`, given it now if it has none."""
        found = self._codes.get(id(snap))
        if found is None:
            masks = (snap.reads, snap.writes, snap.add, snap.dele, snap.num_reads, snap.num_writes)
            found = int(self.core.add(*(bit_positions(m) for m in masks)))
            self._codes[id(snap)] = found
            self._snaps.append(snap)
        return found


@dataclass(frozen=True, slots=True)
class _Net:
    """The Python core's network: each step's incoming edges, the earliest times."""

    edges: tuple[tuple[tuple[int, float], ...], ...] = ()
    times: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class Timeline:
    """Steps, their incoming ordering edges and their earliest consistent times.

    `net` holds the numbers: the Python core's (`_Net`), or with an `oracle` the
    compiled core's network, which does exactly what `extend` does here.
    """

    steps: tuple[Step, ...] = ()
    net: Any = field(default_factory=_Net, compare=False)
    epsilon: float = 0.001
    span: float = 0.0
    oracle: Oracle | None = field(default=None, compare=False)

    @staticmethod
    def start(epsilon: float, oracle: Oracle | None = None) -> Timeline:
        """Return the timeline of no step (on the compiled core with an oracle)."""
        net = oracle.empty() if oracle is not None else _Net()
        return Timeline(net=net, epsilon=epsilon, oracle=oracle)

    @property
    def times(self) -> Sequence[float]:
        """Each step's earliest time (a copy on the compiled core: read it once)."""
        return cast(Sequence[float], self.net.times)

    @property
    def edges(self) -> Sequence[Sequence[tuple[int, float]]]:
        """Each step's incoming edges `(earlier step, least distance)`."""
        return cast(Sequence[Sequence[tuple[int, float]]], self.net.edges)

    @property
    def makespan(self) -> float:
        """Return the latest time of an action step (a lower bound for any extension)."""
        return self.span

    def extend(self, step: Step, future: Future | None = None) -> Timeline | None:
        """Return the timeline with `step` appended, or None if it is inconsistent.

        `future` lists the happenings still to come after `step` (the ends of the
        actions running after it, the timed literals not yet happened).
        """
        if self.oracle is not None:
            return self._extend_compiled(step, future, self.oracle)
        eps = self.epsilon
        incoming = [(i, eps) for i in _interfering(self.steps, step.snap)]
        if step.kind == END:
            incoming.append((step.partner, step.low))
        edges = (*self.net.edges, tuple(incoming))
        steps = (*self.steps, step)
        times = [*self.net.times, 0.0]
        n = len(steps) - 1
        times[n] = self._base(step, incoming, times)
        waits = _waits(steps, future) if future is not None else ()
        if not _settle(steps, edges, times, n, waits, eps):
            return None
        if future is not None and not _before_deadlines(steps, times, future, eps):
            return None
        span = max((t for t, s in zip(times, steps, strict=True) if s.kind != TIL), default=0.0)
        return Timeline(steps, _Net(edges, tuple(times)), eps, span)

    def _extend_compiled(
        self, step: Step, future: Future | None, oracle: Oracle
    ) -> Timeline | None:
        coming = None
        if future is not None:
            coming = (
                [(start, oracle.code(snap)) for start, snap in future.ends],
                [(when, oracle.code(snap)) for when, snap in future.deadlines],
            )
        code = oracle.code(step.snap)
        net = self.net.extend(
            oracle.core,
            step.kind,
            step.action,
            step.partner,
            step.low,
            step.high,
            code,
            coming,
            self.epsilon,
        )
        if net is None:
            return None
        return Timeline((*self.steps, step), net, self.epsilon, net.span, oracle)

    @staticmethod
    def _base(step: Step, incoming: list[tuple[int, float]], times: list[float]) -> float:
        value = step.low if step.kind == TIL else 0.0
        for i, w in incoming:
            if times[i] + w > value:
                value = times[i] + w
        return value


@dataclass(frozen=True, slots=True)
class Future:
    """Happenings certain to come after the steps of a timeline.

    `ends` pairs the start step of each running action with its end snap; `deadlines`
    pairs the time of each timed literal still to happen with its snap.
    """

    ends: tuple[tuple[int, Snap], ...] = ()
    deadlines: tuple[tuple[float, Snap], ...] = ()


# (start step, maximum duration, steps the future end must follow)
_Wait = tuple[int, float, tuple[int, ...]]


def _waits(steps: tuple[Step, ...], future: Future) -> tuple[_Wait, ...]:
    """Return, for each running action, the steps its future end must follow."""
    out = []
    for start, end_snap in future.ends:
        high = steps[start].high
        if high == math.inf:
            continue
        after = tuple(k for k in _interfering(steps, end_snap) if k != start)
        if after:
            out.append((start, high, after))
    return tuple(out)


def _before_deadlines(
    steps: tuple[Step, ...], times: list[float], future: Future, eps: float
) -> bool:
    """Tell whether every step a future timed literal interferes with can precede it."""
    for when, snap in future.deadlines:
        for k, old in enumerate(steps):
            if times[k] + eps > when + _TOL and interferes(old.snap, snap):
                return False
    return True


def _settle(
    steps: tuple[Step, ...],
    edges: tuple[tuple[tuple[int, float], ...], ...],
    times: list[float],
    first: int,
    waits: tuple[_Wait, ...] = (),
    eps: float = 0.0,
) -> bool:
    """Propagate earliest times from step `first` on; False on a positive cycle.

    A running action whose future end would come too late is started later, as an
    end already appended would.
    """
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
        for start, high, after in waits:
            latest = max(times[k] for k in after) + eps
            if latest - times[start] > high + _TOL:
                times[start] = latest - high
                lowest = min(lowest, start)
        if lowest == len(steps):
            return True
        first = lowest
    return False
