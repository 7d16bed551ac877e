"""The intention scheduler: from the chosen desire to plans executing, safely.

It is a pure state machine. Its inputs are what happens (a desire chosen, a partial plan
from the planner, the planner giving up, a step failing, the executor stopping after an
early arrest, time passing); its outputs are `Command`s for the service to send (start or
cancel a search, pass a plan to the executor, ask for an early arrest, drop a desire).

- A plan continuing the one executing (its baseline is the current plan) is passed on.
- A plan with another baseline (a repair or an improvement) replaces the queue: it is
  passed on at once, and the executor runs the executing plan up to the last step the
  new plan keeps (its `applies_after`), then the new plan, with no gap. A step of the
  old plan that fails meanwhile ends both: a new search starts.
- A higher-priority desire under `no_preempt` waits until the intention ends; under
  `preempt` the executor stops after the running step and the new desire starts at once;
  under `clean_preempt` the new desire starts only once the executor reported it stopped.
- Planning and execution failures are retried up to their limits, then the desire is
  dropped with the reason. A search that failed only because something that moves is in
  the way (`blocked`: a person on the goal cell) is not a failure: the intention waits
  and searches again whenever the beliefs change, until its desire's deadline. Any
  failed search waits for the beliefs to change, from whatever source (percepts,
  outcomes, sensors, an operator), and says so (a `wait` command). A change while
  the search ran counts too (the search may have started from the beliefs before it): a
  search that fails after one is retried at the next cycle. A wait
  in which nothing changes for `wait_stall` seconds (a person waiting for the robot that
  waits for it) counts as a failure and searches again, so a deadlock ends in a drop.
  With a `spread`, each agent's stall comes up to that fraction of `wait_stall` later,
  drawn from its name and how many times its intention stalled: two robots that hold
  each other up in lockstep stall in the same epoch and, stepping aside together, meet
  again; drawn apart, one steps aside and the other passes (a run stays a function of
  its inputs: the draw is a hash, not a clock or a random stream). With `stall_counts`
  "waiting" the seconds of waiting count, whatever changes meanwhile.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Literal

from cbdi.wire.agent import ActionStatus, ArrestReport, PartialPlan
from cbdi_scheduler.desires import Desire

__all__ = ["FOLLOWED", "Command", "IntentionScheduler", "StallCounts"]

FOLLOWED = 16  # plans a replacement may still follow (a chain of partial plans)

# What a blocked wait's `wait_stall` counts: seconds in which nothing changed ("quiet"),
# or seconds of waiting, whatever changed meanwhile ("waiting": a cart passing by or a
# door opening elsewhere does not keep two robots head to head waiting for ever).
StallCounts = Literal["quiet", "waiting"]


@dataclass(frozen=True)
class Command:
    """Something the service must do: `kind` and what it needs."""

    kind: str  # start_search | cancel_search | execute | arrest | drop | achieved | wait
    desire: Desire | None = None
    plan: PartialPlan | None = None
    plan_id: str = ""  # arrest: the executing plan
    after_step: str = ""  # arrest: the last step that may start ("" none more)
    reason: str = ""


@dataclass
class Intention:
    """The desire being pursued and the plan executing for it."""

    desire: Desire
    plan_id: str = ""
    steps: list[str] = field(default_factory=list)
    last_started: str = ""
    # The plans replacements follow (newest last): their kept steps may still run, so a
    # step of any of them failing fails the intention's plan.
    previous: list[str] = field(default_factory=list)
    plan_failures: int = 0
    exec_failures: int = 0
    waiting: bool = False  # its goal is blocked by something that moves
    quiet_since: float = 0.0  # when the wait last searched again
    waiting_since: float = 0.0  # when the wait began (or last stalled)
    stalled: bool = False  # its wait saw nothing change for wait_stall seconds
    # Its plan was lost with a restarted executor: the next search may run while the
    # robot's action is still under way (an item neither on the ground nor in hand), so
    # its failure is waited out like a blocked goal's, not counted.
    after_restart: bool = False


class IntentionScheduler:
    """One agent's intention scheduler."""

    def __init__(
        self,
        preemption: str = "clean_preempt",
        plan_retries: int = 3,
        exec_retries: int = 3,
        wait_stall: float = 8.0,
        *,
        spread: float = 0.0,
        agent: str = "",
        stall_counts: StallCounts = "quiet",
    ) -> None:
        if preemption not in ("no_preempt", "preempt", "clean_preempt"):
            raise ValueError(f"unknown preemption policy {preemption!r}")
        self.preemption = preemption
        self.plan_retries, self.exec_retries = plan_retries, exec_retries
        self.wait_stall = wait_stall
        self.spread, self.agent, self.stall_counts = spread, agent, stall_counts
        self.current: Intention | None = None
        self.next_desire: Desire | None = None  # waits for a clean preemption
        self.stopping = False
        self.retry_reason = ""  # a failed search waits for the beliefs to change
        self.changed_meanwhile = False  # the beliefs changed since the last search began
        self.halted = False  # a safe stop: nothing starts until `resume`

    def _search(self, desire: Desire, reason: str = "") -> Command:
        """Start (or revise) the search for `desire` from the beliefs of now."""
        self.changed_meanwhile = False
        return Command("start_search", desire, reason=reason)

    # -- desires -------------------------------------------------------------------------
    def choose(self, desire: Desire | None) -> list[Command]:
        """React to the goal reasoner's choice (None: nothing to pursue)."""
        if self.halted:
            return []
        cur = self.current
        if desire is None or (cur is not None and desire.name == cur.desire.name):
            return self._revise(desire) if desire is not None else []
        if cur is None:
            return self._start(desire)
        if desire.priority <= cur.desire.priority or self.preemption == "no_preempt":
            return []
        commands = [Command("cancel_search", cur.desire, reason=f"preempted by {desire.name}")]
        commands += self._arrest_now()
        if self.preemption == "preempt" or not self.stopping:
            self.current = None
            self.next_desire = None
            return commands + self._start(desire)
        self.next_desire = desire  # clean_preempt: start once the executor stopped
        return commands

    def _revise(self, desire: Desire) -> list[Command]:
        cur = self.current
        assert cur is not None
        if desire.goal == cur.desire.goal:
            return []
        grown = set(cur.desire.goal) <= set(desire.goal)
        cur.desire = desire
        if grown:  # a BOOSTed goal: the planner revises its search (the union)
            return [self._search(desire, "goal revised")]
        # Part of the goal was given up (claimed by another agent): search anew.
        return [self._search(desire, "goal reduced")]

    def _start(self, desire: Desire) -> list[Command]:
        self.retry_reason = ""
        self.current = Intention(desire)
        return [self._search(desire)]

    def _arrest_now(self) -> list[Command]:
        """Stop after the step running now (nothing more starts)."""
        cur = self.current
        if cur is None or not cur.plan_id:
            self.stopping = False
            return []
        self.stopping = True
        return [Command("arrest", plan_id=cur.plan_id, after_step=cur.last_started)]

    # -- a safe stop ---------------------------------------------------------------------
    def halt(self) -> list[Command]:
        """Stop safely: cancel the search, let the running step end and start nothing
        more, keep the intention (and every desire) for `resume`."""
        if self.halted:
            return []
        self.halted = True
        self.next_desire, self.retry_reason = None, ""
        cur = self.current
        if cur is None:
            return []
        cur.waiting = cur.stalled = False
        return [Command("cancel_search", cur.desire, reason="halted"), *self._arrest_now()]

    def resume(self, now: float = 0.0) -> list[Command]:
        """Go on after a safe stop: plan the intention again from the beliefs of now."""
        if not self.halted:
            return []
        self.halted = self.stopping = False
        cur = self.current
        if cur is None:
            return []
        cur.plan_id, cur.steps, cur.last_started, cur.quiet_since = "", [], "", now
        return [self._search(cur.desire, "resumed")]

    # -- the planner ---------------------------------------------------------------------
    def on_plan(self, plan: PartialPlan) -> list[Command]:
        """A partial plan arrived: pass it on, or replace the executing plan safely."""
        cur = self.current
        if cur is None or self.halted:
            return []
        if not cur.plan_id or plan.baseline == cur.plan_id or plan.plan_id == cur.plan_id:
            return self._pass_on(plan)
        if self.next_desire is not None:
            return []  # a clean preemption is under way: the intention is over
        cur.previous = [*cur.previous, cur.plan_id][-FOLLOWED:]
        cur.steps = []
        return self._pass_on(plan)

    def _pass_on(self, plan: PartialPlan) -> list[Command]:
        cur = self.current
        assert cur is not None
        cur.waiting = cur.stalled = cur.after_restart = False
        cur.plan_id = plan.plan_id
        cur.steps += [s.step_id for s in plan.steps if s.step_id not in cur.steps]
        return [Command("execute", cur.desire, plan=plan)]

    def on_search_failed(
        self, reason: str, blocked: bool = False, now: float = 0.0
    ) -> list[Command]:
        """The planner found no plan: retry once the beliefs change, or drop the desire.

        Planning again from the same beliefs would fail the same way (a person blocking
        the only way is still there): the retry waits for `retry()`. A `blocked` failure
        does not count: the intention waits (a `wait` command the first time).
        """
        cur = self.current
        if cur is None or self.halted:
            return []
        blocked, cur.after_restart = blocked or cur.after_restart, False
        if blocked:
            self.retry_reason = f"retry after: {reason}"
            if cur.waiting:
                return []
            cur.waiting, cur.quiet_since, cur.waiting_since = True, now, now
            why = f"{reason}; searching again {self.retry_when()}"
            return [Command("wait", cur.desire, reason=why)]
        cur.waiting = False
        dropped = self._failed_planning(reason)
        if dropped:
            return dropped
        # Said once per failure, so a desire never waits in silence: the log, the
        # desire's events and `cbdi ctl show` tell what failed and what retries it.
        why = f"planning failed ({reason}); searching again {self.retry_when()}"
        return [Command("wait", cur.desire, reason=why)]

    @property
    def retry_due(self) -> bool:
        """A failed search waits, and the beliefs changed after it began: the next cycle
        tries it again even if nothing changes then."""
        return bool(self.retry_reason) and self.changed_meanwhile

    def retry_when(self) -> str:
        """Say when the failed search waiting is tried again ("" if none waits)."""
        cur = self.current
        if cur is None or not self.retry_reason:
            return ""
        if self.changed_meanwhile:
            when = "at the next cycle (the beliefs changed while it searched)"
        elif cur.waiting:
            stall = self._since(cur) + self.stall_after(cur)
            when = f"when the beliefs change, or at t={stall:g} if nothing does"
        else:
            when = "when the beliefs change"
        deadline = cur.desire.deadline
        return when + (f"; its deadline is t={deadline:g}" if math.isfinite(deadline) else "")

    def _failed_planning(self, reason: str) -> list[Command]:
        cur = self.current
        assert cur is not None
        cur.plan_failures += 1
        if cur.plan_failures > self.plan_retries:
            return self._drop(f"planning failed {cur.plan_failures} times: {reason}")
        self.retry_reason = f"retry after: {reason}"
        return []

    def retry(self, now: float = 0.0) -> list[Command]:
        """The beliefs changed: start the search a failed planning is waiting for."""
        cur = self.current
        if cur is None or not self.retry_reason or self.halted:
            return []
        reason, self.retry_reason = self.retry_reason, ""
        cur.quiet_since = now
        return [self._search(cur.desire, reason)]

    def _since(self, cur: Intention) -> float:
        """When `cur`'s wait started to count toward a stall."""
        return cur.quiet_since if self.stall_counts == "quiet" else cur.waiting_since

    def stall_after(self, cur: Intention) -> float:
        """How long `cur`'s blocked wait may see nothing change: `wait_stall`, plus up to
        `spread` of it drawn from the agent's name and the intention's failures so far."""
        if not self.spread:
            return self.wait_stall
        key = f"{self.agent}/{cur.desire.name}/{cur.plan_failures}".encode()
        draw = zlib.crc32(key) / 2**32
        return self.wait_stall * (1 + self.spread * draw)

    def stalled(self, now: float) -> list[Command]:
        """Nothing changed: a blocked wait quiet for `wait_stall` seconds counts as a
        failed planning (dropped after `plan_retries`) and searches again."""
        cur = self.current
        if (
            cur is None
            or not cur.waiting
            or not self.retry_reason
            or now - self._since(cur) < self.stall_after(cur)
        ):
            return []
        if self.stall_counts == "quiet":
            reason = f"blocked for {now - cur.quiet_since:g} s with nothing moving"
        else:
            reason = f"blocked for {now - cur.waiting_since:g} s"
        cur.stalled, cur.waiting_since = True, now
        dropped = self._failed_planning(reason)
        if dropped:
            return dropped
        return self.retry(now)

    # -- the executor --------------------------------------------------------------------
    def on_status(self, status: ActionStatus) -> list[Command]:
        """Follow the executor: a failed or refused step means replan (or drop)."""
        cur = self.current
        if cur is None or not status.plan_id or status.plan_id not in (cur.plan_id, *cur.previous):
            return []
        if status.status == "running":
            cur.last_started = status.step_id
        if status.status not in ("failed", "refused") or self.halted:
            return []
        cur.exec_failures += 1
        if cur.exec_failures > self.exec_retries:
            return self._drop(f"execution failed {cur.exec_failures} times: {status.reason}")
        cur.plan_id, cur.previous, cur.steps, cur.last_started = "", [], [], ""
        return [self._search(cur.desire, f"replan after: {status.reason}")]

    def executor_restarted(self) -> list[Command]:
        """The executor came back without the plan it had: plan the intention again
        (from the beliefs of now; not counted as a failure), unless stopped."""
        cur = self.current
        self.stopping = False
        if cur is None or self.halted or not cur.plan_id:
            return []
        cur.plan_id, cur.previous, cur.steps, cur.last_started = "", [], [], ""
        cur.after_restart = True
        return [self._search(cur.desire, "the executor restarted")]

    def on_arrested(self, report: ArrestReport) -> list[Command]:
        """The executor stopped: start the preempting desire, if one waits for it."""
        self.stopping = False
        if self.halted:
            if self.current is not None and report.plan_id == self.current.plan_id:
                self.current.plan_id, self.current.steps = "", []
            return []
        if self.next_desire is not None:
            desire, self.next_desire = self.next_desire, None
            self.current = None
            return self._start(desire)
        return []

    # -- ends ----------------------------------------------------------------------------
    def achieved(self) -> list[Command]:
        """The intention's goal is believed true."""
        cur = self.current
        if cur is None:
            return []
        self.current = None
        return [Command("achieved", cur.desire)]

    def drop(self, reason: str) -> list[Command]:
        """Drop the current intention (deadline passed, context failed)."""
        return self._drop(reason)

    def _drop(self, reason: str) -> list[Command]:
        cur = self.current
        if cur is None:
            return []
        commands = [Command("cancel_search", cur.desire, reason=reason)]
        commands += self._arrest_now()
        commands.append(Command("drop", cur.desire, reason=reason))
        self.current = None
        return commands
