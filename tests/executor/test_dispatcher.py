"""The executor's dispatcher: timing, condition checks, world answers, plans, early arrest."""

from __future__ import annotations

from cbdi.beliefs import BeliefSet, fact, fluent
from cbdi.wire.agent import Check, PartialPlan, PlanStep
from cbdi.wire.world import ActionOutcome, ActionReply
from cbdi_executor.checks import describe, first_failing
from cbdi_executor.dispatcher import Dispatcher, Effects

FREE = BeliefSet.of(
    [fact("free", f"c_{x}_0") for x in range(1, 5)]
    + [fact("in", "r", "c_0_0"), fluent("loaded_amount", "r", value=0)]
)


def move(i: int, start: float, checks: bool = True) -> PlanStep:
    at_start = [Check(atom=["free", f"c_{i + 1}_0"])] if checks else []
    return PlanStep(
        step_id=f"s{i}",
        action="move",
        args=["r", f"c_{i}_0", f"c_{i + 1}_0"],
        start=start,
        duration=1.0,
        at_start=at_start,
        over_all=[Check(atom=["free", f"c_{i + 1}_0"])],
    )


def plan(plan_id: str, *steps: PlanStep, baseline: str = "") -> PartialPlan:
    return PartialPlan(agent="r", plan_id=plan_id, baseline=baseline, steps=list(steps))


def statuses(out: Effects) -> list[tuple[str, str]]:
    return [(s.step_id, s.status) for s in out.statuses]


def start(d: Dispatcher, now: float, beliefs: BeliefSet = FREE) -> Effects:
    """Tick, and let the world accept what was dispatched (as the service does)."""
    out = d.tick(now, beliefs)
    for req in out.requests:
        reply = ActionReply(
            request_id=req.request_id, accepted=True, starts_at=now, ends_at=now + 1.0
        )
        out.statuses += d.on_reply(reply, now).statuses
    return out


def finish(d: Dispatcher, out: Effects, now: float, ok: bool = True) -> Effects:
    req = out.requests[0]
    return d.on_outcome(
        ActionOutcome(
            agent="r",
            request_id=req.request_id,
            action=req.action,
            status="succeeded" if ok else "failed",
            reason="" if ok else "blocked by person p",
            epoch=int(now),
            time=now,
        ),
        now,
    )


def test_steps_start_at_their_time_one_at_a_time() -> None:
    d = Dispatcher("r")
    assert statuses(d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)) == [
        ("s0", "waiting"),
        ("s1", "waiting"),
    ]
    first = start(d, 0.0, FREE)
    assert first.requests[0].args[2] == "c_1_0" and statuses(first) == [("s0", "running")]
    assert start(d, 1.0, FREE).requests == []  # s0 still running: s1 waits
    assert statuses(finish(d, first, 1.0)) == [("s0", "succeeded")]
    second = start(d, 1.0, FREE)
    assert second.requests[0].args[2] == "c_2_0"


def test_not_before_its_time() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 2.0)), 0)
    assert start(d, 1.0, FREE).requests == []
    assert len(start(d, 2.0, FREE).requests) == 1


def test_inapplicable_step_is_refused_and_the_plan_ends() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    blocked = FREE.removing([fact("free", "c_1_0")])
    out = start(d, 0.0, blocked)
    assert out.requests == []
    assert statuses(out) == [("s0", "refused"), ("s1", "cancelled")]
    assert "(free c_1_0) does not hold" in out.statuses[0].reason


def test_failed_or_rejected_action_cancels_the_rest() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    out = finish(d, start(d, 0.0, FREE), 1.0, ok=False)
    assert statuses(out) == [("s0", "failed"), ("s1", "cancelled")]
    assert out.statuses[0].reason == "blocked by person p"
    d2 = Dispatcher("r")
    d2.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    req = d2.tick(0.0, FREE).requests[0]
    rejected = d2.on_reply(
        ActionReply(request_id=req.request_id, accepted=False, reason="busy"), 0.0
    )
    assert statuses(rejected) == [("s0", "failed"), ("s1", "cancelled")]


def test_an_invariant_that_already_fails_refuses_the_start() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0, checks=False)), 0)
    out = start(d, 0.0, FREE.removing([fact("free", "c_1_0")]))
    assert statuses(out) == [("s0", "refused")] and out.requests == []
    assert "over all condition (free c_1_0)" in out.statuses[0].reason


