"""Plans from the state a running step leaves, whatever the beliefs already show of it.

A robot's sensors report its state as it is: mid-drive the courier robot is still at the
cell it left, busy (not `idle`), its battery already used. The planner works out what the
drive leaves (the committed state) from the domain alone: the task must reach the drive
though the beliefs make it impossible now (`held_at_start`), and the drive's `decrease` of
the battery is not applied again once the beliefs show the drive started (`Sensed`).
"""

from __future__ import annotations

import itertools

import pytest

from cbdi.agentfile import PlanningSettings
from cbdi.beliefs import BeliefSet, fact, fluent, instance
from cbdi.wire.agent import ActionStatus, PlanStep
from cbdi_planner.agent.continual import ContinualPlanner
from cbdi_planner.agent.grounded import Groundings, reaches_goal
from cbdi_planner.agent.lines import Line, Purpose
from cbdi_planner.agent.offline import Execution
from cbdi_planner.agent.steps import held_at_start
from cbdi_planner.agent.transient import Transients
from cbdi_planner.continual import Sensed, commit
from cbdi_planner.errors import Unsolvable
from cbdi_planner.pddl import parse_domain
from cbdi_planner.plan import ScheduledAction
from tests_support import REPO

DOMAIN = parse_domain((REPO / "domains/courier/pddl/domain.pddl").read_text(encoding="utf-8"))
DRIVE = "drive robot1 c_1_1 c_2_1"
GOAL = [["at", "robot1", "c_3_1"]]


def floor(battery: float, busy: bool) -> BeliefSet:
    """robot1 on a row of three cells, at c_1_1; `busy`: mid-drive to c_2_1 (as sensed:
    not idle, c_2_1 taken, `battery` already used or not)."""
    cells = ("c_1_1", "c_2_1", "c_3_1")
    beliefs = [instance("robot1", "robot"), *(instance(c, "cell") for c in cells)]
    beliefs += [fact("link", a, b) for a, b in itertools.pairwise(cells)]
    beliefs += [fact("link", b, a) for a, b in itertools.pairwise(cells)]
    beliefs += [fact("open", c) for c in cells] + [fact("at", "robot1", "c_1_1")]
    beliefs += [fact("clear", "c_3_1"), fact("empty", "robot1")]
    if not busy:
        beliefs += [fact("idle", "robot1"), fact("clear", "c_2_1")]
    beliefs += [fluent("battery", "robot1", value=battery)]
    beliefs += [fluent("capacity", "robot1", value=20.0)]
    return BeliefSet().adding(beliefs)


def value(task: object, state: object, var: str) -> float:
    return state.nums[task.num_vars.index(var)]  # type: ignore[attr-defined]


def test_the_facts_a_running_step_started_from_are_the_ones_it_needed() -> None:
    held = held_at_start(DOMAIN, DRIVE)
    assert ("idle", "robot1") in held and ("at", "robot1", "c_1_1") in held
    assert ("clear", "c_2_1") in held
    assert held_at_start(DOMAIN, "fly robot1") == []


def test_a_busy_robot_s_task_reaches_its_running_drive_and_what_follows() -> None:
    busy = floor(19.0, busy=True)
    with pytest.raises(Unsolvable):  # grounded from these beliefs, nothing can start
        Groundings(DOMAIN).task(busy, GOAL)
    task = Groundings(DOMAIN).task(busy, GOAL, held_at_start(DOMAIN, DRIVE))
    steps = [ScheduledAction(0.0, DRIVE, 2.0)]
    done = commit(task, steps, {0: "running"}, 0)
    assert done.state is not None
    after = set(task.fact_names(done.state.facts))
    assert "(at robot1 c_2_1)" in after and "(idle robot1)" in after
    assert "(at robot1 c_1_1)" not in after
    assert reaches_goal(task, done.state)


