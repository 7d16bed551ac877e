"""The executor service: the dispatcher on the bus, for one agent.

Inputs: plans and early-arrest requests from the agent's scheduler, its beliefs (one
update per world epoch), the world's clock and the agent's action outcomes. Outputs:
action requests to the world, every step's status, arrest reports, and the epoch
acknowledgements the world waits for in lockstep mode. An epoch is acknowledged once the
beliefs of that epoch were seen and every due step was dispatched (or at once when
nothing waits), so a lockstep world never runs ahead of the agent.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import AsyncIterator, Mapping, Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.beliefs import BeliefSet, BeliefsReceiver
from cbdi.bus import publish, request, sequenced_inputs, serve
from cbdi.bus.typed import Stamped, dropping
from cbdi.clock import SimClock, WallClock
from cbdi.errors import CbdiError, RequestTimeoutError
from cbdi.lockstep import WORLD, Lockstep, Need, announce_ready
from cbdi.performer import outcomes_key, performer_key, stop_key
from cbdi.plugins import percept_types
from cbdi.robot import MEMBER
from cbdi.runtime import ServiceContext, ServiceSettings
from cbdi.runtime.service import ServiceMain
from cbdi.wire.agent import (
    BeliefsUpdate,
    EarlyArrest,
    ExecutorState,
    ExecutorStop,
    PartialPlan,
)
from cbdi.wire.base import Message
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    EpochAck,
    Percept,
    Tick,
)
from cbdi_executor.dispatcher import Dispatcher, Effects

__all__ = ["ExecutorService", "ExecutorSettings", "condition_waits", "executor_main"]

INPUTS: tuple[type[Message], ...] = (
    Tick,
    BeliefsUpdate,
    PartialPlan,
    EarlyArrest,
    ActionOutcome,
    *percept_types(),  # Sensed and the installed domains' own
    EpochAck,
)


@dataclass(frozen=True)
class ExecutorSettings(ServiceSettings):
    """Settings of `cbdi-executor`."""

    agent: str = field(default="robot1", metadata={"help": "the agent this executor serves"})
    ack_timeout: float = field(
        default=120.0, metadata={"help": "lockstep: seconds to wait for the scheduler's epoch"}
    )
    performer: tuple[str, ...] = field(
        default=(),
        metadata={"help": "an ACTION a performer carries out (cbdi.performer), not the world"},
    )
    world_wait: float = field(
        default=15.0,
        metadata={"help": "wall s to ask a world that does not answer again (it restarts)"},
    )
    condition_wait: float = field(
        default=0.0,
        metadata={
            "help": "simulated s a due step waits for its conditions (sensing catching up) "
            "before it is refused (the agent file's [execution] condition_wait)"
        },
    )
    condition_wait_for: tuple[str, ...] = field(
        default=(),
        metadata={"help": "ACTION=SECONDS: condition_wait for one action"},
    )


class ExecutorService:
    """One agent's executor on the bus."""

    def __init__(
        self,
        ctx: ServiceContext,
        agent: str,
        ack_timeout: float = 120.0,
        performers: tuple[str, ...] = (),
        world_wait: float = 15.0,
        condition_wait: float = 0.0,
        condition_wait_for: Mapping[str, float] | None = None,
    ) -> None:
        self.ctx, self.agent = ctx, agent
        self.world_wait = world_wait
        self.performers = frozenset(a.lower() for a in performers)
        self.dispatcher = Dispatcher(agent, condition_wait, condition_wait_for)
        self.clock = SimClock()
        self.beliefs = BeliefSet()
        self.beliefs_epoch = -1
        self.beliefs_in = BeliefsReceiver()
        self.outcome_epoch = -1
        self.acked = -1
        self.taking_in = False  # lockstep: an epoch's inputs are being taken in, dispatch after
        self.ack_timeout = ack_timeout
        self.lockstep = Lockstep(
            self.input_keys(),
            lambda first: ctx.start(self.epochs(first), name="epochs"),
            bus=ctx.bus,
            me=keys.member(agent, "executor"),
        )

    def input_keys(self) -> list[str]:
        a = self.agent
        return [
            keys.world_stream("clock"),
            keys.world_for_agent(a),  # outcomes, then percepts: the world's epoch is out
            keys.scheduler_plans(a),
            keys.scheduler_arrest(a),
            keys.scheduler_beliefs(a),
            keys.epoch_ack(a, "scheduler"),
            *([outcomes_key(a), keys.epoch_ack(a, MEMBER)] if self.performers else []),
        ]

    async def run(self, stream: AsyncIterator[Stamped]) -> None:
        """Handle every input: in arrival order (real time), or epoch by epoch (lockstep)."""
        async for item in stream:
            for key, m in await self.lockstep.put(item):
                if not isinstance(m, (EpochAck, Percept)):
                    with dropping(self.ctx, key, m):
                        await self.handle(m)
                    await self.maybe_ack()

    async def epochs(self, first: int) -> None:
        """Lockstep: the executor's part of each epoch, once the scheduler's is done."""
        scheduler = keys.member(self.agent, "scheduler")
        robot = keys.member(self.agent, MEMBER)  # its performers' process (cbdi.robot)

        def needs(epoch: int, _stage: str, members: frozenset[str]) -> list[Need]:
            found = [Need(WORLD, epoch)]
            if scheduler in members:
                found.append(Need(scheduler, epoch))
            if robot in members:  # the outcomes of its calls that ended by this epoch
                found.append(Need(robot, epoch, "beliefs"))
            return found

        async for epoch in self.lockstep.epochs(first, needs, self.ack_timeout, self.ctx.log):
            # Take in the whole epoch (outcomes, beliefs, plans, arrests) before anything
            # is dispatched: an outcome handled first would start the next step of a
            # plan the scheduler arrests in the same epoch.
            self.taking_in = True
            try:
                for key, msg in epoch.messages:
                    if not isinstance(msg, (EpochAck, Percept)):
                        with dropping(self.ctx, key, msg):
                            await self.handle(msg)
            finally:
                self.taking_in = False
            await self.step()
            self.acked = epoch.number  # acknowledged as the loop goes on

    async def handle(self, msg: Message) -> None:
        now = self.clock.now()
        if isinstance(msg, Tick):
            self.clock.on_tick(msg.epoch, msg.time)
            await self.step()
        elif isinstance(msg, BeliefsUpdate):
            beliefs = self.beliefs_in.apply(msg) if msg.agent == self.agent else None
            if beliefs is None and msg.agent == self.agent:
                self.ctx.log.warning("beliefs_skipped", seq=msg.seq, base=msg.base)
            if beliefs is not None and msg.epoch >= self.beliefs_epoch:
                self.beliefs, self.beliefs_epoch = beliefs, msg.epoch
                self.clock.on_tick(msg.epoch, msg.time)  # the world has reached that epoch
                await self.step()
        elif isinstance(msg, PartialPlan):
            await self.send(self.dispatcher.load(msg, now))
            await self.step()
        elif isinstance(msg, EarlyArrest):
            await self.send(self.dispatcher.early_arrest(msg.plan_id, msg.after_step, now))
        elif isinstance(msg, ActionOutcome):
            self.outcome_epoch = max(self.outcome_epoch, msg.epoch)
            self.clock.on_tick(msg.epoch, msg.time)
            await self.send(self.dispatcher.on_outcome(msg, self.clock.now()))
            await self.step()

    async def on_stop(self, _key: str, req: ExecutorStop) -> Message:
        """The operator's safe stop: serve it at once, whatever the scheduler does."""
        d = self.dispatcher
        if req.op != "state":
            d.halt(req.op == "stop")
            self.ctx.log.info("safe_stop", op=req.op, by=req.from_agent)
            # Performers stop what they carry out for this agent (`cbdi.performer`).
            await publish(self.ctx.bus, stop_key(self.agent), req, block=True)
            if req.op == "resume":
                await self.step()
        running = d.running()
        return ExecutorState(
            agent=self.agent,
            halted=d.halted,
            running=running.step.step_id if running else "",
            time=self.clock.now(),
        )

    def current(self) -> bool:
        """Whether the beliefs are as new as everything the world told us (clock, outcomes).

        Inputs come from several publishers, so an outcome or a tick may arrive before the
        scheduler's beliefs of the same epoch: conditions are only checked once they have.
        """
        return self.beliefs_epoch >= max(self.clock.epoch, self.outcome_epoch)

    async def step(self) -> None:
        """Dispatch what is due now (again after a refusal frees the next step)."""
        while self.current() and not self.taking_in:
            effects = self.dispatcher.tick(self.clock.now(), self.beliefs)
            await self.send(effects)
            if not any(st.status == "refused" for st in effects.statuses):
                return

    async def maybe_ack(self) -> None:
        """Acknowledge the epoch once acted upon (at once when nothing waits)."""
        epoch = self.clock.epoch
        if epoch <= self.acked:
            return
        waiting = any(s.status == "waiting" for s in self.dispatcher.steps)
        if waiting and not self.current():
            return  # the scheduler's beliefs of this epoch are on their way
        if waiting and self.dispatcher.outcome_due(self.clock.now()):
            return  # the world's outcome of this epoch is on its way: the next step follows
        self.acked = epoch
        ack = EpochAck(agent=self.agent, epoch=epoch)
        await publish(self.ctx.bus, keys.agent_ack(self.agent), ack, block=True)

    async def send(self, effects: Effects) -> None:
        bus, now = self.ctx.bus, self.clock.now()
        for req in effects.requests:
            to = self.performers and req.action.lower() in self.performers
            key = performer_key(self.agent, req.action) if to else keys.world_act(self.agent)
            try:
                reply = await self.ask(key, req)
            except CbdiError as exc:
                reply = ActionReply(request_id=req.request_id, accepted=False, reason=str(exc))
            answered = self.dispatcher.on_reply(reply, now)
            effects.statuses += answered.statuses
            effects.arrest = answered.arrest or effects.arrest  # a rejection may end an arrest
        for status in effects.statuses:
            self.ctx.log.info(
                "step",
                plan=status.plan_id,
                step=status.step_id,
                action=status.action,
                status=status.status,
                reason=status.reason,
            )
            await publish(bus, keys.executor_status(self.agent), status, block=True)
        if effects.arrest is not None:
            self.ctx.log.info(
                "arrested", plan=effects.arrest.plan_id, last_step=effects.arrest.last_step
            )
            await publish(bus, keys.executor_arrested(self.agent), effects.arrest, block=True)

    async def ask(self, key: str, req: ActionRequest) -> ActionReply:
        """Send one request. A world that does not answer (killed, being restarted) is
        asked again until it does, `world_wait` wall seconds at most: restarted, it goes
        on where it was, and a request it served already gets the same reply again."""
        clock = WallClock()
        wait = self.world_wait if key == keys.world_rpc("act") else 0.0
        deadline = clock.now() + wait
        for attempt in itertools.count():
            try:
                return await request(self.ctx.bus, key, req, ActionReply)
            except RequestTimeoutError:
                if clock.now() >= deadline:
                    raise
                if attempt == 0:
                    self.ctx.log.warning("world_silent", request=req.request_id, wait=wait)
                await clock.sleep(0.1)
        raise AssertionError("unreachable")


