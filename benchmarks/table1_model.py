"""What Table I is made of: the paper's situations and numbers, runs, and their CSV rows.

Pure: no process is started here. A `Run` is what one `cbdi up --json` left (or that it
left nothing); `read_csv(write_csv(runs))` gives the same runs back, so a table rendered
from a kept CSV (`--reuse`) is the table rendered right after the runs.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

__all__ = [
    "CLOCKS",
    "COLUMNS",
    "MODES",
    "PAPER",
    "REPLAN_PURPOSES",
    "SITUATIONS",
    "PaperCell",
    "Run",
    "Situation",
    "Task",
    "parse_situations",
    "read_csv",
    "row_of",
    "run_from_summary",
    "run_of",
    "seeds_of",
    "summary_of",
    "with_reason",
    "write_csv",
]

MODES = ("offline", "online")
CLOCKS = ("lockstep", "realtime")  # realtime: `--speed 1 --no-lockstep`
REPLAN_PURPOSES = ("new", "repair", "revise", "improve")


@dataclass(frozen=True)
class Situation:
    """The paper's situation: people step every `move_step` epochs, detection depth, known."""

    move_step: int
    det_area: int
    known_litter: int

    @property
    def label(self) -> str:
        """Return `move,det,known`, as `--only` and the CSV spell it."""
        return f"{self.move_step},{self.det_area},{self.known_litter}"


@dataclass(frozen=True)
class PaperCell:
    """The paper's mean and standard deviation of moves over its four runs."""

    mu: float
    sigma: float


# Table I of the paper, in its row order: (offline, online) per situation. Its sixth
# column (mu+) is offline mu minus online mu, recomputed where shown.
PAPER: dict[Situation, tuple[PaperCell, PaperCell]] = {
    Situation(4, 1, 2): (PaperCell(56.0, 2.3), PaperCell(42.5, 9.8)),
    Situation(8, 1, 2): (PaperCell(58.5, 6.8), PaperCell(43.0, 10.1)),
    Situation(4, 2, 2): (PaperCell(58.5, 3.3), PaperCell(36.0, 0.0)),
    Situation(8, 2, 2): (PaperCell(58.0, 5.9), PaperCell(35.5, 6.0)),
    Situation(4, 3, 2): (PaperCell(66.0, 4.0), PaperCell(42.5, 10.5)),
    Situation(8, 3, 2): (PaperCell(57.0, 4.2), PaperCell(42.0, 6.3)),
    Situation(4, 1, 3): (PaperCell(48.0, 0.0), PaperCell(43.5, 5.5)),
    Situation(8, 1, 3): (PaperCell(57.8, 0.5), PaperCell(36.0, 2.8)),
    Situation(4, 2, 3): (PaperCell(48.0, 0.0), PaperCell(35.5, 2.5)),
    Situation(8, 2, 3): (PaperCell(57.0, 1.2), PaperCell(37.0, 11.6)),
    Situation(4, 3, 3): (PaperCell(48.0, 0.0), PaperCell(42.0, 8.2)),
    Situation(8, 3, 3): (PaperCell(48.0, 1.6), PaperCell(39.5, 17.2)),
}
SITUATIONS: tuple[Situation, ...] = tuple(PAPER)


def parse_situations(text: str) -> tuple[Situation, ...]:
    """Read `--only`: situations `move,det,known` separated by spaces or semicolons.

    Raise ValueError naming the bad entry: three integers that are a Table I row.
    """
    entries = [e for e in text.replace(";", " ").split() if e]
    if not entries:
        raise ValueError("no situation given (e.g. --only '4,1,2 8,1,2')")
    chosen: list[Situation] = []
    for entry in entries:
        parts = entry.split(",")
        try:
            situation = Situation(*(int(p) for p in parts))
        except (TypeError, ValueError):
            raise ValueError(f"{entry!r} is not move,det,known (three integers)") from None
        if situation not in PAPER:
            raise ValueError(f"{entry!r} is not a situation of Table I")
        if situation not in chosen:
            chosen.append(situation)
    return tuple(s for s in SITUATIONS if s in chosen)


@dataclass(frozen=True)
class Task:
    """One `cbdi up` to make: situation, mode, seed, planning speed factor, clock."""

    situation: Situation
    mode: str
    seed: int
    factor: float = 1.0
    clock: str = "lockstep"

    def sort_key(self) -> tuple[int, float, int, int, int]:
        """Order tasks as the tables read: clock, speed, paper row, mode, seed."""
        return (
            CLOCKS.index(self.clock),
            self.factor,
            SITUATIONS.index(self.situation),
            MODES.index(self.mode),
            self.seed,
        )

    def describe(self) -> str:
        """Return a short name of the task for progress lines."""
        speed = "" if self.factor == 1 else f" x{self.factor:g}"
        clock = " realtime" if self.clock == "realtime" else ""
        return f"{self.situation.label} {self.mode} seed {self.seed}{speed}{clock}"


