"""The intention scheduler: plans passed on or replaced safely, preemption, retries."""

from __future__ import annotations

import pytest

from cbdi.beliefs import fact
from cbdi.wire.agent import ActionStatus, ArrestReport, PartialPlan, PlanStep
from cbdi_scheduler.desires import Desire
from cbdi_scheduler.intentions import Command, IntentionScheduler

RECYCLE = Desire("recycle", (fact("recycled", "a"),), 0.5, 100.0)
URGENT = Desire("urgent", (fact("safe"),), 0.9, 100.0)


def plan(plan_id: str, *ids: str, baseline: str = "", after: str = "") -> PartialPlan:
    steps = [PlanStep(step_id=i, action="move", args=[], start=0.0, duration=1.0) for i in ids]
    return PartialPlan(
        agent="r", plan_id=plan_id, baseline=baseline, steps=steps, applies_after=after
    )


def kinds(commands: list[Command]) -> list[str]:
    return [c.kind for c in commands]


def status(plan_id: str, step: str, state: str, reason: str = "") -> ActionStatus:
    return ActionStatus(
        agent="r",
        plan_id=plan_id,
        step_id=step,
        action="move",
        status=state,
        reason=reason,
        time=0.0,
    )


def arrested(plan_id: str, last: str) -> ArrestReport:
    return ArrestReport(agent="r", plan_id=plan_id, last_step=last, time=1.0, cancelled=[])


def running(policy: str = "clean_preempt") -> IntentionScheduler:
    s = IntentionScheduler(policy)
    assert kinds(s.choose(RECYCLE)) == ["start_search"]
    assert kinds(s.on_plan(plan("p1", "s1", "s2"))) == ["execute"]
    s.on_status(status("p1", "s1", "running"))
    return s


def test_continuations_are_passed_on() -> None:
    s = running()
    more = s.on_plan(plan("p2", "s3", baseline="p1"))
    assert kinds(more) == ["execute"] and more[0].plan is not None
    assert s.current is not None and s.current.steps == ["s1", "s2", "s3"]


def test_a_repair_is_passed_on_at_once_and_follows_the_steps_it_keeps() -> None:
    """No early arrest and no wait for its report: the executor runs the old plan up to
    `applies_after`, then the repair, with no idle epoch between them."""
    s = running()
    out = s.on_plan(plan("r1", "t1", baseline="committed", after="s1"))
    assert kinds(out) == ["execute"] and out[0].plan is not None
    assert out[0].plan.plan_id == "r1" and out[0].plan.applies_after == "s1"
    assert s.current is not None and s.current.plan_id == "r1" and not s.stopping
    # The kept step of the old plan still runs: its status counts, its failure replans.
    assert s.on_status(status("p1", "s2", "cancelled", "replaced by plan r1")) == []
    failed = s.on_status(status("p1", "s1", "failed", "blocked by person p"))
    assert kinds(failed) == ["start_search"] and "blocked by person p" in failed[0].reason
    assert s.current is not None and s.current.plan_id == ""


def test_a_boosted_goal_revises_the_search() -> None:
    s = running()
    bigger = Desire("recycle", (fact("recycled", "a"), fact("recycled", "b")), 0.5, 100.0)
    out = s.choose(bigger)
    assert kinds(out) == ["start_search"] and out[0].reason == "goal revised"
    assert s.choose(bigger) == []  # nothing new


def test_no_preempt_keeps_the_intention() -> None:
    s = running("no_preempt")
    assert s.choose(URGENT) == []
    assert s.current is not None and s.current.desire.name == "recycle"


def test_preempt_starts_the_new_desire_at_once() -> None:
    s = running("preempt")
    out = s.choose(URGENT)
    assert kinds(out) == ["cancel_search", "arrest", "start_search"]
    assert out[1].after_step == "s1"  # the running step finishes, nothing after it
    assert s.current is not None and s.current.desire.name == "urgent"


def test_clean_preempt_waits_for_the_robot_to_stop() -> None:
    s = running("clean_preempt")
    out = s.choose(URGENT)
    assert kinds(out) == ["cancel_search", "arrest"]
    assert s.current is not None and s.current.desire.name == "recycle"
    started = s.on_arrested(arrested("p1", "s1"))
    assert kinds(started) == ["start_search"] and started[0].desire == URGENT


def test_lower_priority_never_preempts() -> None:
    s = running("preempt")
    low = Desire("patrol", (fact("in", "r", "c"),), 0.1, 100.0)
    assert s.choose(low) == []


