"""Time-triggered plans: built from a timeline, printed and read in the IPC format."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from cbdi_planner.errors import PlanInvalid
from cbdi_planner.stn import END, INST, START, Timeline
from cbdi_planner.task import Task

__all__ = ["Plan", "ScheduledAction", "parse_plan", "plan_from_timeline"]

_LINE = re.compile(
    r"^\s*(?P<time>[0-9.eE+-]+)\s*:\s*\((?P<name>[^)]*)\)\s*(\[(?P<dur>[0-9.eE+-]+)\])?\s*$"
)


@dataclass(frozen=True, slots=True)
class ScheduledAction:
    """An action with its start time; `duration` is None for an instantaneous action."""

    time: float
    name: str
    duration: float | None

    def to_ipc(self) -> str:
        """Format as `0.000: (move a c1 c2) [1.000]`."""
        text = f"{self.time:.3f}: ({self.name})"
        return text if self.duration is None else f"{text} [{self.duration:.3f}]"


@dataclass(frozen=True, slots=True)
class Plan:
    """A time-triggered plan, sorted by start time."""

    actions: tuple[ScheduledAction, ...]

    @property
    def makespan(self) -> float:
        """Return the time the last action ends."""
        return max((a.time + (a.duration or 0.0) for a in self.actions), default=0.0)

    def to_ipc(self) -> str:
        """Format the whole plan, one action a line."""
        return "".join(a.to_ipc() + "\n" for a in self.actions)

    def __len__(self) -> int:
        return len(self.actions)


def plan_from_timeline(task: Task, timeline: Timeline) -> Plan:
    """Read the scheduled plan off a complete timeline (every start has its end), leaving
    out the planner's internal actions (those of a disjunctive goal)."""
    ends = {s.partner: k for k, s in enumerate(timeline.steps) if s.kind == END}
    times = timeline.times  # read once (a copy, on the compiled core)
    out = []
    for k, step in enumerate(timeline.steps):
        if step.kind not in (START, INST) or task.actions[step.action].internal:
            continue  # ends are read with their starts; internal actions are no plan's
        time = round(times[k], 6)
        name = task.actions[step.action].name
        if step.kind == INST:
            out.append(ScheduledAction(time, name, None))
        elif step.kind == START:
            end = ends.get(k)
            if end is None:
                raise PlanInvalid(f"action ({name}) never ends")
            duration = round(times[end] - times[k], 6)
            out.append(ScheduledAction(time, name, duration))
    out.sort(key=lambda a: a.time)
    return Plan(tuple(out))


def parse_plan(text: str) -> Plan:
    """Read an IPC plan (`time: (action args) [duration]`); `;` starts a comment."""
    out = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)[0].strip()
        if not line:
            continue
        match = _LINE.match(line)
        if match is None:
            raise PlanInvalid(
                f"plan line {number}: cannot read {raw.strip()!r} "
                "(expected 'TIME: (name args) [DURATION]')"
            )
        name = " ".join(match.group("name").lower().split())
        dur = match.group("dur")
        time = _finite(match.group("time"), number, raw)
        out.append(
            ScheduledAction(time, name, _finite(dur, number, raw) if dur is not None else None)
        )
    out.sort(key=lambda a: a.time)
    return Plan(tuple(out))


def _finite(text: str, number: int, raw: str) -> float:
    """Read a plan's time or duration: a finite number, or PlanInvalid naming the line."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise PlanInvalid(f"plan line {number}: {text!r} is not a finite number in {raw.strip()!r}")
    return value
