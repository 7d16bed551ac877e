"""Simulating a plan from a state: what the executor's checks and the forecast rely on."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from cbdi_planner.errors import PlanInvalid
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.plan import parse_plan
from cbdi_planner.search import search
from cbdi_planner.simulate import simulate, validate
from cbdi_planner.state import initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
PAPER = ROOT / "domains/recycling/problems/paper-7x7.pddl"


@pytest.fixture(scope="module")
def task() -> Task:
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    return ground(domain, parse_problem(PAPER.read_text(), domain, str(PAPER)))


def test_a_found_plan_simulates_to_the_goal(task: Task) -> None:
    plan = search(task).plan
    assert plan is not None
    sim = validate(task, plan)
    assert sim.ok and sim.goal_reached
    assert sim.time == pytest.approx(plan.makespan)
    assert len(sim.trace) == 2 * len(plan)  # a start and an end per durative action


def test_a_person_on_the_path_makes_the_forecast_fail_at_that_move(task: Task) -> None:
    plan = search(task).plan
    assert plan is not None
    moves = [i for i, a in enumerate(plan.actions) if a.name.startswith("move")]
    target = plan.actions[moves[3]].name.split()[-1]  # the 4th move's destination
    bit = 1 << task.facts.index(f"(free {target})")
    blocked = replace(initial_state(task), facts=initial_state(task).facts & ~bit)
    sim = simulate(task, plan, blocked)
    assert sim.failed == moves[3]
    assert f"(free {target})" in sim.reason
    with pytest.raises(PlanInvalid, match="move"):
        validate_from(task, plan, blocked)


def validate_from(task: Task, plan, state) -> None:  # type: ignore[no-untyped-def]
    sim = simulate(task, plan, state)
    if not sim.ok:
        raise PlanInvalid(f"({plan.actions[sim.failed].name}): {sim.reason}")


def test_a_horizon_simulates_only_the_next_actions(task: Task) -> None:
    plan = search(task).plan
    assert plan is not None
    sim = simulate(task, plan, horizon=2)
    assert sim.ok and not sim.goal_reached
    assert len(sim.trace) == 4


def test_wrong_durations_and_unknown_actions_are_named(task: Task) -> None:
    wrong = parse_plan("0.000: (move robot1 c_0_1 c_0_2) [2.000]\n")
    assert "duration 2 outside [1, 1]" in simulate(task, wrong).reason
    unknown = parse_plan("0.000: (fly robot1 c_0_1 c_6_6) [1.000]\n")
    assert "no such action" in simulate(task, unknown).reason
    with pytest.raises(PlanInvalid, match="without reaching the goal"):
        validate(task, parse_plan("0.000: (move robot1 c_0_1 c_0_2) [1.000]\n"))
