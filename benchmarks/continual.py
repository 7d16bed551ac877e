"""Continual vs offline planning on recycling maps of growing size (issue 4's benchmark).

For each problem it measures, in one process on one core:

- continual: rounds of the continual search (Alg. 2) bounded by `--round` seconds and
  `--plan-size` actions, each round's partial plan appended to the ones before (as an
  executing agent would receive them); the time to the first partial plan, to the
  complete plan, and the makespan of the concatenated plan;
- offline: one search for a complete plan (`--strategy`, default auto: the goal agenda,
  then climbing, then complete best-first), its time and makespan;

and validates every plan with our simulator and, if installed, with `kairos validate`.

Run: `make bench-continual` or
`python benchmarks/continual.py [--timeout 60] [--round 0.1] [--csv out.csv] [PROBLEM...]`.
"""

from __future__ import annotations

import argparse
import csv
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from cbdi_planner.continual import PartialPlanFound, RoundBound, SearchFailed, SearchThread
from cbdi_planner.errors import PlanInvalid
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.plan import Plan
from cbdi_planner.search import Budget, search
from cbdi_planner.simulate import validate
from cbdi_planner.state import initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
PROBLEMS = [
    ROOT / "domains/recycling/problems/paper-7x7.pddl",
    ROOT / "domains/recycling/problems/warehouse-15x15.pddl",
    ROOT / "domains/recycling/problems/campus-30x30.pddl",
]


@dataclass
class Row:
    """One problem's figures (times in seconds; -1: no plan within the timeout)."""

    problem: str
    facts: int
    actions: int
    ground_s: float
    first_partial_s: float = -1.0
    first_round: int = -1  # the round that handed out the first partial plan
    partial_plans: int = 0
    rounds: int = 0
    continual_s: float = -1.0
    continual_makespan: float = -1.0
    continual_valid: str = ""
    offline_s: float = -1.0
    offline_makespan: float = -1.0
    offline_valid: str = ""

    @property
    def ratio(self) -> float:
        """The concatenated continual makespan over the offline one (-1: not both)."""
        if self.continual_makespan < 0 or self.offline_makespan <= 0:
            return -1.0
        return self.continual_makespan / self.offline_makespan


def checked(task: Task, plan: Plan, problem: Path) -> str:
    """`ok` if our simulator and kairos (when installed) accept the plan, else why not."""
    try:
        validate(task, plan)
    except PlanInvalid as exc:
        return f"invalid: {exc}"
    kairos = shutil.which("kairos") or str(Path(sys.executable).parent / "kairos")
    if not Path(kairos).exists():
        return "ok (kairos not installed)"
    with tempfile.NamedTemporaryFile("w", suffix=".plan", delete=False) as f:
        f.write(plan.to_ipc())
    done = subprocess.run(
        [kairos, "validate", str(DOMAIN), str(problem), f.name], capture_output=True, text=True
    )
    Path(f.name).unlink()
    return "ok" if done.returncode == 0 else f"kairos: {done.stdout.strip()[-200:]}"


def continual(
    task: Task, row: Row, bound: RoundBound, timeout: float, problem: Path, agenda: bool
) -> None:
    """Run the continual search to the goal, appending partial plans as they come."""
    started = time.perf_counter()
    thread = SearchThread(task, initial_state(task), agenda=agenda)
    actions: list = []
    while not thread.finished and time.perf_counter() - started < timeout:
        for event in thread.step(bound):
            if isinstance(event, PartialPlanFound):
                if row.partial_plans == 0:
                    row.first_partial_s = time.perf_counter() - started
                    row.first_round = thread.rounds
                row.partial_plans += 1
                actions += event.plan.actions
                if event.complete:
                    row.continual_s = time.perf_counter() - started
            elif isinstance(event, SearchFailed):
                row.continual_valid = f"failed: {event.reason}"
                return
    row.rounds = thread.rounds
    if row.continual_s >= 0:
        plan = Plan(tuple(actions))
        row.continual_makespan = round(plan.makespan, 3)
        row.continual_valid = checked(task, plan, problem)


def offline(task: Task, row: Row, strategy: str, timeout: float, problem: Path) -> None:
    started = time.perf_counter()
    result = search(task, strategy=strategy, budget=Budget(max_seconds=timeout))
    if result.plan is None:
        row.offline_valid = result.status
        return
    row.offline_s = time.perf_counter() - started
    row.offline_makespan = round(result.plan.makespan, 3)
    row.offline_valid = checked(task, result.plan, problem)


def measure(problem: Path, args: argparse.Namespace) -> Row:
    started = time.perf_counter()
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    task = ground(domain, parse_problem(problem.read_text(), domain, str(problem)))
    row = Row(problem.stem, len(task.facts), len(task.actions), time.perf_counter() - started)
    bound = RoundBound(seconds=args.round, plan_size=args.plan_size)
    continual(task, row, bound, args.timeout, problem, args.agenda)
    offline(task, row, args.strategy, args.timeout, problem)
    return row


def show(rows: list[Row], args: argparse.Namespace) -> None:
    print(
        f"\nround bound {args.round * 1000:.0f} ms / {args.plan_size} actions;"
        f" timeout {args.timeout:.0f} s; offline search {args.strategy}"
    )
    head = (
        f"{'problem':<16} {'ground':>7} {'1st part':>9} {'parts':>5} {'continual':>10}"
        f" {'offline':>9} {'mk cont':>8} {'mk off':>8} {'ratio':>6}  valid (cont/off)"
    )
    print(head)
    print("-" * len(head))

    def s(v: float, unit: str = "s") -> str:
        return f"{v:.3f}{unit}" if v >= 0 else "-"

    for r in rows:
        print(
            f"{r.problem:<16} {s(r.ground_s):>7} {s(r.first_partial_s):>9} {r.partial_plans:>5}"
            f" {s(r.continual_s):>10} {s(r.offline_s):>9} {s(r.continual_makespan, ''):>8}"
            f" {s(r.offline_makespan, ''):>8} {s(r.ratio, ''):>6}"
            f"  {r.continual_valid or '-'} / {r.offline_valid or '-'}"
        )
    print(
        f"\ntargets: the first round ({args.round * 1000:.0f} ms) hands out a partial plan"
        " (time above: the root's evaluation plus that round);"
        " concatenated makespan within 20% of the offline plan's (ratio <= 1.2)"
    )
    for r in rows:
        first_ok = r.first_round == 1
        ratio_ok = 0 <= r.ratio <= 1.2
        print(
            f"  {r.problem:<16} first partial in round {r.first_round}:"
            f" {'met' if first_ok else 'MISSED'};"
            f" makespan: {'met' if ratio_ok else ('MISSED' if r.ratio >= 0 else 'n/a')}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("problems", nargs="*", type=Path, default=PROBLEMS)
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per search")
    parser.add_argument("--round", type=float, default=0.1, help="round interval (s)")
    parser.add_argument("--plan-size", type=int, default=8, help="actions per partial plan")
    parser.add_argument("--strategy", default="auto", help="offline search: auto, ff, ehc, bfs")
    parser.add_argument(
        "--agenda",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the continual greedy search reaches the goal facts one at a time (default on)",
    )
    parser.add_argument("--csv", type=Path, help="also write the rows to this CSV file")
    args = parser.parse_args(argv)
    rows = []
    for problem in args.problems:
        print(f"{problem.stem} ...", file=sys.stderr, flush=True)
        rows.append(measure(problem, args))
    show(rows, args)
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[*asdict(rows[0]), "ratio"])
            writer.writeheader()
            for r in rows:
                writer.writerow({**asdict(r), "ratio": round(r.ratio, 3)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
