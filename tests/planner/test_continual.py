"""Continual search (Algorithms 1 and 2), commitment and the failure forecast."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from planning import validate
from test_disjunction import LIGHTS, LIGHTS_PROBLEM

from cbdi_planner.continual import (
    COMMITTED_FAILS,
    FAILS_LATER,
    HOLDS,
    NG,
    ImprovedPlan,
    ModeChanged,
    Outdated,
    PartialPlanFound,
    RoundBound,
    RoundDone,
    SearchFailed,
    SearchThread,
    Sensed,
    commit,
    forecast,
)
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.search import search
from cbdi_planner.simulate import validate as simulate_validate
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
PAPER = ROOT / "domains/recycling/problems/paper-7x7.pddl"
KAIROS = Path(sys.executable).parent / "kairos"


def load(text: str | None = None) -> Task:
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    return ground(domain, parse_problem(text or PAPER.read_text(), domain, str(PAPER)))


@pytest.fixture(scope="module")
def task() -> Task:
    return load()


def run(thread: SearchThread, bound: RoundBound, limit: int = 500) -> list[object]:
    events: list[object] = []
    while not thread.finished and limit:
        events += thread.step(bound)
        limit -= 1
    return events


def whole(events: list[object]) -> Plan:
    parts = [e.plan for e in events if isinstance(e, PartialPlanFound)]
    return Plan(tuple(sorted((a for p in parts for a in p.actions), key=lambda a: a.time)))


def kairos_valid(plan: Plan, tmp_path: Path, problem: Path = PAPER) -> None:
    out = tmp_path / "plan.txt"
    out.write_text(plan.to_ipc())
    done = subprocess.run(
        [str(KAIROS), "validate", str(DOMAIN), str(problem), str(out)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_rounds_hand_out_partial_plans_that_add_up_to_a_valid_plan(
    task: Task, tmp_path: Path
) -> None:
    thread = SearchThread(task, initial_state(task))
    events = run(thread, RoundBound(expansions=10, plan_size=6))
    parts = [e for e in events if isinstance(e, PartialPlanFound)]
    assert len(parts) >= 4  # execution could start long before the plan is complete
    assert [p.baseline for p in parts] == list(range(len(parts)))
    assert [p.complete for p in parts] == [False] * (len(parts) - 1) + [True]
    starts = [p.plan.actions[0].time for p in parts]
    assert starts == sorted(starts)  # each continues after the previous one
    kairos_valid(whole(events), tmp_path)
    rounds = [e for e in events if isinstance(e, RoundDone)]
    assert all(r.expanded <= 10 for r in rounds)


def test_expansion_bounded_rounds_are_deterministic(task: Task) -> None:
    def plans() -> list[str]:
        events = run(SearchThread(task, initial_state(task)), RoundBound(expansions=7))
        return [e.plan.to_ipc() for e in events if isinstance(e, PartialPlanFound)]

    assert plans() == plans()


def test_outdated_when_execution_committed_past_the_prefix(task: Task) -> None:
    thread = SearchThread(task, initial_state(task), prefix=2)
    assert not any(isinstance(e, Outdated) for e in thread.step(RoundBound(expansions=5), 2))
    events = thread.step(RoundBound(expansions=5), committed=3)
    assert isinstance(events[-1], Outdated) and thread.finished


def test_greedy_falls_back_to_complete_search_then_reports_unsolvable() -> None:
    walled = (
        PAPER.read_text()
        .replace("(near c_5_0 c_6_0)", "")
        .replace("(near c_6_0 c_5_0)", "")
        .replace("(near c_6_2 c_6_3)", "")
        .replace("(near c_6_3 c_6_2)", "")
    )
    thread = SearchThread(load(walled), initial_state(load(walled)))
    events = run(thread, RoundBound(expansions=50))
    kinds = [type(e) for e in events if not isinstance(e, RoundDone)]
    assert kinds == [ModeChanged, SearchFailed]
    assert "complete search" in events[-1].reason  # type: ignore[attr-defined]
    assert events[-1].proved  # type: ignore[attr-defined]  # it never re-rooted


ROAD = """(define (domain road)
  (:requirements :strips :typing :fluents :durative-actions)
  (:types place)
  (:predicates (at ?p - place) (road ?p ?q - place) (depot ?p - place))
  (:functions (fuel))
  (:durative-action go
    :parameters (?p ?q - place)
    :duration (= ?duration 1)
    :condition (and (at start (at ?p)) (at start (road ?p ?q)) (at start (>= (fuel) 1)))
    :effect (and (at start (not (at ?p))) (at start (decrease (fuel) 1)) (at end (at ?q))))
  (:durative-action refuel
    :parameters (?p - place)
    :duration (= ?duration 1)
    :condition (and (at start (at ?p)) (at start (depot ?p)))
    :effect (at end (assign (fuel) 3))))"""
# One-way roads a -> b -> c -> d, fuel for two legs: refuel at a first. The relaxed
# graph never runs out of fuel, so going to b looks like progress.
TRIP = """(define (problem trip) (:domain road)
  (:objects a b c d - place)
  (:init (at a) (depot a) (road a b) (road b c) (road c d) (= (fuel) 2))
  (:goal (at d)))"""


def test_an_exhausted_search_that_re_rooted_proves_nothing_the_whole_search_does() -> None:
    """The complete search re-roots on its partial plan (go to b) and exhausts there
    (out of fuel at c): not a proof (`proved` False). Searching the whole space from
    the origin, handing out only the plan that reaches the goal, finds it."""
    domain = parse_domain(ROAD)
    trip = ground(domain, parse_problem(TRIP, domain))
    bound = RoundBound(expansions=1, plan_size=1)
    events = run(SearchThread(trip, initial_state(trip), mode=NG), bound)
    sent = [e for e in events if isinstance(e, PartialPlanFound)]
    assert [a.name for e in sent for a in e.plan.actions] == ["go a b"]
    assert isinstance(events[-1], SearchFailed) and not events[-1].proved
    whole = SearchThread(trip, initial_state(trip), mode=NG, whole=True)
    events = run(whole, bound)
    [plan] = [e for e in events if isinstance(e, PartialPlanFound)]
    assert plan.complete and plan.baseline == 0
    assert [a.name for a in plan.plan.actions] == ["refuel a", "go a b", "go b c", "go c d"]
    simulate_validate(trip, plan.plan)
    with pytest.raises(ValueError, match="complete search"):
        SearchThread(trip, initial_state(trip), whole=True)


def test_improving_mode_sends_only_a_better_plan(task: Task) -> None:
    events = run(
        SearchThread(task, initial_state(task), improving=True, improve_on=1000.0),
        RoundBound(expansions=50),
    )
    assert not any(isinstance(e, PartialPlanFound) for e in events)
    better = [e for e in events if isinstance(e, ImprovedPlan)]
    assert len(better) == 1 and better[0].plan.makespan < 1000.0
    events = run(
        SearchThread(task, initial_state(task), improving=True, improve_on=1.0),
        RoundBound(expansions=50),
    )
    assert not any(isinstance(e, ImprovedPlan) for e in events)


def block(task: Task, state: State, cell: str) -> State:
    return replace(state, facts=state.facts & ~(1 << task.facts.index(f"(free {cell})")))


def test_forecast_classifies_failures_by_the_committed_part(task: Task) -> None:
    plan = search(task).plan
    assert plan is not None
    steps = plan.actions
    assert forecast(task, steps, {}).kind == HOLDS
    moves = [k for k, a in enumerate(steps) if a.name.startswith("move")]
    fourth = steps[moves[3]].name.split()[-1]
    blocked = replace(task, init_facts=block(task, initial_state(task), fourth).facts)
    later = forecast(blocked, steps, {0: "succeeded", 1: "running"})
    assert later.kind == FAILS_LATER and later.failed == moves[3]
    assert f"(free {fourth})" in later.reason
    assert later.commitment.count == 2 and later.commitment.state is not None
    soon = forecast(blocked, steps, {0: "succeeded", 1: "running"}, min_commit_steps=5)
    assert soon.kind == COMMITTED_FAILS
    short = forecast(blocked, steps, {0: "succeeded", 1: "running"}, horizon=1)
    assert short.kind == HOLDS  # the refinement: look only one action ahead


def test_commit_counts_started_steps_and_simulates_them(task: Task) -> None:
    plan = search(task).plan
    assert plan is not None
    done = commit(task, plan.actions, {0: "succeeded", 1: "succeeded", 2: "running"})
    assert (done.finished, done.count) == (2, 3)
    robot_at = plan.actions[2].name.split()[-1]
    assert done.state is not None
    assert f"(in robot1 {robot_at})" in task.fact_names(done.state.facts)


def _loaded(task: Task, state: State) -> float:
    return state.nums[task.num_vars.index("(loaded_amount robot1)")]


def _through(task: Task, steps: tuple[ScheduledAction, ...], last: int, part: str) -> State:
    """The beliefs once steps 0..last-1 ended and step `last` started (`part`: "start")
    or ended ("end"): what the world's percepts show then."""
    state = initial_state(task)
    for a in steps[:last]:
        state = simulate_state(task, a, state, "end")
    return simulate_state(task, steps[last], state, part)


