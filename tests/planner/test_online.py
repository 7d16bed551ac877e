"""The planner service's online core: partial plans, forecast, repair, revise, outdated."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from msgspec.structs import replace

from cbdi.agentfile import PlanningSettings
from cbdi.beliefs import BeliefSet
from cbdi.wire.agent import ActionStatus, PartialPlan
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound, SearchStatus
from cbdi_planner.agent.continual import ContinualPlanner
from cbdi_planner.agent.errors import BadRequestError, UnknownPlanError
from cbdi_planner.agent.lines import Purpose
from cbdi_planner.agent.transient import Transients
from cbdi_planner.pddl import parse_domain

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = parse_domain((ROOT / "domains/recycling/pddl/domain.pddl").read_text(), "domain.pddl")
W = 5  # a 5x1 corridor: bin at c_0_0, robot at c_1_0, litter at c_4_0


def beliefs(robot: str = "c_1_0", blocked: tuple[str, ...] = ()) -> BeliefSet:
    cells = [f"c_{x}_0" for x in range(W)]
    facts: list[tuple[str, ...]] = [("map_loaded",), ("in", "robot1", robot)]
    facts += [("near", a, b) for a, b in itertools.pairwise(cells)]
    facts += [("near", b, a) for a, b in itertools.pairwise(cells)]
    facts += [("free", c) for c in cells[1:] if c != robot and c not in blocked]
    facts += [("bin_pose", "bin1", "c_0_0"), ("litter_pose", "p1", "c_4_0")]
    facts += [("litter_pose", "p2", "c_3_0")]
    instances = {"robot1": "robot", "bin1": "bin", "p1": "plastic", "p2": "plastic"}
    instances.update({c: "cell" for c in cells})
    fluents = {("loaded_amount", "robot1"): 0.0, ("detection_depth", "robot1"): 1.0}
    return BeliefSet(instances=instances, facts=frozenset(facts), fluents=fluents)


def planner(life: int = 0, **kw: object) -> ContinualPlanner:
    settings = PlanningSettings(round_interval=0, expansions_per_round=3, plan_size_limit=2, **kw)  # type: ignore[arg-type]
    core = ContinualPlanner("robot1", DOMAIN, settings, improve=False, life=life)
    core.on_beliefs(beliefs(), 0.0)
    return core


def request(kind: str = "start", goal: tuple[str, ...] = ("p1",)) -> SearchRequest:
    return SearchRequest(
        agent="robot1",
        request_id="s1",
        kind=kind,
        desire="recycle",
        goal=[["recycled", g] for g in goal],
    )


def drain(core: ContinualPlanner, limit: int = 200) -> list[object]:
    out: list[object] = []
    while core.search is not None and limit:
        search = core.search
        out += core.after_round(search, core.round(search))
        limit -= 1
    return out


def test_partial_plans_continue_one_plan_until_complete() -> None:
    core = planner()
    assert isinstance(core.on_request(request())[0], SearchStatus)
    out = drain(core)
    plans = [m for m in out if isinstance(m, PartialPlan)]
    assert len(plans) >= 2 and plans[-1].complete and not any(p.complete for p in plans[:-1])
    assert plans[0].baseline == "" and all(p.baseline == plans[0].plan_id for p in plans[1:])
    ids = [s.step_id for p in plans for s in p.steps]
    assert ids == [f"{plans[0].plan_id}-{k}" for k in range(1, len(ids) + 1)]
    starts = [s.start for p in plans for s in p.steps]
    assert starts == sorted(starts) and starts[0] == 0.0  # at once: the executor acts
    # after the planner in the same epoch, so a step planned now starts now (no gap)
    assert any(isinstance(m, SearchRound) for m in out)
    assert [m.status for m in out if isinstance(m, SearchStatus)] == ["done"]
    assert core.on_request(request()) == []  # the same request again: already on it


def run_first_steps(core: ContinualPlanner, n: int) -> PartialPlan:
    core.on_request(request())
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    first = plans[0]
    line = core.line
    assert line is not None
    for k in range(n):
        core.on_status(
            ActionStatus(
                agent="robot1",
                plan_id=first.plan_id,
                step_id=line.step_ids[k],
                action="move",
                status="succeeded" if k < n - 1 else "running",
                reason="",
                time=float(k),
            )
        )
    return first


def test_a_forecast_failure_after_the_committed_part_starts_a_repair() -> None:
    core = planner()
    first = run_first_steps(core, 1)  # moving c_1_0 -> c_2_0
    assert core.on_beliefs(beliefs(), 0.5) and core.search is None  # holds: reported once
    out = core.on_beliefs(beliefs(blocked=("c_3_0",)), 1.0)  # someone stands ahead
    report = next(m for m in out if isinstance(m, ForecastReport))
    assert report.kind == "fails_after_committed" and report.failed_step == f"{first.plan_id}-2"
    assert report.committed == f"{first.plan_id}-1"
    assert core.search is not None and core.search.purpose is Purpose.REPAIR
    repair = [m for m in drain(core) if isinstance(m, PartialPlan)]
    # The person blocks the only way: no repair exists, the executing plan goes on.
    assert repair == [] and core.line is not None and core.line.plan_id == first.plan_id


def test_purposes_go_out_as_the_words_recordings_hold() -> None:
    """Plans and rounds carry the purpose's word, a plain string (the monitor counts by it)."""
    assert [p.value for p in Purpose] == ["new", "repair", "revise", "improve"]
    core = planner()
    core.on_request(request())
    said = [m.purpose for m in drain(core) if isinstance(m, PartialPlan | SearchRound)]
    assert said and all(type(p) is str and p == "new" for p in said)
    core = planner()
    run_first_steps(core, 1)
    core.on_request(request("revise", ("p2",)))
    said = [m.purpose for m in drain(core) if isinstance(m, PartialPlan | SearchRound)]
    assert said and all(type(p) is str and p == "revise" for p in said)


