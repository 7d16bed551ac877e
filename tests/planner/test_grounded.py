"""The planner service grounds a task once and changes only its initial state."""

from __future__ import annotations

import itertools
import random
from pathlib import Path

from cbdi.beliefs import BeliefSet, fact
from cbdi_planner.agent.grounded import Groundings, reaches_goal
from cbdi_planner.agent.problem import problem_from_beliefs
from cbdi_planner.agent.transient import Transients
from cbdi_planner.grounding import ground
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl import parse_domain
from cbdi_planner.plan import Plan
from cbdi_planner.search import Budget, search
from cbdi_planner.simulate import simulate
from cbdi_planner.state import initial_state

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = parse_domain((ROOT / "domains/recycling/pddl/domain.pddl").read_text(), "domain.pddl")
W = H = 4
CELLS = [f"c_{x}_{y}" for x in range(W) for y in range(H)]
GOAL = [["recycled", "p1"]]


def beliefs(robot: str = "c_1_1", taken: tuple[str, ...] = (), litter: int = 1) -> BeliefSet:
    """A 4x4 grid, a bin at c_0_0, litter at c_3_3 (and c_3_0), people on `taken`."""
    facts: set[tuple[str, ...]] = {("map_loaded",), ("in", "robot1", robot)}
    for x, y in itertools.product(range(W), range(H)):
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            if 0 <= x + dx < W and 0 <= y + dy < H:
                facts.add(("near", f"c_{x}_{y}", f"c_{x + dx}_{y + dy}"))
    facts |= {("free", c) for c in CELLS if c not in (robot, "c_0_0", *taken)}
    facts |= {("bin_pose", "bin1", "c_0_0"), ("litter_pose", "p1", "c_3_3")}
    instances = {"robot1": "robot", "bin1": "bin", "p1": "plastic"}
    if litter > 1:
        facts.add(("litter_pose", "p2", "c_3_0"))
        instances["p2"] = "plastic"
    instances.update({c: "cell" for c in CELLS})
    fluents = {("loaded_amount", "robot1"): 0.0, ("detection_depth", "robot1"): 1.0}
    return BeliefSet(instances=instances, facts=frozenset(facts), fluents=fluents)


def seen(*sets: BeliefSet) -> Groundings:
    transients = Transients(["free"])
    for b in sets:
        transients.see(b)
    return Groundings(DOMAIN, transients)


def test_a_robot_or_a_person_moving_reuses_the_grounding() -> None:
    g = seen(beliefs())
    first = g.task(beliefs(), GOAL)
    for robot, taken in (("c_2_1", ()), ("c_2_2", ("c_1_1",)), ("c_1_2", ("c_2_2",))):
        b = beliefs(robot, taken)
        g.transients.see(b)
        task = g.task(b, GOAL)
        assert task.actions is first.actions  # not grounded again
        fresh = ground(DOMAIN, problem_from_beliefs(DOMAIN, b, GOAL))
        assert set(task.fact_names(task.init_facts)) == set(fresh.fact_names(fresh.init_facts))
    assert (g.grounded, g.reused) == (1, 3)


def test_a_new_object_or_a_cell_never_seen_free_grounds_again_a_new_goal_does_not() -> None:
    g = seen(beliefs(taken=("c_3_2",)))  # c_3_2 never seen free
    g.task(beliefs(taken=("c_3_2",)), GOAL)
    first = g.task(beliefs(taken=("c_3_2",), litter=2), GOAL)  # a new item: a new object
    assert g.grounded == 2
    other = g.task(beliefs(taken=("c_3_2",), litter=2), [["recycled", "p2"]])  # a new goal
    assert g.grounded == 2 and other.actions is first.actions and other.goal != first.goal
    b = beliefs(litter=2)  # c_3_2 free for the first time: its moves were never grounded
    g.transients.see(b)
    task = g.task(b, [["recycled", "p2"]])
    assert g.grounded == 3
    fresh = ground(DOMAIN, problem_from_beliefs(DOMAIN, b, [["recycled", "p2"]]))
    assert {a.name for a in fresh.actions} <= {a.name for a in task.actions}