def simulate_state(task: Task, step: ScheduledAction, state: State, part: str) -> State:
    (action,) = [a for a in task.actions if a.name == step.name]
    facts, nums = action.start.apply(state.facts, state.nums)
    if part == "end" and action.end is not None:
        facts, nums = action.end.apply(facts, nums)
    return State(facts, nums, state.open, state.til)


def _running_first(
    task: Task, action: str
) -> tuple[tuple[ScheduledAction, ...], int, dict[int, str]]:
    """A plan of `task`, the index of its first `action`, and statuses that have every
    step before it ended and it running."""
    plan = search(task).plan
    assert plan is not None
    k = next(i for i, a in enumerate(plan.actions) if a.name.startswith(action))
    return plan.actions, k, {**dict.fromkeys(range(k), "succeeded"), k: "running"}


def test_a_started_step_whose_end_the_beliefs_show_is_not_applied_again(task: Task) -> None:
    """The executor's `running` can come after the percepts that show the step ended (in
    lockstep the planner sees the executor's statuses an epoch late): a pickup's
    `increase` must not count twice, or the next pickup is forecast to break the
    capacity (a false failure and a needless repair)."""
    steps, k, statuses = _running_first(task, "litter_pickup")
    began = 10.0
    ended = _through(task, steps, k, "end")  # the percepts at the pickup's end
    beliefs = replace(task, init_facts=ended.facts, init_nums=ended.nums)
    at_end = Sensed(began + (steps[k].duration or 0.0), {k: began})
    done = commit(beliefs, steps, statuses, 1, at_end)
    assert done.state is not None and _loaded(task, done.state) == _loaded(task, ended)
    # Without the times (or before the end) the step is applied: counted twice.
    twice = commit(beliefs, steps, statuses, 1)
    assert twice.state is not None and _loaded(task, twice.state) == _loaded(task, ended) + 1


