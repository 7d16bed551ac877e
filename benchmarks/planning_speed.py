"""Calibrate virtual time's planning speed: node expansions per wall second, here.

Virtual time (lockstep) charges planning to simulated time at `planning_speed`
expansions per simulated second (`[planning]` in the agent file). This measures what the
planner really does per wall second on this machine, so the default can be chosen as
"planning takes as long in simulated time as it would in real time here":

- continual: rounds of the continual search (expansions per round as the agent file
  sets them, 200) until a complete plan or `--budget` expansions;
- offline: the offline backend's search (FF: climbing, then best-first) to a plan;

on each recycling problem, `--repeat` times, with each search core (`--cores`: the
compiled one and the Python reference, `cbdi_planner.core`), runs interleaved so that a
change of the machine's load hits both alike; it prints expansions, seconds and
expansions per second (median, min, max) per problem, mode and core, and the compiled
core's speed-up (the ratio of the medians).

Run: `make bench-planning-speed` or `python benchmarks/planning_speed.py [--repeat 5]`.
"""

from __future__ import annotations

import argparse
import os
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
    p.add_argument(
        "--cores", default="compiled,python", help="search cores to measure, comma-separated"
    )
    p.add_argument("problems", nargs="*", default=PROBLEMS)
    args = p.parse_args(argv)
    if args.repeat < 1 or args.budget < 1 or args.per_round < 1:
        p.error("--repeat, --budget and --per-round must be at least 1")
    cores = [c.strip() for c in args.cores.split(",") if c.strip()]
    if not cores or any(c not in ("compiled", "python") for c in cores):
        p.error("--cores: a comma-separated list of compiled and python")
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    rates: dict[str, list[float]] = {c: [] for c in cores}
    print(
        f"{'problem':<18}{'mode':<11}{'core':<10}{'expanded':>9}{'seconds':>9}"
        "  expansions/s med [min, max]"
    )
    for name in args.problems:
        path = ROOT / "domains/recycling/problems" / f"{name}.pddl"
        task = ground(domain, parse_problem(path.read_text(), domain, str(path)))
        for mode in ("continual", "offline"):
            runs: dict[str, list[tuple[int, float]]] = {c: [] for c in cores}
            for _ in range(args.repeat):
                for core in cores:  # interleaved: load changes hit every core alike
                    os.environ["CBDI_SEARCH_CORE"] = core
                    run = (
                        continual(task, args.budget, args.per_round)
                        if mode == "continual"
                        else offline(task, args.budget)
                    )
                    runs[core].append(run)
            medians = {}
            for core in cores:
                per_s = [n / s for n, s in runs[core] if s > 0]
                rates[core] += per_s
                n, sec = runs[core][-1]
                medians[core] = statistics.median(per_s)
                print(
                    f"{name:<18}{mode:<11}{core:<10}{n:>9}{sec:>9.3f}  "
                    f"{medians[core]:8.0f} [{min(per_s):.0f}, {max(per_s):.0f}]"
                )
            if {"compiled", "python"} <= set(cores):
                ratio = medians["compiled"] / medians["python"]
                print(f"{name:<18}{mode:<11}compiled core: {ratio:.1f}x the Python core")
    for core in cores:
        print(f"{core}: median {statistics.median(rates[core]):.0f} expansions per wall second")
    return 0


if __name__ == "__main__":
    sys.exit(main())