@dataclass(frozen=True)
class Run:
    """What one run left. `result` is the summary's, or `no_summary` / `killed`."""

    task: Task
    result: str
    reason: str = ""
    exit: int = 0
    planning_speed: float | None = None  # passed as --planning-speed; None: the agent's
    speed: float | None = None  # passed as --speed (0: flat out); None: the scenario's
    up_args: str = ""
    moves: int | None = None
    sim_time: float | None = None
    busy: float | None = None  # simulated seconds the robot spent in actions
    recycled: int | None = None
    plans: int | None = None
    replans: int | None = None
    replans_new: int | None = None
    replans_repair: int | None = None
    replans_revise: int | None = None
    replans_improve: int | None = None
    forecast_repairs: int | None = None
    improvements: int | None = None
    stalls: int | None = None  # epochs a lockstep member missed its ack timeout
    trace_digest: str = ""  # the world's request trace: equal digests, equal runs
    wall: float = 0.0  # seconds; kept in the CSV for the running time, never in a table

    @property
    def ok(self) -> bool:
        """Tell whether the run recycled everything (a `done` run has statistics)."""
        return self.result == "done" and self.moves is not None and self.sim_time is not None

    @property
    def idle(self) -> float | None:
        """Return the percentage of the mission the robot spent in no action."""
        if self.busy is None or not self.sim_time:
            return None
        return 100.0 * max(0.0, 1.0 - self.busy / self.sim_time)


_TASK_COLUMNS: tuple[str, ...] = ("situation", "move_step", "det_area", "known_litter")
_TASK_COLUMNS += ("mode", "seed", "clock", "planning_factor")
_RUN_FIELDS = tuple(f.name for f in fields(Run) if f.name != "task")
COLUMNS: tuple[str, ...] = _TASK_COLUMNS + _RUN_FIELDS
_INTS = {"exit", "moves", "recycled", "plans", "replans", "forecast_repairs", "improvements"}
_INTS |= {"stalls"}
_INTS |= {f"replans_{p}" for p in REPLAN_PURPOSES}
_FLOATS = {"planning_speed", "speed", "sim_time", "busy", "wall"}


def run_from_summary(given: Run, summary: dict[str, Any]) -> Run:
    """Fill a run (task, exit, what was passed) from a `cbdi up --json` summary."""
    robot = summary.get("stats", {}).get("agents", {}).get("robot1", {})
    planner = summary.get("planner", {}).get("agents", {}).get("robot1", {})
    by = planner.get("replans_by", {})
    stalls = summary.get("stalls")
    return replace(
        given,
        result=str(summary.get("result", "no_summary")),
        reason=str(summary.get("reason", "")),
        moves=robot.get("moves"),
        sim_time=summary.get("sim_time"),
        busy=robot.get("busy"),
        recycled=robot.get("recycled"),
        plans=planner.get("plans"),
        replans=planner.get("replans"),
        forecast_repairs=planner.get("forecast_repairs"),
        improvements=planner.get("improvements"),
        stalls=sum(stalls.values()) if isinstance(stalls, dict) else None,
        trace_digest=str(summary.get("trace_digest", "")),
        **{f"replans_{p}": by.get(p) for p in REPLAN_PURPOSES},
    )


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(round(value, 6))  # exact on reading back
    return str(value)


def row_of(run: Run) -> dict[str, str]:
    """Return the CSV row of a run; empty cells for what it did not report."""
    t = run.task
    out = {
        "situation": t.situation.label,
        "move_step": str(t.situation.move_step),
        "det_area": str(t.situation.det_area),
        "known_litter": str(t.situation.known_litter),
        "mode": t.mode,
        "seed": str(t.seed),
        "clock": t.clock,
        "planning_factor": f"{t.factor:g}",
    }
    out.update({name: _cell(getattr(run, name)) for name in _RUN_FIELDS})
    return out


def run_of(row: dict[str, str]) -> Run:
    """Read back a CSV row; raise KeyError/ValueError if it is not this benchmark's."""
    situation = Situation(int(row["move_step"]), int(row["det_area"]), int(row["known_litter"]))
    if row["mode"] not in MODES or row["clock"] not in CLOCKS:
        raise ValueError(f"mode {row['mode']!r} or clock {row['clock']!r} unknown")
    task = Task(
        situation, row["mode"], int(row["seed"]), float(row["planning_factor"]), row["clock"]
    )
    values: dict[str, Any] = {}
    for name in _RUN_FIELDS:
        text = row[name]
        if name in _INTS:
            values[name] = int(text) if text else None
        elif name in _FLOATS:
            values[name] = float(text) if text else None
        else:
            values[name] = text
    values["exit"] = values["exit"] or 0
    values["wall"] = values["wall"] or 0.0
    return Run(task=task, **values)


def write_csv(runs: Iterable[Run], path: Path) -> list[Run]:
    """Write the runs, sorted as the tables read, and return them in that order."""
    ordered = sorted(runs, key=lambda r: r.task.sort_key())
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as out:
        writer = csv.DictWriter(out, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(row_of(r) for r in ordered)
    return ordered


def read_csv(path: Path) -> list[Run]:
    """Read the runs of a CSV this benchmark wrote, sorted as the tables read."""
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        missing = set(COLUMNS) - set(reader.fieldnames or ())
        if missing:
            raise KeyError(f"columns missing: {', '.join(sorted(missing))}")
        runs = [run_of(r) for r in reader]
    return sorted(runs, key=lambda r: r.task.sort_key())


def with_reason(run: Run, reason: str) -> Run:
    """Return the run with a reason, shortened to one line for the CSV."""
    return replace(run, reason=" ".join(reason.split())[:300])


def summary_of(text: str) -> dict[str, Any] | None:
    """Parse a `cbdi up --json` stdout; None if it printed no JSON object."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        return None
    return data if isinstance(data, dict) else None


def seeds_of(runs: Sequence[Run]) -> list[int]:
    """Return the seeds the runs used, sorted."""
    return sorted({r.task.seed for r in runs})