def test_execution_failures_replan_then_drop() -> None:
    s = IntentionScheduler(exec_retries=1)
    s.choose(RECYCLE)
    s.on_plan(plan("p1", "s1"))
    first = s.on_status(status("p1", "s1", "failed", "blocked by person p"))
    assert kinds(first) == ["start_search"] and "blocked by person p" in first[0].reason
    s.on_plan(plan("p2", "s2"))
    out = s.on_status(status("p2", "s2", "refused", "(free c) does not hold"))
    assert kinds(out)[-1] == "drop" and "execution failed 2 times" in out[-1].reason
    assert s.current is None


def test_planning_failures_retry_when_beliefs_change_then_drop() -> None:
    s = IntentionScheduler(plan_retries=2)
    s.choose(RECYCLE)
    assert s.retry() == []  # nothing failed: nothing to retry
    # The same beliefs would fail again: it waits for them to change, and says so.
    waits = s.on_search_failed("no plan")
    assert kinds(waits) == ["wait"] and "planning failed (no plan)" in waits[0].reason
    assert "when the beliefs change" in waits[0].reason
    retried = s.retry()
    assert kinds(retried) == ["start_search"] and "no plan" in retried[0].reason
    assert s.retry() == []  # once
    assert kinds(s.on_search_failed("no plan")) == ["wait"]
    out = s.on_search_failed("no plan")
    assert kinds(out) == ["cancel_search", "drop"] and "planning failed 3 times" in out[-1].reason


def test_a_blocked_goal_is_waited_out_not_dropped() -> None:
    s = IntentionScheduler(plan_retries=1)
    s.choose(RECYCLE)
    first = s.on_search_failed("the goal can never hold", blocked=True)
    assert kinds(first) == ["wait"] and first[0].desire == RECYCLE  # said once
    for _ in range(10):  # a person standing on the goal for ten belief changes
        assert kinds(s.retry()) == ["start_search"]
        assert s.on_search_failed("the goal can never hold", blocked=True) == []
    assert s.current is not None and s.current.plan_failures == 0
    assert kinds(s.retry()) == ["start_search"]
    assert kinds(s.on_plan(plan("p1", "s1"))) == ["execute"]  # the person moved on
    assert not s.current.waiting
    # A wait in which nothing changes (a person waiting for the robot that waits for it)
    # counts after wait_stall seconds, searches again, and is dropped at the limit.
    s3 = IntentionScheduler(plan_retries=1, wait_stall=5)
    s3.choose(RECYCLE)
    s3.on_search_failed("in the way", blocked=True, now=10)
    assert s3.stalled(14) == []
    assert kinds(s3.stalled(15)) == ["start_search"] and s3.current.plan_failures == 1
    s3.on_search_failed("in the way", blocked=True, now=15)
    out = s3.stalled(20)
    assert kinds(out) == ["cancel_search", "drop"] and "nothing moving" in out[-1].reason
    # Unsolvable failures still count and drop.
    s2 = IntentionScheduler(plan_retries=1)
    s2.choose(RECYCLE)
    assert kinds(s2.on_search_failed("no plan")) == ["wait"]
    assert kinds(s2.on_search_failed("no plan"))[-1] == "drop"


def test_achieved_and_stale_messages() -> None:
    s = running()
    assert s.on_status(status("old-plan", "x", "failed")) == []  # not the current plan
    assert kinds(s.achieved()) == ["achieved"] and s.current is None
    assert s.on_plan(plan("p9", "s9")) == []


def test_unknown_policy_is_refused() -> None:
    with pytest.raises(ValueError, match="preemption"):
        IntentionScheduler("sometimes")


def test_a_replacement_in_several_parts_runs_whole() -> None:
    """Each part of a repair is passed on in order; the later parts continue it."""
    s = running()
    first = s.on_plan(plan("r1", "t1", "t2", baseline="s1", after="s1"))
    assert kinds(first) == ["execute"]
    more = s.on_plan(plan("r1", "t3", baseline="r1"))
    assert kinds(more) == ["execute"]
    assert s.current is not None and s.current.steps == ["t1", "t2", "t3"]


def test_a_plan_that_comes_during_a_clean_preemption_is_not_executed() -> None:
    s = running()
    assert kinds(s.choose(URGENT)) == ["cancel_search", "arrest"]  # waits for the report
    assert s.on_plan(plan("r1", "t1", baseline="s1", after="s1")) == []
    started = s.on_arrested(arrested("p1", "s1"))
    assert kinds(started) == ["start_search"] and started[0].desire == URGENT


def test_a_restarted_executor_has_the_intention_planned_again_and_its_failure_waited_out() -> None:
    s = running()
    out = s.executor_restarted()
    assert kinds(out) == ["start_search"] and out[0].reason == "the executor restarted"
    assert s.current is not None and s.current.plan_id == ""
    # The robot's last action may still run: a failed search then is a wait, not a failure.
    assert kinds(s.on_search_failed("the goal can never hold", now=3.0)) == ["wait"]
    assert s.current.plan_failures == 0 and s.current.waiting
    assert kinds(s.retry(4.0)) == ["start_search"]
    assert kinds(s.on_search_failed("no plan", now=5.0)) == ["wait"]  # the next one counts
    assert s.current.plan_failures == 1