def test_a_revised_goal_replaces_the_plan_after_the_committed_step() -> None:
    core = planner()
    first = run_first_steps(core, 1)
    assert core.on_request(request("revise", ("p2",))) == []
    assert core.search is not None and core.search.purpose is Purpose.REVISE
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert plans and plans[0].plan_id != first.plan_id
    assert plans[0].applies_after == f"{first.plan_id}-1" == plans[0].baseline
    names = [" ".join([s.action, *s.args]) for p in plans for s in p.steps]
    assert any("p1" in n for n in names) and any("p2" in n for n in names)  # the union
    assert plans[-1].complete


def test_a_repair_is_dropped_when_execution_commits_past_it() -> None:
    core = planner()
    first = run_first_steps(core, 1)
    core.on_request(request("revise", ("p2",)))
    search = core.search
    assert search is not None
    line = search.repairs
    assert line is not None
    core.on_status(
        ActionStatus(
            agent="robot1",
            plan_id=first.plan_id,
            step_id=line.step_ids[1],
            action="move",
            status="running",
            reason="",
            time=1.0,
        )
    )
    out = core.after_round(search, core.round(search))
    assert core.search is None and not any(isinstance(m, PartialPlan) for m in out)


# -- bad input: each is refused with an error naming what and where ------------------------
CORRIDOR = """(define (problem corridor) (:domain recycling)
  (:objects robot1 - robot bin1 - bin p1 - plastic c_0_0 c_1_0 c_2_0 - cell)
  (:init (map_loaded) (in robot1 c_1_0) (free c_0_0) (free c_2_0)
         (near c_0_0 c_1_0) (near c_1_0 c_0_0) (near c_1_0 c_2_0) (near c_2_0 c_1_0)
         (bin_pose bin1 c_0_0) (litter_pose p1 c_2_0)
         (= (loaded_amount robot1) 0) (= (detection_depth robot1) 1))
  (:goal (and (recycled p1))))
"""


def test_a_request_may_carry_its_own_pddl_problem() -> None:
    settings = PlanningSettings(round_interval=0, expansions_per_round=50)
    core = ContinualPlanner("robot1", DOMAIN, settings, improve=False)
    out = core.on_request(
        SearchRequest(agent="robot1", request_id="s1", kind="start", problem=CORRIDOR)
    )
    assert [m.status for m in out if isinstance(m, SearchStatus)] == ["searching"]
    assert core.request is not None and core.request.goal == [["recycled", "p1"]]
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert plans and plans[-1].complete
    actions = [s.action for p in plans for s in p.steps]
    assert actions == ["move", "litter_pickup", "move", "recycle"]