def condition_waits(pairs: Sequence[str]) -> dict[str, float]:
    """Parse `ACTION=SECONDS` pairs; ValueError naming the bad one."""
    out: dict[str, float] = {}
    for pair in pairs:
        action, sep, text = pair.partition("=")
        try:
            seconds = float(text) if sep else math.nan
        except ValueError:
            seconds = math.nan
        if not action or not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(
                f"condition_wait_for {pair!r}: expected ACTION=SECONDS, seconds finite and >= 0"
            )
        out[action.lower()] = seconds
    return out


def executor_main(settings: ExecutorSettings) -> ServiceMain:
    """Return the service body of one executor."""

    async def body(ctx: ServiceContext) -> None:
        service = ExecutorService(
            ctx,
            settings.agent,
            settings.ack_timeout,
            settings.performer,
            settings.world_wait,
            settings.condition_wait,
            condition_waits(settings.condition_wait_for),
        )
        stream = sequenced_inputs(ctx.bus, service.input_keys(), INPUTS, ctx)
        ctx.start(service.run(stream), name="executor")
        stop = serve(
            ctx.bus,
            keys.component_rpc(settings.agent, "executor", "stop"),
            ExecutorStop,
            service.on_stop,
            ctx,
        )
        ctx.start(stop, name="stop")
        ready = announce_ready(
            ctx.bus, settings.agent, "executor", service.lockstep.decided, lockstep=service.lockstep
        )
        ctx.start(ready, name="ready")

    return body