def test_a_drive_uses_its_charge_once_whatever_the_beliefs_show() -> None:
    """Sensed when the drive began (t=0), the beliefs show nothing of it: its charge is
    used in the committed state; sensed after (t=1: busy, the charge used), not again."""
    steps = [ScheduledAction(0.0, DRIVE, 2.0)]
    held = held_at_start(DOMAIN, DRIVE)
    for beliefs, now in ((floor(20.0, busy=False), 0.0), (floor(19.0, busy=True), 1.0)):
        task = Groundings(DOMAIN).task(beliefs, GOAL, held)
        done = commit(task, steps, {0: "running"}, 0, Sensed(now, {0: 0.0}))
        assert done.state is not None
        assert value(task, done.state, "(battery robot1)") == 19.0
    # Sensed as it ended (t=2: at c_2_1, idle again, the charge used) while its status
    # still says running: its start shows though `idle` is back (the end gave it back).
    ended = floor(19.0, busy=False).removing([fact("at", "robot1", "c_1_1")])
    ended = ended.adding([fact("at", "robot1", "c_2_1"), fact("clear", "c_1_1")])
    ended = ended.removing([fact("clear", "c_2_1")])
    task = Groundings(DOMAIN).task(ended, GOAL, held)
    done = commit(task, steps, {0: "running"}, 0, Sensed(2.0, {0: 0.0}))
    assert done.state is not None and value(task, done.state, "(battery robot1)") == 19.0
    assert "(at robot1 c_2_1)" in task.fact_names(done.state.facts)
    # Without the times, a started step is applied whole (the charge twice).
    task = Groundings(DOMAIN).task(floor(19.0, busy=True), GOAL, held)
    done = commit(task, steps, {0: "running"}, 0)
    assert done.state is not None and value(task, done.state, "(battery robot1)") == 18.0


def test_the_offline_planner_plans_from_where_a_busy_robot_s_drive_leaves_it() -> None:
    """The offline planner's execution record: the drive runs (reported with its start
    time), the beliefs were sensed after it started; the problem starts at c_2_1, idle,
    with the charge the drive used once."""
    e = Execution()
    drive = PlanStep(step_id="p-1", action="drive", args=DRIVE.split()[1:], start=0.0, duration=2.0)
    e.follow(0, [drive])
    running = ActionStatus(
        agent="robot1",
        plan_id="p",
        step_id="p-1",
        action="drive",
        status="running",
        reason="",
        time=0.0,
    )
    e.on_status(running)
    assert ("idle", "robot1") in e.held(DOMAIN)  # what a failed search is judged from
    c = e.commit(DOMAIN, floor(19.0, busy=True), GOAL, sensed_at=1.0)
    assert (c.count, c.after, c.ends) == (1, "p-1", 2.0)
    init = {(a.predicate, *a.args) for a in c.problem.init}
    assert ("at", "robot1", "c_2_1") in init and ("idle", "robot1") in init
    assert ("at", "robot1", "c_1_1") not in init
    assert {k.args: v for k, v in c.problem.init_numeric.items() if k.name == "battery"} == {
        ("robot1",): 19.0
    }


def test_the_online_planner_grounds_a_busy_robot_s_task_with_its_running_drive() -> None:
    """The continual planner's task reaches the drive its executing line runs, though
    the beliefs (busy, not idle) would give no action at all."""
    core = ContinualPlanner("robot1", DOMAIN, PlanningSettings(), improve=False)
    core.on_beliefs(floor(19.0, busy=True), 1.0)
    with pytest.raises(Unsolvable):  # nothing runs, as far as the planner knows
        core.task(GOAL)
    core.line = Line(
        "p", Purpose.NEW, 0.0, steps=[ScheduledAction(0.0, DRIVE, 2.0)], step_ids=["p-1"]
    )
    core.line.statuses[0], core.line.began[0] = "running", 0.0
    task = core.task(GOAL)
    assert DRIVE in {a.name for a in task.actions}


def test_a_busy_robot_s_goal_behind_something_that_moves_is_blocked_not_unsolvable() -> None:
    """Mid-drive a cart takes the cell beyond: the failed search is told blocked (wait
    for the cart), judged from what the drive started from, not from the beliefs alone
    (busy, not idle: from them nothing could start, moving things or not)."""
    core = ContinualPlanner(
        "robot1", DOMAIN, PlanningSettings(), improve=False, transients=Transients(["clear"])
    )
    core.on_beliefs(floor(20.0, busy=False), 0.0)  # every cell seen clear
    cart = floor(19.0, busy=True).removing([fact("clear", "c_3_1")])
    core.on_beliefs(cart, 1.0)
    assert core._blocked(GOAL) is False  # nothing runs, as far as the planner knows
    core.line = Line(
        "p", Purpose.NEW, 0.0, steps=[ScheduledAction(0.0, DRIVE, 2.0)], step_ids=["p-1"]
    )
    core.line.statuses[0], core.line.began[0] = "running", 0.0
    assert core._blocked(GOAL) is True
    assert core.groundings.blocked(cart, GOAL, core.held()) in (True, None)
    assert core.transients.blocked(DOMAIN, cart, GOAL, core.held()) is True
    assert core.transients.blocked(DOMAIN, cart, GOAL) is False