def test_a_started_step_mid_way_gets_its_end_once_and_its_start_not_again(task: Task) -> None:
    steps, k, statuses = _running_first(task, "recycle")
    began = 20.0
    started = _through(task, steps, k, "start")  # the recycle's `decrease` shows already
    beliefs = replace(task, init_facts=started.facts, init_nums=started.nums)
    mid = Sensed(began + 1.0, {k: began})
    done = commit(beliefs, steps, statuses, 1, mid)
    ended = _through(task, steps, k, "end")
    assert done.state is not None
    assert (done.state.facts, done.state.nums) == (ended.facts, ended.nums)
    # Beliefs sensed before the start (the same time) show none of it: all applied.
    before = _through(task, steps, k - 1, "end") if k else initial_state(task)
    early = replace(task, init_facts=before.facts, init_nums=before.nums)
    whole = commit(early, steps, statuses, 1, Sensed(began, {k: began}))
    assert whole.state is not None
    assert (whole.state.facts, whole.state.nums) == (ended.facts, ended.nums)


def test_a_step_stretched_past_its_planned_end_is_still_running_in_the_forecast(
    task: Task,
) -> None:
    """Past the planned end but without its end effects in the beliefs (the world
    stretched it), the step has not ended: its end is applied, once."""
    steps, k, statuses = _running_first(task, "litter_pickup")
    started = _through(task, steps, k, "start")
    beliefs = replace(task, init_facts=started.facts, init_nums=started.nums)
    late = Sensed(10.0 + 2 * (steps[k].duration or 0.0), {k: 10.0})
    done = commit(beliefs, steps, statuses, 1, late)
    assert done.state is not None and _loaded(task, done.state) == _loaded(task, started) + 1


