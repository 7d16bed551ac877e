"""Helpers of the planner tests: plan a PDDL problem and check the plan with Kairos.

Every plan a test produces goes through `kairos validate`, an independent validator,
so a test never trusts the planner's own idea of what a valid plan is.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from cbdi_planner.errors import Unsolvable
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.plan import Plan
from cbdi_planner.search import Budget, SearchResult, search

__all__ = [
    "EPSILON",
    "Planned",
    "kairos",
    "plan_and_validate",
    "solve",
    "status_of",
    "validate",
]

EPSILON = 0.001


def kairos() -> str:
    """Return the path of the `kairos` validator (next to the running Python first)."""
    local = Path(sys.executable).parent / "kairos"
    if local.exists():
        return str(local)
    found = shutil.which("kairos")
    if found is None:
        raise RuntimeError("kairos is not installed; run `make venv`")
    return found


@dataclass(frozen=True)
class Planned:
    """A search result together with the files it was validated against."""

    result: SearchResult
    domain_file: Path
    problem_file: Path
    plan_file: Path | None

    @property
    def plan(self) -> Plan:
        """Return the plan (the search must have solved the problem)."""
        assert self.result.plan is not None, f"no plan: status {self.result.status}"
        return self.result.plan

    def start_of(self, prefix: str) -> float:
        """Return the start time of the first action whose name starts with `prefix`."""
        return next(a.time for a in self.plan.actions if a.name.startswith(prefix))

    def named(self, prefix: str) -> list[tuple[float, float | None]]:
        """Return `(start, duration)` of every action whose name starts with `prefix`."""
        return [(a.time, a.duration) for a in self.plan.actions if a.name.startswith(prefix)]


def validate(domain_file: Path, problem_file: Path, plan_file: Path) -> tuple[bool, str]:
    """Run `kairos validate`; return (valid, its output)."""
    done = subprocess.run(
        [
            kairos(),
            "validate",
            str(domain_file),
            str(problem_file),
            str(plan_file),
            "--epsilon",
            str(EPSILON),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    return done.returncode == 0, done.stdout + done.stderr


def solve(
    domain_text: str,
    problem_text: str,
    *,
    strategy: str = "auto",
    budget: Budget | None = None,
    anytime: bool = False,
) -> SearchResult:
    """Parse, ground and search (no validation)."""
    domain = parse_domain(domain_text, "domain.pddl")
    problem = parse_problem(problem_text, domain, "problem.pddl")
    task = ground(domain, problem)
    return search(
        task,
        strategy=strategy,
        budget=budget or Budget(max_seconds=20),
        epsilon=EPSILON,
        anytime=anytime,
    )


def status_of(domain_text: str, problem_text: str, budget: Budget | None = None) -> str:
    """Return the search status, counting `Unsolvable` from grounding as "unsolvable"."""
    try:
        return solve(domain_text, problem_text, budget=budget).status
    except Unsolvable:
        return "unsolvable"


def plan_and_validate(
    tmp_path: Path,
    domain_text: str,
    problem_text: str,
    *,
    strategy: str = "auto",
    budget: Budget | None = None,
    anytime: bool = False,
    name: str = "case",
) -> Planned:
    """Plan, then assert the plan exists and `kairos validate` accepts it."""
    folder = tmp_path / name
    folder.mkdir(parents=True, exist_ok=True)
    domain_file = folder / "domain.pddl"
    problem_file = folder / "problem.pddl"
    domain_file.write_text(domain_text)
    problem_file.write_text(problem_text)
    result = solve(domain_text, problem_text, strategy=strategy, budget=budget, anytime=anytime)
    assert result.status == "solved" and result.plan is not None, (
        f"no plan: status {result.status}, stats {result.stats}"
    )
    plan_file = folder / "plan.txt"
    plan_file.write_text(result.plan.to_ipc())
    valid, output = validate(domain_file, problem_file, plan_file)
    assert valid, f"kairos rejects the plan:\n{result.plan.to_ipc()}\n{output}"
    return Planned(result, domain_file, problem_file, plan_file)
