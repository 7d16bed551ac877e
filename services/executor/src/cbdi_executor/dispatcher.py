"""The time-triggered dispatcher: the executor's pure core.

Steps start at their scheduled time, one action at a time (the world runs one action per
robot), each only once its at-start and over-all conditions hold in the current beliefs.
A step whose conditions fail waits for them (sensing catching up with an outcome) up to
its action's `condition_wait` simulated seconds, reported `waiting` with what it waits
for, and starts as soon as they hold: the rest of the plan shifts by the wait. After the
bound (at once with none) it is refused with the reason. A step the world rejects or
fails ends the plan (the rest is cancelled) so that a repaired plan can take over. A
plan with a new baseline replaces the queue after the step it applies after. An early
arrest after step A lets what already started finish, starts nothing after A, and
reports the state once nothing runs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from cbdi.beliefs import BeliefSet
from cbdi.wire.agent import ActionStatus, ArrestReport, PartialPlan, PlanStep, StepStatus
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest
from cbdi_executor.checks import describe, first_failing

__all__ = ["Dispatcher", "Effects", "StepState"]

EPS = 1e-6


@dataclass
class StepState:
    """A plan step and how it is doing."""

    plan_id: str
    step: PlanStep
    status: StepStatus = "waiting"
    reason: str = ""
    request_id: str = ""
    ends_at: float = float("inf")  # when the world said it ends (once accepted)
    blocked_since: float | None = None  # due, its conditions failing since then


@dataclass
class Effects:
    """What the service must send after a call: world requests, status reports, an arrest."""

    requests: list[ActionRequest] = field(default_factory=list)
    statuses: list[ActionStatus] = field(default_factory=list)
    arrest: ArrestReport | None = None


class Dispatcher:
    """Dispatch one agent's plan steps in time."""

    def __init__(
        self,
        agent: str,
        condition_wait: float = 0.0,
        condition_wait_for: Mapping[str, float] | None = None,
    ) -> None:
        """`condition_wait`: simulated seconds a due step waits for its conditions before
        it is refused; `condition_wait_for`: the same per action name, overriding it."""
        self.agent = agent
        self.condition_wait = condition_wait
        self.condition_wait_for = {k.lower(): v for k, v in (condition_wait_for or {}).items()}
        self.plan_id = ""
        self.steps: list[StepState] = []
        self.arrest: tuple[str, str] | None = None  # (plan id, last step allowed to start)
        self.halted = False  # an operator's safe stop: nothing starts until resumed
        self._requests = 0

    # -- plans ---------------------------------------------------------------------------
    def load(self, plan: PartialPlan, now: float) -> Effects:
        """Queue a plan: more of the current one, or a replacement (new baseline).

        A replacement applies after step `applies_after` of the queue (the last step
        its plan keeps): the steps up to it stay and run, the rest is cancelled, and the
        replacement follows with no gap and no early arrest. A replacement that comes
        too late (a step after that one already started, or that step did not succeed)
        is refused: its first step says why, so that the scheduler plans again.
        """
        out = Effects()
        continues = plan.plan_id == self.plan_id or (
            plan.baseline and plan.baseline == self.plan_id
        )
        late = ""
        if not continues:
            late = self._splice(plan, now, out)
        known = {s.step.step_id for s in self.steps}
        for step in sorted(plan.steps, key=lambda st: st.start):
            if step.step_id not in known:
                state = StepState(plan.plan_id, step)
                self.steps.append(state)
                self._report(state, now, out)
        self.plan_id = plan.plan_id
        if late:
            first = next(s for s in self.steps if s.plan_id == plan.plan_id)
            self._set(first, "refused", late, now, out)
            self._abandon(now, out)
        return out

    def _splice(self, plan: PartialPlan, now: float, out: Effects) -> str:
        """Make room for a replacement; return why it comes too late ("" if it does not)."""
        ids = [s.step.step_id for s in self.steps]
        after = plan.applies_after
        keep = ids.index(after) + 1 if after in ids else 0
        why = ""
        if keep:
            kept = self.steps[keep - 1]
            started = next((s for s in self.steps[keep:] if s.ends_at != float("inf")), None)
            if kept.status in ("failed", "refused", "cancelled"):
                why = f"too late: it applies after {after}, which {kept.status}"
            elif started is not None:
                why = f"too late: it applies after {after}, but {started.step.step_id} started"
        for s in self.steps[keep:]:
            if s.status == "waiting":
                self._set(s, "cancelled", f"replaced by plan {plan.plan_id}", now, out)
        # What stays: the steps still to run up to the one the replacement follows, that
        # step itself (a later replacement may follow it too) and whatever runs.
        self.steps = [
            s
            for k, s in enumerate(self.steps)
            if s.status == "running" or (k < keep and s.status == "waiting") or k == keep - 1
        ]
        self.arrest = None
        return why

    def halt(self, stop: bool) -> None:
        """Stop safely (start nothing more; what runs ends) or go on."""
        self.halted = stop

    def running(self) -> StepState | None:
        return next((s for s in self.steps if s.status == "running"), None)

    def outcome_due(self, now: float) -> bool:
        """Whether a running step should have ended by `now` (its outcome is on its way)."""
        current = self.running()
        return current is not None and current.ends_at <= now + EPS

    # -- time ----------------------------------------------------------------------------
    def tick(self, now: float, beliefs: BeliefSet) -> Effects:
        """Start the next due step if nothing runs; report over-all violations."""
        out = Effects()
        current = self.running()
        if current is not None:
            # Over-all conditions hold on the open interval: at its end an action's own
            # effects may end them (a robot arriving makes its cell not free).
            if now < current.ends_at - EPS and not current.reason:
                broken = first_failing(current.step.over_all, beliefs)
                if broken is not None:
                    current.reason = f"over all condition {describe(broken)} does not hold"
                    self._report(current, now, out)
            return out
        step = next((s for s in self.steps if s.status == "waiting"), None)
        if step is None or self.halted or step.step.start > now + EPS or self._arrested(step):
            return out
        self._start(step, now, beliefs, out)
        return out

    def _arrested(self, state: StepState) -> bool:
        """Whether an early arrest forbids `state` to start: it comes after the arrest's
        last step in the queue (a replacement's steps follow the ones it kept), or the
        arrest allows no step at all."""
        if self.arrest is None:
            return False
        ids = [s.step.step_id for s in self.steps]
        last = self.arrest[1]
        if last not in ids:
            return True
        return ids.index(state.step.step_id) > ids.index(last)

    def _start(self, state: StepState, now: float, beliefs: BeliefSet, out: Effects) -> None:
        # An over-all condition that already fails would fail the action as it starts.
        broken, when = first_failing(state.step.at_start, beliefs), "at start"
        if broken is None:
            broken, when = first_failing(state.step.over_all, beliefs), "over all"
        if broken is not None:
            reason = f"{when} condition {describe(broken)} does not hold"
            since = now if state.blocked_since is None else state.blocked_since
            state.blocked_since = since
            bound = self.condition_wait_for.get(state.step.action.lower(), self.condition_wait)
            if now - since < bound - EPS:
                if state.reason != reason:  # said once per condition waited for
                    self._set(state, "waiting", reason, now, out)
                return
            if bound > 0:
                reason += f" after waiting {now - since:g} s"
            self._set(state, "refused", reason, now, out)
            self._abandon(now, out)
            return
        state.reason = ""  # what it waited for holds now
        self._requests += 1
        step = state.step
        request = ActionRequest(
            agent=self.agent,
            action=step.action,
            request_id=f"{self.agent}-{self._requests}",
            args=list(step.args),
            duration=step.duration,
        )
        state.request_id = request.request_id
        state.status = "running"  # reported with the world's start time, on its reply
        out.requests.append(request)

    # -- the world's answers -------------------------------------------------------------
    def on_reply(self, reply: ActionReply, now: float) -> Effects:
        """Follow the world's immediate answer to a request."""
        out = Effects()
        state = self._by_request(reply.request_id)
        if state is None:
            return out
        if reply.accepted:
            state.ends_at = reply.ends_at
            self._report(state, reply.starts_at, out)
        else:
            self._set(state, "failed", f"rejected by the world: {reply.reason}", now, out)
            self._abandon(now, out)
            self._maybe_report_arrest(now, out)
        return out

    def on_outcome(self, outcome: ActionOutcome, now: float) -> Effects:
        """Follow how an action ended."""
        out = Effects()
        state = self._by_request(outcome.request_id)
        if state is None or state.status != "running":
            return out
        if outcome.status == "succeeded":
            self._set(state, "succeeded", "", now, out)
        else:
            self._set(state, "failed", outcome.reason, now, out)
            self._abandon(now, out)
        self._maybe_report_arrest(now, out)
        return out

    # -- early arrest ----------------------------------------------------------------------
    def early_arrest(self, plan_id: str, after_step: str, now: float) -> Effects:
        """Start nothing after `after_step`; report once nothing runs any more."""
        out = Effects()
        if plan_id != self.plan_id:
            # Not (or no longer) ours: nothing of it runs, so it has stopped already. Say
            # so, or a scheduler waiting to swap plans would wait for good.
            out.arrest = ArrestReport(
                agent=self.agent, plan_id=plan_id, last_step="", time=now, cancelled=[]
            )
            return out
        self.arrest = (plan_id, after_step)
        self._maybe_report_arrest(now, out)
        return out

    def _maybe_report_arrest(self, now: float, out: Effects) -> None:
        if self.arrest is None or self.running() is not None:
            return
        plan_id, last = self.arrest
        if any(s.status == "waiting" and not self._arrested(s) for s in self.steps):
            return  # steps up to `last` still have to run
        for s in self.steps:
            if s.status == "waiting" and self._arrested(s):
                why = f"early arrest after {last}" if last else "early arrest"
                self._set(s, "cancelled", why, now, out)
        ours = self.steps  # a replacement's queue holds the steps it kept
        # Started: accepted by the world (a refused or rejected step never ran).
        started = [s for s in ours if s.ends_at != float("inf")]
        cancelled = [s.step.step_id for s in ours if s.status == "cancelled"]
        done = started[-1].step.step_id if started else ""
        out.arrest = ArrestReport(
            agent=self.agent, plan_id=plan_id, last_step=done, time=now, cancelled=cancelled
        )
        self.arrest = None

    # -- helpers ---------------------------------------------------------------------------
    def _abandon(self, now: float, out: Effects) -> None:
        for s in self.steps:
            if s.status == "waiting":
                self._set(s, "cancelled", "an earlier step of the plan did not succeed", now, out)

    def _by_request(self, request_id: str) -> StepState | None:
        return next((s for s in self.steps if s.request_id == request_id), None)

    def _set(
        self, state: StepState, status: StepStatus, reason: str, now: float, out: Effects
    ) -> None:
        state.status, state.reason = status, reason
        self._report(state, now, out)

    def _report(self, state: StepState, now: float, out: Effects) -> None:
        out.statuses.append(
            ActionStatus(
                agent=self.agent,
                plan_id=state.plan_id,
                step_id=state.step.step_id,
                action=state.step.action,
                status=state.status,
                reason=state.reason,
                time=now,
            )
        )