def test_over_all_violation_is_reported_while_running() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0)), 0)
    start(d, 0.0, FREE)
    out = start(d, 0.5, FREE.removing([fact("free", "c_1_0")]))
    assert statuses(out) == [("s0", "running")]
    assert "over all condition (free c_1_0)" in out.statuses[0].reason
    assert start(d, 0.7, FREE.removing([fact("free", "c_1_0")])).statuses == []  # said once
    d2 = Dispatcher("r")
    d2.load(plan("p", move(0, 0.0)), 0)
    start(d2, 0.0)
    arrived = FREE.removing([fact("free", "c_1_0")])  # the robot itself is there now
    assert start(d2, 1.0, arrived).statuses == []  # at the end point: not a violation


def test_continuation_appends_and_new_baseline_replaces() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0)), 0)
    more = d.load(plan("p2", move(1, 1.0), baseline="p"), 0)
    assert statuses(more) == [("s1", "waiting")] and len(d.steps) == 2
    running = start(d, 0.0, FREE)
    swap = d.load(plan("q", move(5, 3.0)), 0.5)  # a repair: replaces what waits
    assert ("s1", "cancelled") in statuses(swap) and ("s5", "waiting") in statuses(swap)
    assert [s.step.step_id for s in d.steps] == ["s0", "s5"]  # the running step stays
    assert finish(d, running, 1.0).statuses[0].status == "succeeded"


def test_early_arrest_lets_the_started_step_finish_and_starts_nothing_after() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0), move(2, 2.0)), 0)
    first = start(d, 0.0, FREE)
    assert d.early_arrest("p", "s0", 0.5).arrest is None  # s0 still runs
    done = finish(d, first, 1.0)
    assert done.arrest is not None
    assert done.arrest.last_step == "s0" and done.arrest.cancelled == ["s1", "s2"]
    assert start(d, 2.0, FREE).requests == []


def test_early_arrest_waits_for_steps_up_to_the_arrest_point() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0), move(2, 2.0)), 0)
    assert d.early_arrest("p", "s1", 0.0).arrest is None
    out = finish(d, start(d, 0.0, FREE), 1.0)
    assert out.arrest is None  # s1 may still start
    out = finish(d, start(d, 1.0, FREE), 2.0)
    assert out.arrest is not None and out.arrest.last_step == "s1"
    assert out.arrest.cancelled == ["s2"]
    # Not the current plan: nothing of it runs, so it is reported stopped at once (a
    # scheduler waiting for the report to swap plans would otherwise wait for good).
    other = d.early_arrest("other", "s0", 2.0).arrest
    assert other is not None and other.plan_id == "other" and other.last_step == ""
    assert other.cancelled == []


def test_a_step_the_world_rejects_during_an_early_arrest_ends_it_with_a_true_report() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0), move(2, 2.0)), 0)
    assert d.early_arrest("p", "s1", 0.0).arrest is None
    finish(d, start(d, 0.0, FREE), 1.0)
    out = d.tick(1.0, FREE)  # s1 may still start: it goes to the world, which says no
    reply = ActionReply(request_id=out.requests[0].request_id, accepted=False, reason="busy")
    rejected = d.on_reply(reply, 1.0)
    assert ("s1", "failed") in statuses(rejected) and ("s2", "cancelled") in statuses(rejected)
    report = rejected.arrest
    assert report is not None and report.plan_id == "p"
    assert report.last_step == "s0"  # the last step that ran, not one that never started
    assert report.cancelled == ["s2"]


def test_checks() -> None:
    beliefs = FREE
    assert first_failing([Check(atom=["loaded_amount", "r"], op="LT", value=3)], beliefs) is None
    bad = Check(atom=["loaded_amount", "r"], op="GE", value=3)
    assert first_failing([bad], beliefs) == bad and describe(bad) == "(>= (loaded_amount r) 3)"
    assert describe(Check(atom=["free", "c"], op="F")) == "(not (free c))"


def test_a_step_is_requested_as_its_grounded_pddl_action() -> None:
    """The executor knows no domain: the world (or a performer) binds the action."""
    d = Dispatcher("r")
    pick = PlanStep(
        step_id="x", action="litter_pickup", args=["r", "pla61", "c_6_1"], start=0, duration=3
    )
    d.load(plan("p", pick), 0)
    req = d.tick(0.0, FREE).requests[0]
    assert (req.action, req.args, req.duration) == ("litter_pickup", ["r", "pla61", "c_6_1"], 3)
    assert req.target is None and req.item is None


def test_a_replacement_follows_the_step_it_applies_after_with_no_gap() -> None:
    """Plan q applies after s1: s1 (waiting) still runs, s2 is cancelled, and q's first
    step starts as soon as s1 ends, with no early arrest in between."""
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0), move(2, 2.0)), 0)
    first = start(d, 0.0)
    repair = PartialPlan(
        agent="r", plan_id="q", baseline="s1", steps=[move(3, 2.0)], applies_after="s1"
    )
    out = d.load(repair, 0.5)
    assert statuses(out) == [("s2", "cancelled"), ("s3", "waiting")]
    assert [s.step.step_id for s in d.steps] == ["s0", "s1", "s3"]
    finish(d, first, 1.0)
    second = start(d, 1.0)
    assert second.requests[0].args[2] == "c_2_0"  # s1, kept
    finish(d, second, 2.0)
    third = start(d, 2.0, FREE.adding([fact("free", "c_4_0")]))
    assert third.requests and third.requests[0].args[2] == "c_4_0"  # q's step, at once
    assert statuses(third) == [("s3", "running")]