# -- disjunctions: internal goal actions and actions split into copies -------------------


def parsed(domain_text: str, problem_text: str) -> Task:
    domain = parse_domain(domain_text, "domain.pddl")
    return ground(domain, parse_problem(problem_text, domain, "problem.pddl"))


@pytest.mark.parametrize("bound", [RoundBound(expansions=1), RoundBound(expansions=100)])
def test_partial_plans_for_a_disjunctive_goal_leave_out_the_goal_actions(
    bound: RoundBound, tmp_path: Path
) -> None:
    task = parsed(LIGHTS, LIGHTS_PROBLEM)
    assert any(a.internal for a in task.actions)
    events = run(SearchThread(task, initial_state(task)), bound)
    parts = [e for e in events if isinstance(e, PartialPlanFound)]
    assert parts and parts[-1].complete
    names = [a.name for p in parts for a in p.plan.actions]
    assert not any(name.startswith("#") for name in names)
    assert names[:2] == ["switch-on", "work"] and len(names) == 3
    assert all(r.plan_actions <= 3 for r in events if isinstance(r, RoundDone))
    files = (
        (tmp_path / "domain.pddl", LIGHTS),
        (tmp_path / "problem.pddl", LIGHTS_PROBLEM),
        (tmp_path / "plan.txt", whole(events).to_ipc()),
    )
    for path, text in files:
        path.write_text(text)
    valid, output = validate(*(path for path, _ in files))
    assert valid, output


DRY = """
(define (domain dry)
  (:requirements :typing :durative-actions :conditional-effects :disjunctive-preconditions)
  (:types item)
  (:predicates (dry ?x - item) (wet ?x - item) (sunny) (painted ?x - item)
               (shipped ?x - item) (at-dock ?x - item) (on-truck ?x - item)
               (loaded ?x - item))
  (:durative-action paint :parameters (?x - item) :duration (= ?duration 2)
    :condition (at start (not (painted ?x)))
    :effect (and (at start (not (dry ?x))) (at start (wet ?x)) (at end (painted ?x))
                 (at end (when (at start (dry ?x)) (and (dry ?x) (not (wet ?x)))))))
  (:action wipe :parameters (?x - item) :precondition (wet ?x)
    :effect (and (dry ?x) (not (wet ?x))))
  (:durative-action load :parameters (?x - item) :duration (= ?duration 1)
    :condition (at start (or (at-dock ?x) (on-truck ?x)))
    :effect (and (at start (not (at-dock ?x))) (at start (not (on-truck ?x)))
                 (at end (loaded ?x))))
  (:action bring :parameters (?x - item) :precondition () :effect (at-dock ?x))
  (:action stow :parameters (?x - item) :precondition (at-dock ?x)
    :effect (and (not (at-dock ?x)) (on-truck ?x)))
  (:action ship :parameters (?x - item) :precondition (and (painted ?x) (dry ?x))
    :effect (shipped ?x)))
"""