def test_a_wait_says_when_the_search_is_tried_again() -> None:
    s = IntentionScheduler(wait_stall=5)
    s.choose(RECYCLE)  # deadline 100
    waits = s.on_search_failed("no plan")
    assert waits[0].reason == (
        "planning failed (no plan); searching again when the beliefs change; its deadline is t=100"
    )
    assert s.retry_when() == "when the beliefs change; its deadline is t=100"
    s.retry(3.0)
    blocked = s.on_search_failed("a person on the goal", blocked=True, now=4.0)
    assert blocked[0].reason == (
        "a person on the goal; searching again when the beliefs change, or at t=9 if nothing"
        " does; its deadline is t=100"
    )


def test_a_search_that_fails_after_the_beliefs_changed_under_it_is_retried_at_once() -> None:
    """A search from the beliefs before a change (a sensor's reading that came while it
    ran) fails; the change was counted while it ran, so no further change is needed."""
    s = IntentionScheduler()
    s.choose(RECYCLE)
    s.changed_meanwhile = True  # the mind: the beliefs changed at a cycle meanwhile
    waits = s.on_search_failed("no plan")
    assert "searching again at the next cycle (the beliefs changed while it searched)" in (
        waits[0].reason
    )
    assert s.retry_due
    assert kinds(s.retry()) == ["start_search"] and not s.retry_due
    s.on_search_failed("no plan")  # from the beliefs of now: waits for a change
    assert not s.retry_due and s.retry_when().startswith("when the beliefs change")


def test_two_agents_head_to_head_stall_apart_with_a_spread() -> None:
    """Two robots waiting for each other in lockstep begin waiting in the same epoch;
    without a spread they stall together (and, stepping aside together, meet again);
    with one, each agent's stall comes at its own time, the same in every run."""

    def stall_time(agent: str, spread: float) -> float:
        s = IntentionScheduler(wait_stall=8, spread=spread, agent=agent)
        s.choose(RECYCLE)
        s.on_search_failed("in the way", blocked=True, now=10)
        t = 10.0
        while not s.stalled(t):  # nothing changes meanwhile: no retry
            t += 1.0
        return t

    assert stall_time("robot1", 0.0) == stall_time("robot2", 0.0) == 18.0
    apart = stall_time("robot1", 1.0), stall_time("robot2", 1.0)
    assert apart[0] != apart[1] and all(18.0 <= t <= 26.0 for t in apart)
    assert apart == (stall_time("robot1", 1.0), stall_time("robot2", 1.0))


def test_a_wait_can_stall_however_the_beliefs_change() -> None:
    """`quiet` (the default): a change (a cart passing by) starts the count again, so
    a wait among things that move never stalls; `waiting`: the seconds of waiting count."""
    for counts, stalls_at in (("quiet", None), ("waiting", 15.0)):
        s = IntentionScheduler(wait_stall=5, stall_counts=counts)
        s.choose(RECYCLE)
        s.on_search_failed("in the way", blocked=True, now=10)
        stalled_at, again = None, []
        for t in range(11, 30):
            again = s.stalled(float(t))
            if again:
                stalled_at = float(t)
                break
            s.retry(float(t))  # the beliefs changed this epoch: search again
            s.on_search_failed("in the way", blocked=True, now=float(t))
        assert stalled_at == stalls_at
        if counts == "waiting":
            assert s.current is not None and s.current.stalled
            assert kinds(again) == ["start_search"] and "blocked for 5 s" in again[0].reason


def test_a_step_failing_in_any_plan_a_replacement_follows_fails_the_plan() -> None:
    """Seen in a courier run: a new plan's line (p2, after p1's running drive s1), the
    complete search's plan after its first step (p3), and the whole search's after that
    (p4); the drive of p2 failed, and the scheduler, which knew only p4 and p3, waited in
    silence: the executor never starts a plan whose predecessor failed."""
    s = running()
    s.on_plan(plan("p2", "t1", "t2", baseline="s1", after="s1"))
    s.on_plan(plan("p3", "u1", "u2", baseline="t1", after="t1"))
    s.on_plan(plan("p4", "v1", baseline="u1", after="u1"))
    failed = s.on_status(status("p2", "t1", "failed", "c_2_5 is not clear"))
    assert kinds(failed) == ["start_search"]
    assert failed[0].reason == "replan after: c_2_5 is not clear"
    assert s.on_status(status("p0", "x", "failed")) == []  # not a plan of this intention
