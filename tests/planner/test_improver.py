"""The improving search (Alg. 2 lines 23-24) in rounds: shorter plans, deterministic."""

from __future__ import annotations

from pathlib import Path

from cbdi_planner.continual import ImprovedPlan, RoundBound, RoundDone
from cbdi_planner.continual.improver import Improver
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.simulate import validate
from cbdi_planner.state import initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[2]


def paper_task() -> Task:
    d = ROOT / "domains/recycling/pddl/domain.pddl"
    p = ROOT / "domains/recycling/problems/paper-7x7.pddl"
    domain = parse_domain(d.read_text(), str(d))
    return ground(domain, parse_problem(p.read_text(), domain, str(p)))


def run(task: Task, rounds: int, improve_on: float = float("inf")) -> list[tuple[int, float]]:
    imp = Improver(task, initial_state(task), improve_on=improve_on)
    out = []
    try:
        for _ in range(rounds):
            for e in imp.step(RoundBound(expansions=200)):
                if isinstance(e, RoundDone):
                    assert e.expanded <= 200  # a round never expands more than granted
                if isinstance(e, ImprovedPlan):
                    out.append((imp.rounds, e.plan.makespan))
                    assert e.plan.makespan < e.than
                    assert validate(task, e.plan).goal_reached  # raises if invalid
            if imp.finished:
                break
    finally:
        imp.close()
    return out


def test_the_improver_finds_ever_shorter_plans_in_rounds() -> None:
    task = paper_task()
    found = run(task, 15)
    spans = [m for _, m in found]
    assert len(spans) >= 3 and spans == sorted(spans, reverse=True)
    assert spans[-1] < 0.6 * spans[0]  # far better than the first plan (66 -> 34 here)


def test_the_improver_is_a_function_of_its_rounds_not_of_thread_timing() -> None:
    task = paper_task()
    assert run(task, 12) == run(task, 12)


def test_the_improver_keeps_only_plans_below_the_plan_it_would_replace() -> None:
    task = paper_task()
    best = run(task, 15)[-1][1]
    assert all(m < best for _, m in run(task, 15, improve_on=best))
