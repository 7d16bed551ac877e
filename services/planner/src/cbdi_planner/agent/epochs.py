"""What both planner services share: their inputs, the lockstep gate and the epoch's
expansion budget (virtual time), and the checks of a search request."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import AsyncIterator

from cbdi import keys
from cbdi.beliefs import BeliefsReceiver
from cbdi.bus.typed import Stamped, dropping
from cbdi.lockstep import Lockstep, Need, default_sender
from cbdi.runtime import ServiceContext
from cbdi.wire.agent import ActionStatus, BeliefsUpdate
from cbdi.wire.base import Message
from cbdi.wire.planner import SearchRequest
from cbdi.wire.world import EpochAck, Tick
from cbdi_planner.agent.errors import BadRequestError, UnknownAgentError
from cbdi_planner.agent.problem import (
    GoalError,
    check_goal,
)
from cbdi_planner.pddl.ast import Domain

__all__ = ["INPUTS", "NO_COUNTING", "Epochs", "checked", "waits"]

INPUTS: tuple[type[Message], ...] = (SearchRequest, BeliefsUpdate, ActionStatus, Tick, EpochAck)
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


class Epochs(ABC):
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
        executor = keys.member(self.agent, "executor")
        scheduler = keys.member(self.agent, "scheduler")

        def needs(epoch: int, _stage: str, members: frozenset[str]) -> list[Need]:
            found = [Need(executor, epoch - 1)] if executor in members else []
            if scheduler in members:
                found.append(Need(scheduler, epoch, "beliefs"))
            return found

        async for epoch in self.lockstep.epochs(first, needs, self.ack_timeout, self.ctx.log):
            for key, msg in epoch.messages:
                if not isinstance(msg, Tick | EpochAck):
                    await self.checked_handle(key, msg)
            await self.plan_epoch()

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


def checked(domain: Domain, req: SearchRequest) -> SearchRequest:
    """Return `req` if its goal fits the domain (checked before it waits for beliefs)."""
    try:
        check_goal(domain, req.goal)
    except GoalError as exc:
        raise BadRequestError(req.request_id, str(exc)) from exc
    return req
