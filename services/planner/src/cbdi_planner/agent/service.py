"""The planner service of one agent: online (continual planning, `ContinualPlanner`) or
offline (plan, then act; the paper's baseline).

Offline:

It keeps the agent's latest beliefs (from the scheduler), and on a search request plans
from them to the goal with the chosen backend, in a worker thread so the service keeps
serving; it publishes the plan as one complete `PartialPlan` whose step times are snapped
to the world's epoch grid from now on, and reports the search status. A revised goal or a
new request replaces the search; a cancelled search's late result is dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
from abc import ABC, abstractmethod
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from itertools import count

from msgspec.structs import replace

from cbdi import keys
from cbdi.agentfile import RawAgentFile
from cbdi.beliefs import BeliefSet, BeliefsReceiver
from cbdi.bus import publish, sequenced_inputs
from cbdi.bus.typed import Stamped, dropping
from cbdi.lockstep import Lockstep, Need, announce_ready, default_sender, send_ack
from cbdi.runtime import ServiceContext, ServiceSettings
from cbdi.runtime.service import ServiceMain
from cbdi.wire.agent import ActionStatus, BeliefsUpdate, PartialPlan
from cbdi.wire.base import Message
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound, SearchStatus
from cbdi.wire.world import EpochAck, Tick
from cbdi_planner.agent.backends import COUNTING_BACKENDS, Counted, plan_counted, plan_with
from cbdi_planner.agent.continual import ContinualPlanner, Search, plan_prefix
from cbdi_planner.agent.errors import BadRequestError, UnknownAgentError
from cbdi_planner.agent.pacing import Pacer
from cbdi_planner.agent.problem import (
    GoalError,
    beliefs_from_problem,
    check_goal,
    goal_of,
    problem_from_beliefs,
)
from cbdi_planner.agent.steps import plan_steps
from cbdi_planner.agent.transient import Transients
from cbdi_planner.continual import Event, RoundDone
from cbdi_planner.errors import PlannerError, SearchTimeout
from cbdi_planner.pddl import parse_problem
from cbdi_planner.pddl.ast import Domain, Problem
from cbdi_planner.plan import Plan

__all__ = ["OnlinePlannerService", "PlannerService", "PlannerSettings", "planner_main"]

INPUTS: tuple[type[Message], ...] = (SearchRequest, BeliefsUpdate, ActionStatus, Tick, EpochAck)
ONLINE_INPUTS = INPUTS
NO_COUNTING = (
    "the {backend} backend cannot count node expansions, so it cannot plan in virtual "
    "time (a lockstep world); use backend cbdi, or run the world without lockstep"
)


def waits(req: SearchRequest, received: BeliefsReceiver, has_beliefs: bool) -> bool:
    """Whether `req` must wait for beliefs: none yet, or older than the ones it was
    asked from (a start or revision that overtook its beliefs update on the bus)."""
    if req.kind == "cancel" or req.problem:
        return False
    return not has_beliefs or received.seq < req.beliefs


@dataclass(frozen=True)
class PlannerSettings(ServiceSettings):
    """Settings of `cbdi-planner serve`."""

    agent: str = field(default="robot1", metadata={"help": "the agent this planner serves"})
    restart: int = field(
        default=0,
        metadata={
            "help": "restarts so far (cbdi up sets CBDI_RESTART): above 0 its plans are "
            "numbered apart from its predecessor's (robot1-plan-r1-1)"
        },
    )
    agent_file: str = field(default="", metadata={"help": "the agent file (TOML)"})
    backend: str = field(default="", metadata={"help": "cbdi or kairos (default: agent file)"})
    time_grid: float = field(default=1.0, metadata={"help": "snap step starts to this grid"})
    planning: str = field(default="", metadata={"help": "online or offline (default: agent file)"})
    improve: bool = field(default=True, metadata={"help": "online: look for improved plans"})
    planning_speed: float = field(
        default=0.0,
        metadata={"help": "virtual time: expansions per simulated second (0: agent file's)"},
    )
    ack_timeout: float = field(
        default=120.0, metadata={"help": "lockstep: seconds to wait for the scheduler's epoch"}
    )


class _Epochs(ABC):
    """The lockstep side shared by both modes: inputs, the gate, the epoch's budget."""

    ctx: ServiceContext
    agent: str
    planning_speed: float
    ack_timeout: float
    epoch_duration: float = 1.0
    lockstep: Lockstep

    def _lockstep(self, input_keys: list[str]) -> Lockstep:
        requests = keys.planner_requests(self.agent)
        scheduler = keys.member(self.agent, "scheduler")

        def sender_of(key: str) -> str:  # requests sit under our key but are the scheduler's
            return scheduler if key == requests else default_sender(key)

        return Lockstep(
            input_keys,
            lambda first: self.ctx.start(self.epochs(first), name="epochs"),
            sender_of,
            keep_ticks=False,
            bus=self.ctx.bus,
            me=keys.member(self.agent, "planner"),
        )

    def lockstep_keys(self) -> list[str]:
        a = self.agent
        return [
            keys.world_stream("clock"),
            keys.epoch_ack(a, "scheduler"),
            keys.epoch_ack(a, "executor"),
        ]

    def budget(self) -> int:
        """Node expansions of one epoch: the planning speed times the epoch's duration."""
        return max(1, round(self.planning_speed * self.epoch_duration))

    async def inputs(self, stream: AsyncIterator[Stamped]) -> None:
        """Every input: handled at once (real time) or through the gate (lockstep)."""
        async for item in stream:
            if isinstance(item.message, Tick):
                self.epoch_duration = item.message.epoch_duration
            for key, m in await self.lockstep.put(item):
                if not isinstance(m, Tick | EpochAck):
                    await self.checked_handle(key, m)

    async def epochs(self, first: int) -> None:
        """Lockstep: once the scheduler's beliefs of an epoch (and the executor's
        reports of the one before) are in, handle them, plan for the epoch, acknowledge."""
        a = self.agent
        members = await self.lockstep.learn_members(self.ctx.bus)
        executor, scheduler = keys.member(a, "executor"), keys.member(a, "scheduler")
        epoch = first
        while True:
            needs = [Need(executor, epoch - 1)] if executor in members else []
            if scheduler in members:
                needs.append(Need(scheduler, epoch, "beliefs"))
            released = await self.lockstep.gate.wait(needs, self.ack_timeout)
            if released.late:
                self.ctx.log.warning("upstream_late", epoch=epoch, late=",".join(released.late))
            for key, msg in released.messages:
                if not isinstance(msg, Tick | EpochAck):
                    await self.checked_handle(key, msg)
            await self.plan_epoch()
            await send_ack(self.ctx.bus, a, "planner", epoch)
            epoch += 1

    async def checked_handle(self, key: str, msg: Message) -> None:
        """Handle one input; bad input is reported, never fatal."""
        agent = getattr(msg, "agent", None)
        if agent != self.agent:
            self.ctx.bad_input(key, UnknownAgentError(str(agent), self.agent, type(msg).__name__))
            return
        with dropping(self.ctx, key, msg):
            await self.handle_input(key, msg)

    @abstractmethod
    async def handle_input(self, key: str, msg: Message) -> None:
        """Handle one input of this mode (online or offline)."""

    @abstractmethod
    async def plan_epoch(self) -> None:
        """Plan for one epoch of virtual time, within its expansion budget."""


