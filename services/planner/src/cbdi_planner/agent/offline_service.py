"""The offline planner service (plan, then act; the paper's baseline).

It keeps the agent's latest beliefs (from the scheduler) and the steps it sent as they
execute (the executor's statuses), and on a search request plans from the beliefs with
the running steps' effects applied (the committed state, `cbdi_planner.agent.offline`)
to the goal with the chosen backend, in a worker thread so the service keeps serving; it
publishes the plan as one complete `PartialPlan` that follows the running step, whose
step times are snapped to the world's epoch grid, and reports the search status. A
revised goal or a new request replaces the search; a cancelled search's late result is
dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
from dataclasses import dataclass, field
from itertools import count

from msgspec.structs import replace

from cbdi import keys
from cbdi.agentfile import RawAgentFile
from cbdi.beliefs import BeliefSet, BeliefsReceiver
from cbdi.bus import publish
from cbdi.runtime import ServiceContext
from cbdi.wire.agent import ActionStatus, BeliefsUpdate, PartialPlan
from cbdi.wire.base import Message
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi_planner.agent.backends import COUNTING_BACKENDS, Counted, plan_counted, plan_with
from cbdi_planner.agent.epochs import NO_COUNTING, Epochs, checked, waits
from cbdi_planner.agent.errors import BadRequestError
from cbdi_planner.agent.lines import Purpose, plan_prefix
from cbdi_planner.agent.offline import Basis, Committed, Execution
from cbdi_planner.agent.pacing import Pacer
from cbdi_planner.agent.problem import (
    GoalError,
    beliefs_from_problem,
    goal_of,
    problem_from_beliefs,
)
from cbdi_planner.agent.steps import plan_steps
from cbdi_planner.agent.transient import Transients
from cbdi_planner.errors import PlannerError, SearchTimeout
from cbdi_planner.pddl import parse_problem
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.plan import Plan

__all__ = ["OfflinePlannerService"]


@dataclass
class _Pending:
    """An offline search in virtual time: its result, and expansions still to be paid."""

    request: SearchRequest
    basis: Basis
    committed: Committed | None = None  # what the search planned from, once it did
    pacer: Pacer = field(default_factory=Pacer)
    result: asyncio.Future[Counted] | None = None


class OfflinePlannerService(Epochs):
    """Plans for one agent on request."""

    def __init__(
        self,
        ctx: ServiceContext,
        agent: str,
        domain: Domain,
        raw: RawAgentFile,
        backend: str,
        grid: float,
        planning_speed: float = 0.0,
        ack_timeout: float = 120.0,
        life: int = 0,
    ) -> None:
        self.ctx, self.agent, self.domain, self.raw = ctx, agent, domain, raw
        self.plan_prefix = plan_prefix(agent, life)  # apart from a predecessor's plans
        self.backend, self.grid = backend, grid
        self.planning_speed = planning_speed or raw.planning.planning_speed
        self.ack_timeout = ack_timeout
        self.pending: _Pending | None = None
        self.lockstep = self._lockstep(self.input_keys())
        self.beliefs = BeliefSet()
        self.has_beliefs = False
        self.beliefs_in = BeliefsReceiver()
        self.deferred: SearchRequest | None = None  # a request that came before any beliefs
        self.now = 0.0
        self.request: SearchRequest | None = None
        self.request_failed = False  # the last request's search failed (a repeat retries)
        self.searching: asyncio.Task[None] | None = None
        self.plan_ids = count(1)
        self.transients = Transients(raw.transient)
        # The steps sent, as they execute: a search plans from where they leave the robot.
        self.execution = Execution()

    def input_keys(self) -> list[str]:
        a = self.agent
        return [
            keys.planner_requests(a),
            keys.scheduler_beliefs(a),
            keys.executor_status(a),
            *self.lockstep_keys(),
        ]

    async def handle_input(self, key: str, msg: Message) -> None:
        await self.handle(msg)

    async def handle(self, msg: Message) -> None:
        if isinstance(msg, ActionStatus):
            self.execution.on_status(msg)
        elif isinstance(msg, BeliefsUpdate):
            beliefs = self.beliefs_in.apply(msg)
            if beliefs is None:
                self.ctx.log.warning("beliefs_skipped", seq=msg.seq, base=msg.base)
                return  # a change of beliefs we never had: the next whole set comes soon
            self.beliefs, self.now = beliefs, max(self.now, msg.time)
            self.has_beliefs = True
            self.transients.see(self.beliefs)
            if self.deferred is not None and not waits(self.deferred, self.beliefs_in, True):
                req, self.deferred = self.deferred, None
                await self.on_request(req)
        elif isinstance(msg, SearchRequest):
            if waits(msg, self.beliefs_in, self.has_beliefs):
                try:
                    checked(self.domain, msg)
                except BadRequestError as exc:
                    await self.status(msg.request_id, "failed", exc.reason)
                    raise
                self.deferred = msg  # plan from the beliefs it was asked from, once here
                return
            await self.on_request(msg)

    async def on_request(self, req: SearchRequest) -> None:
        if self.repeated(req):
            # The scheduler sends its search again when it sees this planner appear; the
            # first time that may come after the search began (when its liveliness event
            # arrives is up to the machine), so a repeat changes nothing: on it already.
            self.ctx.log.info("search_repeated", request=req.request_id)
            return
        if self.searching is not None:
            self.searching.cancel()
            self.searching = None
        if self.pending is not None:
            self.pending.pacer.cancel()  # its thread ends at its next expansion
        self.pending = None
        if req.kind == "cancel":
            self.request = None
            await self.status(req.request_id, "cancelled")
            return
        if self.lockstep.on and self.backend not in COUNTING_BACKENDS:
            reason = NO_COUNTING.format(backend=self.backend)
            await self.status(req.request_id, "failed", reason)
            raise BadRequestError(req.request_id, reason)
        if req.kind == "revise" and self.request is not None:
            req = replace(req, request_id=self.request.request_id)
        try:
            req, basis = self.problem(req)
        except (GoalError, PlannerError) as exc:
            self.request = None
            await self.status(req.request_id, "failed", str(exc))
            raise BadRequestError(req.request_id, str(exc)) from exc
        self.request, self.request_failed = req, False
        await self.status(req.request_id, "searching")
        if self.lockstep.on:
            self.pending = _Pending(req, basis)  # searched and paid for epoch by epoch
            return
        self.searching = self.ctx.start(self.search(req, basis), name="search")

    async def plan_epoch(self) -> None:
        """Virtual time: search (bounded by expansions), then pay for it epoch by epoch;
        the plan goes out in the epoch its expansions are paid off, as a plan-then-act
        robot waits while the world moves on."""
        p = self.pending
        if p is None:
            return
        if p.result is None:
            p.result = self.start_paced(p)
        if not await asyncio.to_thread(p.pacer.pay, self.budget()):
            return  # still searching: this epoch paid for its share
        result = await p.result
        self.pending = None
        if result.plan is None or p.committed is None:
            self.ctx.log.warning("search_failed", request=p.request.request_id, error=result.error)
            await self.failed(p.request, result.error, timeout=result.timeout)
            return
        await self.publish_plan(p.request, result.plan, p.committed)

    def start_paced(self, p: _Pending) -> asyncio.Future[Counted]:
        """Start `p`'s search in a thread of its own that expands only what is paid for
        (a daemon: a search waiting for payment never holds the process at exit)."""
        loop = asyncio.get_running_loop()
        done: asyncio.Future[Counted] = loop.create_future()
        most = max(1, round(self.raw.planning.timeout * self.planning_speed))

        def run() -> None:
            try:
                p.committed = p.basis()
                result = plan_counted(self.domain, p.committed.problem, most, pace=p.pacer.pace)
            except (GoalError, PlannerError, ValueError) as exc:
                result = Counted(None, 1, str(exc), timeout=isinstance(exc, SearchTimeout))
            finally:
                p.pacer.end()

            def settle() -> None:
                if not done.done():
                    done.set_result(result)

            with contextlib.suppress(RuntimeError):  # the service stopped meanwhile
                loop.call_soon_threadsafe(settle)

        threading.Thread(target=run, name="offline-search", daemon=True).start()
        return done

    def problem(self, req: SearchRequest) -> tuple[SearchRequest, Basis]:
        """The request (its goal checked here: a bad one is refused at once) and what
        its search plans from, made in the search's thread (grounding takes a while):
        its own PDDL problem, or the beliefs and its goal from the committed state
        (what the steps running now leave, `Execution.commit`)."""
        now: float | None = self.now  # the beliefs' time (a problem's own has none)
        if req.problem:
            now = None
            parsed = parse_problem(req.problem, self.domain, f"request {req.request_id}")
            goal = [list(g) for g in req.goal] or goal_of(parsed)
            self.beliefs, self.has_beliefs = beliefs_from_problem(parsed), True
            self.transients.see(self.beliefs)
            req = replace(req, goal=goal, problem="")
        problem = problem_from_beliefs(self.domain, self.beliefs, req.goal)
        if not self.execution.steps:
            return req, lambda: Committed(problem, 0, "", 0.0)
        execution, beliefs = self.execution.copy(), self.beliefs
        goal = [list(g) for g in req.goal]
        return req, lambda: execution.commit(self.domain, beliefs, goal, now)

    async def search(self, req: SearchRequest, basis: Basis) -> None:
        """Plan with the backend from `basis`; publish the plan and the outcome."""
        seconds = self.raw.planning.timeout
        try:
            committed = await asyncio.to_thread(basis)
            plan = await asyncio.to_thread(
                plan_with, self.backend, self.domain, self.raw.domain, committed.problem, seconds
            )
        except (GoalError, PlannerError, ValueError) as exc:
            if self.request is req:
                self.ctx.log.warning("search_failed", request=req.request_id, error=str(exc))
                await self.failed(req, str(exc), timeout=isinstance(exc, SearchTimeout))
            return
        if self.request is not req:
            return  # replaced or cancelled meanwhile
        await self.publish_plan(req, plan, committed)

    async def publish_plan(self, req: SearchRequest, plan: Plan, committed: Committed) -> None:
        start = math.floor(self.now / self.grid + 1e-9) * self.grid + self.grid
        start = max(start, math.ceil(committed.ends / self.grid - 1e-9) * self.grid)
        plan_id = f"{self.plan_prefix}{next(self.plan_ids)}"
        steps = [
            replace(s, start=round(s.start / self.grid) * self.grid)
            for s in plan_steps(self.domain, plan, start, plan_id)
        ]
        out = PartialPlan(
            agent=self.agent,
            plan_id=plan_id,
            baseline="",
            applies_after=committed.after,
            steps=steps,
            complete=True,
            request_id=req.request_id,
            purpose=(Purpose.REVISE if req.kind == "revise" else Purpose.NEW).value,
        )
        self.ctx.log.info(
            "plan",
            request=req.request_id,
            plan=plan_id,
            steps=len(steps),
            makespan=plan.makespan,
            after=committed.after,
        )
        self.execution.follow(committed.count, steps)
        await publish(self.ctx.bus, keys.planner_plans(self.agent), out, block=True)
        await self.status(req.request_id, "done")

    async def status(
        self, request_id: str, status: str, reason: str = "", blocked: bool = False
    ) -> None:
        msg = SearchStatus(
            agent=self.agent, request_id=request_id, status=status, reason=reason, blocked=blocked
        )
        await publish(self.ctx.bus, keys.planner_status(self.agent), msg, block=True)

    async def failed(self, req: SearchRequest, reason: str, timeout: bool) -> None:
        """Report a failed search: blocked (not a timeout, and the goal is reachable once
        the transient beliefs hold again, from what the running steps started from) or
        not."""
        held = self.execution.held(self.domain)
        blocked = not timeout and self.transients.blocked(self.domain, self.beliefs, req.goal, held)
        if blocked:
            reason += " (blocked by something that moves: waiting for it)"
        self.request_failed = True
        await self.status(req.request_id, "failed", reason, blocked)

    def repeated(self, req: SearchRequest) -> bool:
        """Whether `req` starts the request this planner is on (or has planned) again."""
        last = self.request
        return (
            req.kind == "start"
            and last is not None
            and not self.request_failed
            and req.request_id == last.request_id
            and not req.problem
            and [list(g) for g in req.goal] == [list(g) for g in last.goal]
        )
