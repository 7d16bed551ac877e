"""The online planner service: continual planning (`ContinualPlanner`) for one agent."""

from __future__ import annotations

import asyncio

from cbdi import keys
from cbdi.beliefs import BeliefsReceiver
from cbdi.bus import publish
from cbdi.runtime import ServiceContext
from cbdi.wire.agent import ActionStatus, BeliefsUpdate, PartialPlan
from cbdi.wire.base import Message
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound, SearchStatus
from cbdi_planner.agent.continual import ContinualPlanner
from cbdi_planner.agent.epochs import Epochs, checked, waits
from cbdi_planner.agent.errors import BadRequestError
from cbdi_planner.agent.lines import Search
from cbdi_planner.continual import Event, RoundDone

__all__ = ["OnlinePlannerService"]


class OnlinePlannerService(Epochs):
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