def test_the_cached_task_plans_and_estimates_as_a_fresh_one() -> None:
    """On random walks of the robot and two people, the reused task's heuristic value
    at the start equals a fresh grounding's, and its plan is valid on the fresh task."""
    rng = random.Random(7)
    free = [c for c in CELLS if c != "c_0_0"]
    g = Groundings(DOMAIN, Transients(["free"]))
    solved = 0
    for _ in range(25):
        robot, *taken = rng.sample([c for c in free if c != "c_3_3"], 3)
        b = beliefs(robot, tuple(taken))
        g.transients.see(b)
        cached = g.task(b, GOAL)
        fresh = ground(DOMAIN, problem_from_beliefs(DOMAIN, b, GOAL))
        h_cached = RelaxedPlanGraph(cached).estimate(initial_state(cached)).value
        h_fresh = RelaxedPlanGraph(fresh).estimate(initial_state(fresh)).value
        assert h_cached == h_fresh
        found = search(cached, strategy="ff", budget=Budget(max_expansions=5000))
        alone = search(fresh, strategy="ff", budget=Budget(max_expansions=5000))
        assert found.status == alone.status  # both solved, or both proved unsolvable
        solved += found.plan is not None
        if found.plan is not None:
            assert simulate(fresh, Plan(found.plan.actions)).ok
    assert solved > 15 and g.grounded < 10 < g.reused


def test_a_goal_unreachable_from_the_beliefs_is_told_and_blocked_if_people_move() -> None:
    g = seen(beliefs())
    # Two people hem the robot in at the corner c_0_1 (beside the bin, no way out).
    b = beliefs("c_0_1", ("c_1_1", "c_0_2"))
    g.transients.see(b)
    task = g.task(b, GOAL)
    assert g.grounded == 1  # every cell was seen free: the same grounding
    assert not reaches_goal(task)
    assert g.blocked(b, GOAL) is True
    assert reaches_goal(g.task(beliefs("c_0_1"), GOAL))


def test_a_task_aimed_at_another_goal_is_the_fresh_grounding_of_that_goal() -> None:
    """Grounding runs from the initial state, so the cached task aimed at another goal
    has the fresh task's facts, goal and heuristic value, and plans the same; a goal
    that can never hold is told as grounding tells it."""
    from cbdi_planner.errors import Unsolvable

    g = seen(beliefs(litter=2))
    b = beliefs(litter=2)
    g.task(b, GOAL)
    goals = [[["recycled", "p2"]], [["in", "robot1", "c_3_0"]], [["holding", "robot1", "p1"]]]
    goals += [[["recycled", "p1"], ["recycled", "p2"]], GOAL]
    for goal in goals:
        task = g.task(b, goal)
        fresh = ground(DOMAIN, problem_from_beliefs(DOMAIN, b, goal))
        assert task.facts == fresh.facts
        names = set(fresh.fact_names(fresh.goal))
        assert set(task.fact_names(task.goal)) == names and task.goal_neg == fresh.goal_neg
        h = RelaxedPlanGraph.of(task).estimate(initial_state(task)).value
        assert h == RelaxedPlanGraph(fresh).estimate(initial_state(fresh)).value
        mine = search(task, strategy="ff", budget=Budget(max_expansions=5000)).plan
        alone = search(fresh, strategy="ff", budget=Budget(max_expansions=5000)).plan
        assert mine is not None and alone is not None
        assert [a.name for a in mine.actions] == [a.name for a in alone.actions]
    assert g.grounded == 1
    try:
        g.task(b, [["bin_pose", "bin1", "c_3_3"]])  # a static fact that is false
    except Unsolvable as exc:
        assert "can never hold" in str(exc)
    else:
        raise AssertionError("a goal that can never hold was not told")


def test_another_robots_recycled_item_grounds_nothing_anew() -> None:
    """`recycled` is read by no action's condition: another robot's item, picked up
    (so out of reach here) and then recycled, leaves the grounding as it was, and the
    task is the fresh grounding's but for that fact. A goal that names such a fact
    grounds anew (and holds at once)."""
    picked = beliefs(litter=2)
    picked = BeliefSet(
        instances=picked.instances,
        facts=picked.facts - {("litter_pose", "p1", "c_3_3")},
        fluents=picked.fluents,
    )
    g = seen(picked)
    first = g.task(picked, [["recycled", "p2"]])
    done = picked.adding([fact("recycled", "p1")])
    task = g.task(done, [["recycled", "p2"]])
    assert (g.grounded, task.actions) == (1, first.actions)
    fresh = ground(DOMAIN, problem_from_beliefs(DOMAIN, done, [["recycled", "p2"]]))
    assert set(fresh.fact_names(fresh.init_facts)) - set(task.fact_names(task.init_facts)) == {
        "(recycled p1)"
    }
    assert {a.name for a in fresh.actions} == {a.name for a in task.actions}
    found = search(task, strategy="ff", budget=Budget(max_expansions=5000))
    assert found.plan is not None and simulate(fresh, Plan(found.plan.actions)).ok
    again = g.task(done, [["recycled", "p1"]])  # a goal on the fact itself: grounded anew
    assert g.grounded == 2 and again.init_facts & again.goal == again.goal