def test_a_problem_that_does_not_parse_is_refused_with_its_position() -> None:
    core = planner()
    broken = CORRIDOR.replace("(:goal (and (recycled p1))))", "(:goal (and (recycled p1)")
    with pytest.raises(BadRequestError, match=r"request s9:\d+:\d+") as err:
        core.on_request(
            SearchRequest(agent="robot1", request_id="s9", kind="start", problem=broken)
        )
    assert err.value.code == "bad_request"
    assert core.search is None and ("in", "robot1", "c_1_0") in core.beliefs.facts


def test_a_goal_over_an_unknown_predicate_is_refused() -> None:
    core = planner()
    req = SearchRequest(agent="robot1", request_id="s2", kind="start", goal=[["shiny", "p1"]])
    with pytest.raises(BadRequestError, match="no predicate 'shiny'"):
        core.on_request(req)
    assert core.search is None
    core.on_request(request())  # and the next good request is served
    assert core.search is not None


def test_a_bad_request_leaves_the_executing_plan_and_its_search_as_they_were() -> None:
    core = planner()
    first = run_first_steps(core, 1)
    line, search, req = core.line, core.search, core.request
    bad = SearchRequest(agent="robot1", request_id="s2", kind="start", goal=[["shiny", "p1"]])
    with pytest.raises(BadRequestError, match="no predicate 'shiny'"):
        core.on_request(bad)
    assert (core.line, core.search, core.request) == (line, search, req)
    # and the executing plan is still forecast and repaired
    out = core.on_beliefs(beliefs(blocked=("c_3_0",)), 1.0)
    report = next(m for m in out if isinstance(m, ForecastReport))
    assert report.plan_id == first.plan_id and report.kind == "fails_after_committed"


def test_a_goal_behind_a_person_is_blocked_one_behind_a_bin_unsolvable() -> None:
    core = ContinualPlanner(
        "robot1", DOMAIN, PlanningSettings(round_interval=0), transients=Transients(["free"])
    )
    core.on_beliefs(beliefs(), 0.0)  # every cell but the bin's seen free
    core.on_beliefs(beliefs(blocked=("c_3_0",)), 1.0)  # a person stands in the corridor

    def failures(core: ContinualPlanner, req: SearchRequest) -> list[tuple[bool, str]]:
        out = core.on_request(req) + drain(core)
        return [(m.blocked, m.reason) for m in out if getattr(m, "status", "") == "failed"]  # type: ignore[attr-defined]

    [(blocked, reason)] = failures(core, request())
    assert blocked and "waiting" in reason and core.search is None
    # The bin's cell was never free: nothing that moves can make it so.
    goal = SearchRequest(
        agent="robot1", request_id="s3", kind="start", goal=[["in", "robot1", "c_0_0"]]
    )
    assert [b for b, _ in failures(core, goal)] == [False]
    # The person went: the same request plans.
    core.on_beliefs(beliefs(), 2.0)
    out = core.on_request(request()) + drain(core)
    assert any(isinstance(m, PartialPlan) and m.complete for m in out)
    # An agent that declares no transient predicates never waits.
    plain = planner()
    plain.on_beliefs(beliefs(blocked=("c_3_0",)), 1.0)
    assert [b for b, _ in failures(plain, request())] == [False]


def test_a_status_for_a_plan_never_published_is_refused() -> None:
    core = planner()
    core.on_request(request())
    drain(core)
    with pytest.raises(UnknownPlanError, match="robot9-plan-1"):
        core.on_status(status("robot9-plan-1", "robot9-plan-1-1", "running"))
    assert core.line is not None
    core.on_status(status(core.line.plan_id, core.line.step_ids[0], "running"))
    assert core.line.statuses == {0: "running"}


def test_a_restarted_planner_numbers_its_plans_apart_and_lets_its_predecessors_go() -> None:
    """After a restart (`life` 1) the plan ids are `robot1-plan-r1-N`, never a reused
    `robot1-plan-1`; the executor's statuses of the predecessor's plans are no error."""
    core = planner(life=1)
    core.on_request(request())
    drain(core)
    assert core.line is not None and core.line.plan_id == "robot1-plan-r1-1"
    core.on_status(status("robot1-plan-3", "robot1-plan-3-9", "succeeded"))  # the predecessor's
    with pytest.raises(UnknownPlanError):  # this life's own number, never published
        core.on_status(status("robot1-plan-r1-7", "robot1-plan-r1-7-1", "running"))
    with pytest.raises(UnknownPlanError):  # a first life knows no predecessor
        planner().on_status(status("robot1-plan-3", "robot1-plan-3-9", "succeeded"))


