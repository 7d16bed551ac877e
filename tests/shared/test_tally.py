"""The planner tally: plans, replans by purpose, forecast repairs, rounds, forecasts."""

from __future__ import annotations

from cbdi import keys
from cbdi.tally import KEYS, SCHEMAS, PlannerTally
from cbdi.wire.agent import PartialPlan, PlanStep
from cbdi.wire.base import Message
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound

A = "robot1"


def step(plan_id: str, n: int) -> PlanStep:
    args = [A, "c_0_0", "c_1_0"]
    return PlanStep(step_id=f"{plan_id}-{n}", action="move", args=args, start=n, duration=1.0)


def request(kind: str, desire: str = "recycle", rid: str = "s1") -> tuple[str, Message]:
    msg = SearchRequest(agent=A, request_id=rid, kind=kind, desire=desire)
    return keys.planner_requests(A), msg


def plan(
    plan_id: str,
    baseline: str = "",
    steps: int = 2,
    after: str = "",
    complete: bool = False,
    rid: str = "",
    purpose: str = "",
) -> tuple[str, Message]:
    msg = PartialPlan(
        agent=A,
        plan_id=plan_id,
        baseline=baseline,
        steps=[step(plan_id, i + 1) for i in range(steps)],
        complete=complete,
        applies_after=after,
        request_id=rid,
        purpose=purpose,
    )
    return keys.planner_plans(A), msg


def round_(plan_id: str, purpose: str, expanded: int = 10) -> tuple[str, Message]:
    msg = SearchRound(
        agent=A,
        request_id="s1",
        plan_id=plan_id,
        purpose=purpose,
        number=1,
        kind="best",
        mode="G",
        expanded=expanded,
        seconds=0.25,
        best_h=3,
        plan_actions=2,
        time=0.0,
    )
    return keys.planner_rounds(A), msg


def forecast(kind: str, plan_id: str = "p1") -> tuple[str, Message]:
    msg = ForecastReport(
        agent=A, plan_id=plan_id, kind=kind, failed_step="", reason="", committed="", time=1.0
    )
    return keys.planner_forecasts(A), msg


def fold(*messages: tuple[str, Message], agents: tuple[str, ...] = ()) -> PlannerTally:
    tally = PlannerTally(agents)
    for key, msg in messages:
        tally.observe(key, msg)
    return tally


def test_online_run_counts_repairs_revisions_improvements_and_fresh_searches() -> None:
    tally = fold(
        request("start"),
        round_("p1", "new"),
        plan("p1"),
        round_("p1", "new"),
        plan("p1", baseline="p1", complete=True),  # a continuation: the same plan
        round_("p2", "improve"),  # no better plan: nothing published
        request("start", rid="s2"),  # a step was refused: search again, same intention
        round_("p3", "new"),
        plan("p3", steps=5),
        forecast("holds", "p3"),
        forecast("fails_after_committed", "p3"),
        round_("p4", "repair"),
        plan("p4", baseline="p3-2", after="p3-2"),
        forecast("fails_after_committed", "p4"),
        round_("p5", "repair"),  # outdated: no plan
        round_("p6", "improve"),
        plan("p6", baseline="p4-1", after="p4-1", complete=True),
        request("cancel", rid="s2"),  # dropped
        request("start", rid="s3"),  # adopted again: a new intention
        round_("p7", "new"),
        plan("p7"),
        request("revise", rid="s3"),
        round_("p8", "revise"),
        plan("p8", baseline="p7-1", after="p7-1"),
    )
    c = tally.counts(A)
    assert (c.plans, c.replans, c.forecast_repairs, c.improvements) == (6, 4, 1, 1)
    assert c.replans_by == {"new": 1, "repair": 1, "revise": 1, "improve": 1}
    assert (c.search_rounds, c.expanded, c.search_seconds) == (9, 90, 2.25)
    assert c.rounds_by == {"new": 4, "repair": 2, "revise": 1, "improve": 2}
    assert c.forecasts == {"fails_in_committed": 0, "fails_after_committed": 2, "holds": 1}
    line = tally.line(A, "p1")
    assert line is not None and (line.steps, line.complete, line.replan) == (4, True, False)


