"""Offline search backends: cbdi's own planner, or kairos-planner when it is installed.

Both take the domain and a problem built from the agent's beliefs and return a `Plan`, or
raise `Unsolvable` / `SearchTimeout` (from `cbdi_planner.errors`).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cbdi.runtime.parent import die_with_parent
from cbdi_planner.errors import SearchTimeout, Unsolvable
from cbdi_planner.grounding import ground
from cbdi_planner.pddl.ast import Domain, Problem
from cbdi_planner.plan import Plan, parse_plan
from cbdi_planner.search import Budget, search

__all__ = ["BACKENDS", "COUNTING_BACKENDS", "Counted", "plan_counted", "plan_with", "problem_text"]

COUNTING_BACKENDS = ("cbdi",)  # those that can be bounded and charged by node expansions

BACKENDS = ("cbdi", "kairos")


def plan_with(
    backend: str, domain: Domain, domain_file: Path, problem: Problem, seconds: float
) -> Plan:
    """Return a plan for `problem` from `backend` within `seconds`."""
    if backend == "cbdi":
        # FF's search (climbing, then best-first), not the goal agenda: the agent acts on
        # this first plan, and climbing to the whole goal gives shorter plans.
        task = ground(domain, problem)
        result = search(task, strategy="ff", budget=Budget(max_seconds=seconds))
        if result.status == "timeout":  # as plan_counted: the goal agenda, as long again
            result = search(task, strategy="auto", budget=Budget(max_seconds=seconds))
        if result.plan is not None:
            return result.plan
        if result.status == "timeout":
            raise SearchTimeout(f"no plan within {2 * seconds:g} s")
        raise Unsolvable(f"no plan reaches the goal ({result.status})")
    if backend == "kairos":
        return _kairos(domain_file, problem, seconds)
    raise ValueError(f"unknown backend {backend!r} (known: {', '.join(BACKENDS)})")


@dataclass(frozen=True)
class Counted:
    """An offline search bounded by node expansions: the plan (or why none) and its cost."""

    plan: Plan | None
    expanded: int
    error: str = ""
    timeout: bool = False  # the expansion bound ran out (no verdict on solvability)


def plan_counted(
    domain: Domain,
    problem: Problem,
    max_expansions: int,
    pace: Callable[[int], None] | None = None,
) -> Counted:
    """Plan `problem` as `plan_with("cbdi")` does, bounded by node expansions only.

    Virtual time charges the search to simulated time by what it expanded, so the
    result is the same on any machine, however loaded. `pace` (`Pacer.pace`) lets the
    search expand only what has been paid for.
    """
    task = ground(domain, problem)
    result = search(task, strategy="ff", budget=Budget(max_expansions=max_expansions, pace=pace))
    expanded = result.stats.expanded
    if result.status == "timeout":
        # FF's climbing and best-first ran out (24 items on a 30x30 map): the goal agenda
        # (one goal fact at a time) with a budget as large again, its cost added.
        first = expanded
        later = None if pace is None else (lambda n: pace(first + n))
        result = search(task, strategy="auto", budget=Budget(max_expansions, pace=later))
        expanded += result.stats.expanded
        max_expansions *= 2
    expanded = max(1, expanded)
    if result.plan is not None:
        return Counted(result.plan, expanded)
    if result.status == "timeout":
        return Counted(None, expanded, f"no plan within {max_expansions} expansions", True)
    return Counted(None, expanded, f"no plan reaches the goal ({result.status})")


def _kairos(domain_file: Path, problem: Problem, seconds: float) -> Plan:
    exe = Path(sys.executable).parent / "kairos"
    found = str(exe) if exe.exists() else shutil.which("kairos")
    if found is None:
        raise ValueError("the kairos backend needs kairos-planner (pip install kairos-planner)")
    with tempfile.TemporaryDirectory() as tmp:
        pfile = Path(tmp) / "problem.pddl"
        pfile.write_text(problem_text(problem))
        try:
            done = subprocess.run(
                [found, str(domain_file), str(pfile), "--timeout", f"{seconds:g}", "--no-anytime"],
                capture_output=True,
                text=True,
                timeout=seconds + 10,
                # Pass the parent-death signal on: kairos ends with this planner (its
                # thread), whatever kills it.
                preexec_fn=die_with_parent,
            )
        except subprocess.TimeoutExpired:
            raise SearchTimeout(f"kairos found no plan within {seconds:g} s") from None
    plan = parse_plan(done.stdout)
    if len(plan) == 0:
        raise Unsolvable(f"kairos found no plan: {done.stderr.strip()[-300:]}")
    return plan


def problem_text(problem: Problem) -> str:
    """Write `problem` as PDDL (objects, init, numeric init, goal literals)."""
    objects = " ".join(f"{n} - {t[0]}" for n, t in sorted(problem.objects.items()))
    init = [str(a) for a in problem.init]
    init += [f"(= ({' '.join((h.name, *h.args))}) {v:g})" for h, v in problem.init_numeric.items()]
    goal = " ".join(
        str(g.atom) if g.positive else f"(not {g.atom})"  # type: ignore[union-attr]
        for g in problem.goal
    )
    return (
        f"(define (problem {problem.name}) (:domain {problem.domain_name})\n"
        f"  (:objects {objects})\n  (:init {' '.join(init)})\n"
        f"  (:goal (and {goal})))\n"
    )