def test_a_replacement_that_comes_too_late_is_refused() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    finish(d, start(d, 0.0), 1.0)
    start(d, 1.0)  # s1 runs: a plan meant to follow s0 comes too late
    late = PartialPlan(
        agent="r",
        plan_id="q",
        baseline="s0",
        steps=[move(5, 1.0), move(6, 2.0)],
        applies_after="s0",
    )
    out = d.load(late, 1.5)
    assert ("s5", "refused") in statuses(out) and ("s6", "cancelled") in statuses(out)
    refused = next(s for s in out.statuses if s.status == "refused")
    assert "too late" in refused.reason and "s1 started" in refused.reason
    assert d.running() is not None and d.running().step.step_id == "s1"  # it goes on


def test_an_arrest_after_a_kept_step_stops_the_replacement_too() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    first = start(d, 0.0)
    d.load(
        PartialPlan(
            agent="r", plan_id="q", baseline="s0", steps=[move(1, 1.0)], applies_after="s0"
        ),
        0.2,
    )
    assert d.early_arrest("q", "s0", 0.5).arrest is None  # s0 runs
    done = finish(d, first, 1.0)
    assert done.arrest is not None and done.arrest.last_step == "s0"
    assert start(d, 1.0).requests == []
    # An arrest after no step at all starts nothing more.
    d2 = Dispatcher("r")
    d2.load(plan("p", move(0, 0.0), move(1, 1.0)), 0)
    report = d2.early_arrest("p", "", 0.0).arrest
    assert report is not None and report.cancelled == ["s0", "s1"]
    assert start(d2, 0.0).requests == []


def test_a_step_waits_for_its_conditions_up_to_its_bound_then_starts() -> None:
    """Sensing lags an outcome: the step waits, says for what, and starts once it holds."""
    d = Dispatcher("r", condition_wait=2.0)
    d.load(plan("p", move(0, 0.0)), 0.0)
    stale = FREE.removing([fact("free", "c_1_0")])
    first = start(d, 0.0, stale)
    assert statuses(first) == [("s0", "waiting")] and not first.requests
    assert "(free c_1_0)" in first.statuses[0].reason
    assert start(d, 1.0, stale).statuses == []  # said once, still waiting
    later = start(d, 1.5, FREE)  # the reading came: it starts, later than planned
    assert [r.action for r in later.requests] == ["move"]
    assert statuses(later)[-1] == ("s0", "running") and later.statuses[-1].reason == ""


def test_a_step_whose_conditions_never_come_is_refused_after_its_bound() -> None:
    d = Dispatcher("r", condition_wait=5.0, condition_wait_for={"Move": 1.0})
    d.load(plan("p", move(0, 0.0), move(1, 1.0)), 0.0)
    stale = FREE.removing([fact("free", "c_1_0")])
    assert statuses(start(d, 0.0, stale)) == [("s0", "waiting")]
    assert start(d, 0.5, stale).statuses == []
    out = start(d, 1.0, stale)  # the action's own bound, not the agent's
    assert statuses(out) == [("s0", "refused"), ("s1", "cancelled")]
    assert out.statuses[0].reason.endswith("does not hold after waiting 1 s")


def test_with_no_bound_a_failing_step_is_refused_at_once() -> None:
    d = Dispatcher("r")
    d.load(plan("p", move(0, 0.0)), 0.0)
    out = start(d, 0.0, FREE.removing([fact("free", "c_1_0")]))
    assert statuses(out) == [("s0", "refused")]
    assert out.statuses[0].reason == "at start condition (free c_1_0) does not hold"


def test_bad_condition_waits_are_refused_with_what_is_wrong() -> None:
    import pytest

    from cbdi_executor.cli import main
    from cbdi_executor.service import condition_waits

    assert condition_waits(["Move=1.5", "pick=0"]) == {"move": 1.5, "pick": 0.0}
    for bad in ("move", "move=", "=2", "move=-1", "move=nan", "move=inf", "move=x"):
        with pytest.raises(ValueError, match="expected ACTION=SECONDS"):
            condition_waits([bad])
    assert main(["--condition-wait-for", "move=soon"]) == 2
    assert main(["--condition-wait", "-3"]) == 2