def dry_task(init: str) -> Task:
    problem = f"""(define (problem p) (:domain dry) (:objects a - item)
      (:init {init}) (:goal (and (shipped a) (loaded a))))"""
    return parsed(DRY, problem)


def test_a_started_split_action_is_the_copy_that_applies() -> None:
    """`paint a` is split by whether `a` was dry at its start: the first copy (dry at
    start, so dry again at its end) is wrong for an item that is not dry."""
    task = dry_task("(at-dock a)")
    copies = [a for a in task.actions if a.name == "paint a"]
    assert len(copies) == 2 and copies[0].start.pre  # the first copy needs (dry a)
    paint = ScheduledAction(0.0, "paint a", 2.0)
    steps = [paint, ScheduledAction(2.001, "ship a", None)]
    done = commit(task, steps, {0: "running"})
    assert done.state is not None and (done.count, done.finished) == (1, 0)
    assert set(task.fact_names(done.state.facts)) == {"(at-dock a)", "(painted a)", "(wet a)"}
    fails = forecast(task, steps, {0: "running"})
    assert fails.kind == FAILS_LATER and fails.failed == 1 and "(dry a)" in fails.reason
    dry = dry_task("(at-dock a) (dry a)")
    assert forecast(dry, steps, {0: "running"}).kind == HOLDS


def test_a_started_split_action_whose_start_shows_in_the_beliefs() -> None:
    """The beliefs already show `load a`'s start (`a` left the dock): no copy's start
    condition holds now, but the one whose only unmet facts its start changed fits."""
    task = dry_task("(dry a)")
    assert len([a for a in task.actions if a.name == "load a"]) == 2
    load = ScheduledAction(0.0, "load a", 1.0)
    done = commit(task, [load], {0: "running"})
    assert done.state is not None
    assert "(loaded a)" in task.fact_names(done.state.facts)


def test_a_started_split_action_that_no_copy_fits_is_not_applicable() -> None:
    task = dry_task("(at-dock a) (painted a)")  # both copies of paint need it unpainted
    steps = [ScheduledAction(0.0, "paint a", 2.0)]
    done = commit(task, steps, {0: "running"})
    assert done.state is None and done.reason == "(paint a) is not applicable"
    assert forecast(task, steps, {0: "running"}).kind == COMMITTED_FAILS


def test_the_agenda_reaches_the_goal_facts_one_at_a_time_in_valid_partial_plans(
    tmp_path: Path,
) -> None:
    """With the goal agenda the greedy rounds aim at one more goal fact at a time (the
    nearest), so on a map with many items the concatenated plan completes with fewer
    expansions than aiming at the whole goal at every step, and it stays valid."""
    problem = ROOT / "domains/recycling/problems/warehouse-15x15.pddl"
    task = load(problem.read_text())
    bound = RoundBound(expansions=20, plan_size=8)
    used = {}
    for agenda in (True, False):
        thread = SearchThread(task, initial_state(task), agenda=agenda)
        events = run(thread, bound, limit=3000)
        assert thread.finished and (thread.mode == "G" or not agenda)  # no fall-back needed
        parts = [e for e in events if isinstance(e, PartialPlanFound)]
        assert parts[-1].complete and not any(isinstance(e, SearchFailed) for e in events)
        plan = whole(events)
        simulate_validate(task, plan)
        if agenda:
            kairos_valid(plan, tmp_path, problem)
        used[agenda] = sum(e.expanded for e in events if isinstance(e, RoundDone))
    assert used[True] < used[False]


def test_the_agenda_aims_at_the_nearest_goal_first_and_falls_back_to_the_whole_goal(
    task: Task,
) -> None:
    from cbdi_planner.continual import NG, SearchSpace

    space = SearchSpace(task, initial_state(task), agenda=True)
    aim = space.expander.subgoal
    assert aim is not None and aim & task.goal == aim and aim.bit_count() == 1
    space.restart(NG, space.root)  # the complete search aims at the whole goal
    assert space.expander.subgoal is None