def test_offline_plans_after_the_first_of_an_intention_are_replans() -> None:
    tally = fold(
        request("start"),
        plan("p1", complete=True),
        request("start", rid="s2"),  # the plan failed: a new search for the same desire
        plan("p2", complete=True),
        request("revise", rid="s2"),
        plan("p3", complete=True),
        request("start", desire="other", rid="s3"),  # another desire: a new intention
        plan("p4", complete=True),
    )
    c = tally.counts(A)
    assert (c.plans, c.replans, c.search_rounds, c.forecast_repairs) == (4, 2, 0, 0)
    assert c.replans_by == {"new": 1, "repair": 0, "revise": 1, "improve": 0}


def test_a_plan_counts_in_its_requests_intention_whichever_arrives_first() -> None:
    """The scheduler's requests and the planner's plans come from two senders: a plan
    may arrive before the request it answers, or after the next one."""
    first = [request("start", rid="s1"), plan("p1", rid="s1", purpose="new")]
    repair = [plan("p2", "p1-1", after="p1-1", rid="s1", purpose="repair")]
    home = [
        request("cancel", rid="s1"),
        request("start", desire="go_home", rid="s2"),
        plan("p3", rid="s2", purpose="new"),
    ]
    in_order = fold(*first, *repair, *home)
    # The repair overtaken by the next intention's requests; the new plan overtaking its
    # own request.
    shuffled = fold(*first, home[0], home[2], home[1], *repair)
    for tally in (in_order, shuffled):
        c = tally.counts(A)
        assert (c.plans, c.replans, c.forecast_repairs) == (3, 1, 1)
        assert c.replans_by == {"new": 0, "repair": 1, "revise": 0, "improve": 0}
    line = shuffled.line(A, "p3")
    assert line is not None and not line.replan


def test_an_offline_plan_says_its_purpose() -> None:
    revise = request("revise", rid="s1")
    tally = fold(request("start"), plan("p1", rid="s1", purpose="new"), revise)
    tally.observe(*plan("p2", rid="s1", purpose="new"))  # searched before the revise came
    assert tally.counts(A).replans_by == {"new": 1, "repair": 0, "revise": 0, "improve": 0}


def test_a_round_after_its_plan_still_names_the_purpose() -> None:
    tally = fold(request("start"), plan("p1"), plan("p2", "p1-1", after="p1-1"))
    assert tally.counts(A).replans_by["new"] == 1
    tally.observe(*round_("p2", "repair"))
    assert tally.counts(A).forecast_repairs == 1
    assert tally.counts(A).replans_by["repair"] == 1


def test_plans_the_scheduler_passes_on_are_not_counted_again() -> None:
    key, msg = plan("p1")
    tally = fold((key, msg), (keys.scheduler_plans(A), msg))
    assert tally.counts(A).plans == 1
    assert tally.observe(keys.scheduler_plans(A), msg) is None


def test_without_requests_every_plan_after_the_first_is_a_replan() -> None:
    # A planner restarted: its plan ids start again, the baseline tells a new plan apart.
    tally = fold(plan("p1"), plan("p1", baseline="p1"), plan("p1"), plan("p2"))
    assert (tally.counts(A).plans, tally.counts(A).replans) == (3, 2)


def test_totals_and_summary_cover_registered_agents_with_zeros() -> None:
    tally = fold(request("start"), plan("p1"), plan("p2"), agents=("robot2",))
    summary = tally.summary()
    assert sorted(summary["agents"]) == ["robot1", "robot2"]
    assert summary["agents"]["robot2"]["replans"] == 0
    assert summary["total"]["replans"] == 1 and summary["total"]["plans"] == 2
    assert tally.counts("nobody").plans == 0


def test_keys_and_schemas_name_the_planner_streams() -> None:
    assert keys.planner_rounds("*") in KEYS and keys.planner_requests("*") in KEYS
    assert "cbdi.planner.SearchRound/1" in SCHEMAS and "cbdi.agent.PartialPlan/1" in SCHEMAS
