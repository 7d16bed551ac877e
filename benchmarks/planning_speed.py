"""Calibrate virtual time's planning speed: node expansions per wall second, here.

Virtual time (lockstep) charges planning to simulated time at `planning_speed`
expansions per simulated second (`[planning]` in the agent file). This measures what the
planner really does per wall second on this machine, so the default can be chosen as
"planning takes as long in simulated time as it would in real time here":

- continual: rounds of the continual search (expansions per round as the agent file
  sets them, 200) until a complete plan or `--budget` expansions;
- offline: the offline backend's search (FF: climbing, then best-first) to a plan;

on each recycling problem, `--repeat` times; it prints expansions, seconds and
expansions per second (median, min, max) per problem and mode.

Run: `make bench-planning-speed` or `python benchmarks/planning_speed.py [--repeat 5]`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from cbdi_planner.continual import PartialPlanFound, RoundBound, RoundDone, SearchThread
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget, search
from cbdi_planner.state import initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
PROBLEMS = ["paper-7x7", "warehouse-15x15", "campus-30x30"]


def continual(task: Task, budget: int, per_round: int) -> tuple[int, float]:
    """Expansions and wall seconds of continual rounds until a complete plan."""
    thread = SearchThread(task, initial_state(task))
    bound = RoundBound(expansions=per_round, plan_size=8)
    expanded, started = 0, time.perf_counter()
    while not thread.finished and expanded < budget:
        events = thread.step(bound)
        expanded += sum(e.expanded for e in events if isinstance(e, RoundDone))
        if any(isinstance(e, PartialPlanFound) and e.complete for e in events):
            break
    return expanded, time.perf_counter() - started


def offline(task: Task, budget: int) -> tuple[int, float]:
    """Expansions and wall seconds of the offline backend's search to a plan."""
    started = time.perf_counter()
    result = search(task, strategy="ff", budget=Budget(max_expansions=budget))
    return result.stats.expanded, time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--repeat", type=int, default=3, help="runs per problem and mode")
    p.add_argument("--budget", type=int, default=20000, help="expansions at most per run")
    p.add_argument("--per-round", type=int, default=200, help="expansions per round")
    p.add_argument("problems", nargs="*", default=PROBLEMS)
    args = p.parse_args(argv)
    if args.repeat < 1 or args.budget < 1 or args.per_round < 1:
        p.error("--repeat, --budget and --per-round must be at least 1")
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    rates: list[float] = []
    print(f"{'problem':<18}{'mode':<11}{'expanded':>9}{'seconds':>9}  expansions/s med [min, max]")
    for name in args.problems:
        path = ROOT / "domains/recycling/problems" / f"{name}.pddl"
        task = ground(domain, parse_problem(path.read_text(), domain, str(path)))
        for mode in ("continual", "offline"):
            runs = [
                continual(task, args.budget, args.per_round)
                if mode == "continual"
                else offline(task, args.budget)
                for _ in range(args.repeat)
            ]
            per_s = [n / s for n, s in runs if s > 0]
            rates += per_s
            n, sec = runs[-1]
            med = statistics.median(per_s)
            print(
                f"{name:<18}{mode:<11}{n:>9}{sec:>9.3f}  "
                f"{med:8.0f} [{min(per_s):.0f}, {max(per_s):.0f}]"
            )
    print(f"all runs: median {statistics.median(rates):.0f} expansions per wall second")
    return 0


if __name__ == "__main__":
    sys.exit(main())