@dataclass
class _Pending:
    """An offline search in virtual time: its result, and expansions still to be paid."""

    request: SearchRequest
    problem: Problem
    pacer: Pacer = field(default_factory=Pacer)
    result: asyncio.Future[Counted] | None = None


class PlannerService(_Epochs):
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

    def input_keys(self) -> list[str]:
        a = self.agent
        return [keys.planner_requests(a), keys.scheduler_beliefs(a), *self.lockstep_keys()]

    async def handle_input(self, key: str, msg: Message) -> None:
        await self.handle(msg)

    async def handle(self, msg: Message) -> None:
        if isinstance(msg, BeliefsUpdate):
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
            req, problem = self.problem(req)
        except (GoalError, PlannerError) as exc:
            self.request = None
            await self.status(req.request_id, "failed", str(exc))
            raise BadRequestError(req.request_id, str(exc)) from exc
        self.request, self.request_failed = req, False
        await self.status(req.request_id, "searching")
        if self.lockstep.on:
            self.pending = _Pending(req, problem)  # searched and paid for epoch by epoch
            return
        self.searching = self.ctx.start(self.search(req, problem), name="search")

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
        if result.plan is None:
            self.ctx.log.warning("search_failed", request=p.request.request_id, error=result.error)
            await self.failed(p.request, result.error, timeout=result.timeout)
            return
        await self.publish_plan(p.request, result.plan)

    def start_paced(self, p: _Pending) -> asyncio.Future[Counted]:
        """Start `p`'s search in a thread of its own that expands only what is paid for
        (a daemon: a search waiting for payment never holds the process at exit)."""
        loop = asyncio.get_running_loop()
        done: asyncio.Future[Counted] = loop.create_future()
        most = max(1, round(self.raw.planning.timeout * self.planning_speed))

        def run() -> None:
            try:
                result = plan_counted(self.domain, p.problem, most, pace=p.pacer.pace)
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

    def problem(self, req: SearchRequest) -> tuple[SearchRequest, Problem]:
        """The request's problem: its own PDDL problem, or the beliefs and its goal."""
        if req.problem:
            parsed = parse_problem(req.problem, self.domain, f"request {req.request_id}")
            goal = [list(g) for g in req.goal] or goal_of(parsed)
            self.beliefs, self.has_beliefs = beliefs_from_problem(parsed), True
            self.transients.see(self.beliefs)
            req = replace(req, goal=goal, problem="")
        return req, problem_from_beliefs(self.domain, self.beliefs, req.goal)

    async def search(self, req: SearchRequest, problem: Problem) -> None:
        """Plan `problem` with the backend; publish the plan and the outcome."""
        seconds = self.raw.planning.timeout
        try:
            plan = await asyncio.to_thread(
                plan_with, self.backend, self.domain, self.raw.domain, problem, seconds
            )
        except (GoalError, PlannerError, ValueError) as exc:
            if self.request is req:
                self.ctx.log.warning("search_failed", request=req.request_id, error=str(exc))
                await self.failed(req, str(exc), timeout=isinstance(exc, SearchTimeout))
            return
        if self.request is not req:
            return  # replaced or cancelled meanwhile
        await self.publish_plan(req, plan)

    async def publish_plan(self, req: SearchRequest, plan: Plan) -> None:
        start = math.floor(self.now / self.grid + 1e-9) * self.grid + self.grid
        plan_id = f"{self.plan_prefix}{next(self.plan_ids)}"
        steps = [
            replace(s, start=round(s.start / self.grid) * self.grid)
            for s in plan_steps(self.domain, plan, start, plan_id)
        ]
        out = PartialPlan(
            agent=self.agent,
            plan_id=plan_id,
            baseline="",
            steps=steps,
            complete=True,
            request_id=req.request_id,
            purpose="revise" if req.kind == "revise" else "new",
        )
        self.ctx.log.info(
            "plan", request=req.request_id, plan=plan_id, steps=len(steps), makespan=plan.makespan
        )
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
        the transient beliefs hold again) or not."""
        blocked = not timeout and self.transients.blocked(self.domain, self.beliefs, req.goal)
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


class OnlinePlannerService(_Epochs):
    """Continual planning for one agent: rounds in a worker thread, plans as they come.

    Real time: rounds back to back, bounded by seconds. Virtual time: this epoch's rounds
    after its beliefs, bounded by expansions (the epoch's budget), then the ack.
    """

    def __init__(
        self,
        ctx: ServiceContext,
        core: ContinualPlanner,
        planning_speed: float = 0.0,
        ack_timeout: float = 120.0,
    ) -> None:
        self.ctx, self.core, self.agent = ctx, core, core.agent
        self.has_beliefs = False
        self.beliefs_in = BeliefsReceiver()
        self.deferred: SearchRequest | None = None
        self.wake = asyncio.Event()
        self.planning_speed = planning_speed or core.settings.planning_speed
        self.ack_timeout = ack_timeout
        self.lockstep = self._lockstep(self.input_keys())

    def input_keys(self) -> list[str]:
        agent = self.core.agent
        return [
            keys.planner_requests(agent),
            keys.scheduler_beliefs(agent),
            keys.executor_status(agent),
            *self.lockstep_keys(),
        ]

    async def handle_input(self, key: str, msg: Message) -> None:
        await self.handle(key, msg)
        if self.core.search is not None and not self.lockstep.on:
            self.wake.set()

    async def plan_epoch(self) -> None:
        """Run this epoch's rounds: as many as its expansion budget pays for."""
        budget = self.budget()
        while (search := self.core.search) is not None and budget > 0:
            events = await self.round(search, budget)
            if events is None:
                return
            budget -= max(1, sum(e.expanded for e in events if isinstance(e, RoundDone)))
            await self.send(self.core.after_round(search, events))

    async def round(self, search: Search, expansions: int | None) -> list[Event] | None:
        """One round in a worker thread; a crash fails the search (reported), not us."""
        try:
            return await asyncio.to_thread(self.core.round, search, expansions)
        except Exception as exc:
            self.ctx.log.error("search_error", error=f"{type(exc).__name__}: {exc}")
            self.core.search = None
            await self.send([self.core._status(search.request_id, "failed", str(exc))])
            return None

    async def handle(self, key: str, msg: Message) -> None:
        core = self.core
        if isinstance(msg, BeliefsUpdate):
            beliefs = self.beliefs_in.apply(msg)
            if beliefs is None:
                self.ctx.log.warning("beliefs_skipped", seq=msg.seq, base=msg.base)
                return  # a change of beliefs we never had: the next whole set comes soon
            self.has_beliefs = True
            await asyncio.to_thread(core.warm, beliefs)  # a grounding holds no loop up
            await self.send(core.on_beliefs(beliefs, msg.time))
            if self.deferred is not None and not waits(self.deferred, self.beliefs_in, True):
                req, self.deferred = self.deferred, None
                await self.start(keys.planner_requests(core.agent), req)
        elif isinstance(msg, SearchRequest):
            try:  # before anything: a bad request leaves the search in progress alone
                checked(self.core.domain, msg)
            except BadRequestError as exc:
                await self.send([core._status(msg.request_id, "failed", exc.reason)])
                raise
            if waits(msg, self.beliefs_in, self.has_beliefs):
                self.deferred = msg  # plan from the beliefs it was asked from, once here
                return
            await self.start(key, msg)
            self.has_beliefs = self.has_beliefs or bool(msg.problem)
        elif isinstance(msg, ActionStatus):
            core.on_status(msg)

    async def start(self, key: str, req: SearchRequest) -> None:
        await asyncio.to_thread(self.core.warm, self.core.beliefs, req)
        try:
            await self.send(self.core.on_request(req))
        except BadRequestError as exc:
            await self.send([self.core._status(req.request_id, "failed", exc.reason)])
            raise

    async def rounds(self) -> None:
        """Run the search in progress round after round (Alg. 2's loop)."""
        while True:
            await self.wake.wait()
            self.wake.clear()
            while (search := self.core.search) is not None:
                events = await self.round(search, None)
                if events is None:
                    break
                await self.send(self.core.after_round(search, events))

    async def send(self, messages: list[Message]) -> None:
        agent = self.core.agent
        for msg in messages:
            if isinstance(msg, PartialPlan):
                key = keys.planner_plans(agent)
                self.ctx.log.info(
                    "plan",
                    plan=msg.plan_id,
                    baseline=msg.baseline,
                    steps=len(msg.steps),
                    complete=msg.complete,
                    applies_after=msg.applies_after,
                )
            elif isinstance(msg, SearchStatus):
                key = keys.planner_status(agent)
            elif isinstance(msg, SearchRound):
                key = keys.planner_rounds(agent)
            elif isinstance(msg, ForecastReport):
                key = keys.planner_forecasts(agent)
            else:
                continue
            await publish(self.ctx.bus, key, msg, block=True)


def checked(domain: Domain, req: SearchRequest) -> SearchRequest:
    """Return `req` if its goal fits the domain (checked before it waits for beliefs)."""
    try:
        check_goal(domain, req.goal)
    except GoalError as exc:
        raise BadRequestError(req.request_id, str(exc)) from exc
    return req


def planner_main(settings: PlannerSettings, domain: Domain, raw: RawAgentFile) -> ServiceMain:
    """Return the service body of one agent's planner (online or offline)."""

    async def body(ctx: ServiceContext) -> None:
        backend = settings.backend or raw.planning.backend
        mode = settings.planning or raw.planning.mode
        if mode == "online":
            core = ContinualPlanner(
                settings.agent,
                domain,
                raw.planning,
                settings.time_grid,
                log=ctx.log.info,
                improve=settings.improve,
                transients=Transients(raw.transient),
                life=settings.restart,
            )
            online = OnlinePlannerService(ctx, core, settings.planning_speed, settings.ack_timeout)
            stream = sequenced_inputs(ctx.bus, online.input_keys(), ONLINE_INPUTS, ctx)
            ctx.start(online.inputs(stream), name="planner")
            ctx.start(online.rounds(), name="rounds")
            service: _Epochs = online
        else:
            service = PlannerService(
                ctx,
                settings.agent,
                domain,
                raw,
                backend,
                settings.time_grid,
                settings.planning_speed,
                settings.ack_timeout,
                life=settings.restart,
            )
            stream = sequenced_inputs(ctx.bus, service.input_keys(), INPUTS, ctx)
            ctx.start(service.inputs(stream), name="planner")
        ready = announce_ready(
            ctx.bus, settings.agent, "planner", service.lockstep.decided, lockstep=service.lockstep
        )
        ctx.start(ready, name="ready")

    return body