def status(plan_id: str, step_id: str, what: str) -> ActionStatus:
    return ActionStatus(
        agent="robot1",
        plan_id=plan_id,
        step_id=step_id,
        action="move",
        status=what,
        reason="",
        time=0.0,
    )


def test_a_search_after_a_cancel_follows_the_step_still_running() -> None:
    """A desire dropped (cancel) while a move runs, another taken up (start): the new
    plan starts where the move leaves the robot, after it (the executor lets it end)."""
    core = planner()
    first = run_first_steps(core, 1)  # moving c_1_0 -> c_2_0
    core.on_request(replace(request(), kind="cancel"))
    assert core.search is None
    core.on_request(replace(request(goal=("p2",)), request_id="s2"))
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert plans[0].applies_after == f"{first.plan_id}-1"
    step = plans[0].steps[0]
    assert step.args[:2] == ["robot1", "c_2_0"] and step.start >= 1.0


def test_a_search_follows_a_step_of_the_plan_the_executing_one_replaced() -> None:
    """The executing line is a replacement (a revised goal) queued after a move of the
    line it replaced, which still runs: a new search follows that move."""
    core = planner()
    first = run_first_steps(core, 1)
    core.on_request(request("revise", ("p2",)))
    revised = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert core.line is not None and core.line.plan_id == revised[0].plan_id != first.plan_id
    core.on_request(replace(request(goal=("p2",)), request_id="s2"))
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert plans[0].applies_after == f"{first.plan_id}-1"
    assert plans[0].steps[0].args[:2] == ["robot1", "c_2_0"]


def test_a_step_of_another_plan_taken_up_ends_the_running_one() -> None:
    """An executor killed mid-move never reports the move's end; its successor takes up
    the next plan's step (or refuses it): the move is over, and a search after that no
    longer follows it (a killed executor's stale move made every later plan start where
    that move would have left the robot, and every one was refused)."""
    core = planner()
    first = run_first_steps(core, 1)  # moving c_1_0 -> c_2_0, then the executor is killed
    core.on_request(request("revise", ("p2",)))
    revised = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert core.running_line() is not None  # the move still runs, as far as we know
    for what in ("refused", "running"):
        core.on_status(status(revised[0].plan_id, revised[0].steps[0].step_id, what))
        assert core.running_line() is (core.line if what == "running" else None)
        assert all(st != "running" for p in core.previous for st in p.statuses.values())
    core.on_request(replace(request(goal=("p2",)), request_id="s2"))
    plans = [m for m in drain(core) if isinstance(m, PartialPlan)]
    assert plans and plans[0].applies_after != f"{first.plan_id}-1"


def test_a_new_plan_whose_complete_search_ran_into_a_dead_end_searches_the_whole_space() -> None:
    """The complete search's partial plans (a to b to c) lead where the fuel runs out
    before e; its exhausted space after them proves nothing. A search of the whole space
    from the committed state replaces them with the plan that refuels first."""
    from test_continual import ROAD

    trip = """(define (problem trip) (:domain road)
      (:objects a b c d e - place)
      (:init (at a) (depot a) (road a b) (road b a) (road b c) (road c d) (road d e)
             (= (fuel) 3))
      (:goal (at e)))"""
    settings = PlanningSettings(
        round_interval=0, expansions_per_round=3, plan_size_limit=2, min_commit_steps=0
    )
    domain = parse_domain(ROAD.replace("(assign (fuel) 3)", "(assign (fuel) 4)"))
    core = ContinualPlanner("robot1", domain, settings, improve=False)
    req = SearchRequest(
        agent="robot1", request_id="s1", kind="start", desire="go", goal=[], problem=trip
    )
    out = core.on_request(req) + drain(core)
    plans = [m for m in out if isinstance(m, PartialPlan)]
    assert [s.action for s in plans[0].steps] == ["go"] and not plans[0].complete
    last = plans[-1]
    assert last.complete and last.baseline == ""  # a line of its own, from the start
    assert [(s.action, s.args) for s in last.steps] == [
        ("refuel", ["a"]),
        ("go", ["a", "b"]),
        ("go", ["b", "c"]),
        ("go", ["c", "d"]),
        ("go", ["d", "e"]),
    ]
    assert [m.status for m in out if isinstance(m, SearchStatus)] == ["searching", "done"]
