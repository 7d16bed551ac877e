"""The scheduler service: one agent's mind on the bus.

Inputs: the agent's percepts from the world, partial plans and search status from its
planner, step statuses and arrest reports from its executor. Outputs: the belief set
(every epoch, for the executor and the planner), desire events, search requests to the
planner, plans and early-arrest requests to the executor.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from itertools import count

from msgspec.structs import replace

from cbdi import keys
from cbdi.beliefs import BeliefsSender
from cbdi.bus import publish, sequenced_inputs, serve
from cbdi.bus.typed import Stamped, dropping
from cbdi.errors import CbdiError
from cbdi.lockstep import WORLD, Lockstep, Need, announce_ready
from cbdi.peers import Peers
from cbdi.plugins import percept_types
from cbdi.runtime import ServiceContext, ServiceSettings
from cbdi.runtime.service import ServiceMain
from cbdi.view import world_info
from cbdi.wire.agent import (
    ActionStatus,
    AgentReply,
    AgentRequest,
    AgentState,
    ArrestReport,
    Claim,
    EarlyArrest,
    PartialPlan,
    StateRequest,
)
from cbdi.wire.base import Message
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi.wire.world import (
    ActionOutcome,
    EpochAck,
    Percept,
    Tick,
)
from cbdi_scheduler.asking import HeldAsks, ask_request, send_ask
from cbdi_scheduler.intentions import Command
from cbdi_scheduler.mind import Mind, Reaction
from cbdi_scheduler.requests import prepare_request
from cbdi_scheduler.state import PlanLog, agent_state

__all__ = ["SchedulerService", "SchedulerSettings", "scheduler_main"]

INPUTS: tuple[type[Message], ...] = (
    *percept_types(),  # Sensed and the installed domains' own
    ActionOutcome,
    PartialPlan,
    SearchStatus,
    ActionStatus,
    ArrestReport,
    Claim,
    EpochAck,
    Tick,
)


MAP_WAIT = 30.0  # wall seconds between "still waiting for the world" warnings


@dataclass(frozen=True)
class SchedulerSettings(ServiceSettings):
    """Settings of `cbdi-scheduler`."""

    agent: str = field(default="robot1", metadata={"help": "the agent's name"})
    agent_file: str = field(default="", metadata={"help": "the agent file (TOML)"})
    load_map: bool = field(default=True, metadata={"help": "ask the world for its map first"})
    ack_timeout: float = field(
        default=120.0, metadata={"help": "lockstep: seconds to wait for the planner's epoch"}
    )


class SchedulerService:
    """The mind of one agent on the bus."""

    def __init__(self, ctx: ServiceContext, mind: Mind, ack_timeout: float = 120.0) -> None:
        self.ctx, self.mind, self.agent = ctx, mind, mind.agent
        self.search_ids = count(1)
        self.search_id = ""
        self.last_search: SearchRequest | None = None  # resent when the planner (re)appears
        self.ack_timeout = ack_timeout
        self.beliefs_out = BeliefsSender(self.agent)  # what changed, every epoch
        self.plan_log = PlanLog()  # the executing plan's steps, for `on_state`
        self.members: list[str] = []  # the world's lockstep members (from its info)
        self.held = HeldAsks()  # other agents' asks, until the epoch after theirs
        self.lockstep = Lockstep(
            self.input_keys(),
            lambda first: ctx.start(self.epochs(first), name="epochs"),
            bus=ctx.bus,
            me=keys.member(mind.agent, "scheduler"),
        )

    def input_keys(self) -> list[str]:
        a = self.agent
        claims = self.mind.claims is not None
        return [
            keys.world_stream("clock"),
            keys.world_for_agent(a),  # percepts and action outcomes, in order
            keys.planner_plans(a),
            keys.planner_status(a),
            keys.executor_status(a),
            keys.executor_arrested(a),
            *([keys.scheduler_claims_all()] if claims else []),
            keys.epoch_ack(a, "executor"),
            keys.epoch_ack(a, "planner"),
            *([keys.epoch_ack("*", "scheduler")] if claims else []),
        ]

    async def load_map(self) -> None:
        """Believe the world's map (its objects and facts): the paper's `map_loaded`.

        Waits for the world as long as it takes (saying so every `MAP_WAIT` s): an agent
        may start well before its world (another project, another machine), and one that
        went on without the map and the world's members would plan from nothing and
        could take a lockstep run for a real-time one.
        """
        waited = 0.0
        while True:
            try:
                info = await world_info(self.ctx.bus, timeout=MAP_WAIT)
                break
            except (CbdiError, TimeoutError) as exc:
                waited += MAP_WAIT
                why = str(exc) or "the world did not answer"
                self.ctx.log.warning("waiting_for_world", waited=waited, error=why)
        known = self.mind.knowledge.map_beliefs(info)
        self.mind.beliefs = self.mind.beliefs.adding(known)
        self.members = list(info.members)
        me = keys.member(self.agent, "scheduler")
        self.lockstep.lockstep_member = info.lockstep and me in info.members
        self.ctx.log.info("map_loaded", map=info.map_name, beliefs=len(known))

    async def run(self, stream: AsyncIterator[Stamped], load_map: bool) -> None:
        """Handle every input: in arrival order (real time), or epoch by epoch (lockstep)."""
        if load_map:
            await self.load_map()  # inputs wait in the stream meanwhile
        # Ready (the start barrier) only now that we know the world's map and members.
        ready = announce_ready(
            self.ctx.bus, self.agent, "scheduler", self.lockstep.decided, lockstep=self.lockstep
        )
        self.ctx.start(ready, name="ready")
        async for item in stream:
            for key, m in await self.lockstep.put(item):
                with dropping(self.ctx, key, m):
                    await self.on_message(m)

    async def on_message(self, msg: Message) -> None:
        """React to one input and publish what follows (beliefs first after percepts)."""
        if isinstance(msg, EpochAck | Tick):
            return
        if isinstance(msg, Percept):
            self.held.release(msg.epoch)
        reaction = self.react(msg)
        if isinstance(msg, Percept):  # beliefs first: the planner plans from them
            update = self.beliefs_out.update(self.mind.beliefs, msg.time, msg.epoch)
            await publish(self.ctx.bus, keys.scheduler_beliefs(self.agent), update, block=True)
        await self.act(reaction)

    async def epochs(self, first: int) -> None:
        """Lockstep: the scheduler's two parts of each epoch.

        First the executor's reports of the epoch before, the group's claims (by agent
        name) and the world's outcomes and percepts: belief revision, rules, commands
        (stage `beliefs`). Then, once the planner's rounds of this epoch are done, its
        plans and status: plans to the executor (stage `done`).
        """
        a = self.agent
        if not self.members:
            self.members = await self.lockstep.learn_members(self.ctx.bus)
        own = [keys.member(a, c) for c in ("executor", "planner")]
        executor, planner = (m if m in self.members else "" for m in own)
        peers = sorted(
            m for m in self.members if m.endswith("/scheduler") and m != keys.member(a, "scheduler")
        )
        if self.mind.claims is None:
            peers = []

        def needs(epoch: int, stage: str, _members: frozenset[str]) -> list[Need]:
            if stage == "done":
                return [Need(planner, epoch)] if planner else []
            before = [Need(s, epoch - 1) for s in ([executor] if executor else []) + peers]
            return [*before, Need(WORLD, epoch)]

        stages = ("beliefs", "done")
        epochs = self.lockstep.epochs(
            first, needs, self.ack_timeout, self.ctx.log, stages, self.members
        )
        async for epoch in epochs:
            for key, msg in epoch.messages:
                with dropping(self.ctx, key, msg):
                    await self.on_message(msg)

    async def watch_peers(self) -> None:
        """React to the agent's planner and executor (re)appearing (`on_planner`,
        `on_executor`); not to one back with our own session (`cbdi.peers`): the bus
        went, not they, and what was sent meanwhile is recovered."""
        me = keys.alive(keys.service_id("scheduler", self.agent))
        planner = keys.alive(keys.service_id("planner", self.agent))
        executor = keys.alive(keys.service_id("executor", self.agent))
        peers = Peers(me)
        async for event in self.ctx.bus.watch_alive(keys.alive(keys.service_id("*", self.agent))):
            appearance = peers.observe(event)
            if appearance is None or event.key not in (planner, executor):
                continue
            if appearance == "reconnected":
                self.ctx.log.info("bus_reconnected", peer=keys.service_of_alive(event.key))
            elif event.key == planner:
                if appearance == "first" and self.planner_in_lockstep():
                    # It subscribed before it said ready, and no epoch (no search) starts
                    # before that: its first appearance missed nothing, however late the
                    # event comes. A resend would depend on when it comes (under load a
                    # replay check failed on one).
                    continue
                await self.on_planner()
            else:
                await self.on_executor(again=appearance == "again")

    def planner_in_lockstep(self) -> bool:
        """Whether our planner is a member of a lockstep run (known once the map is)."""
        planner = keys.member(self.agent, "planner")
        return self.lockstep.lockstep_member is True and planner in self.members

    async def on_planner(self) -> None:
        """Send the search in progress again when the planner appears: a request sent
        before it subscribed, or to a planner that restarted, would be lost. The next
        beliefs go whole (it missed the series)."""
        self.beliefs_out.resend()
        if self.last_search is not None:
            self.ctx.log.info("search_resent", request=self.last_search.request_id)
            key = keys.planner_requests(self.agent)
            await publish(self.ctx.bus, key, self.last_search, block=True)

    async def on_executor(self, again: bool) -> None:
        """Send the next beliefs whole when the executor (re)appears; one that comes
        back (`again`) lost the plan it had, so the intention is planned again."""
        self.beliefs_out.resend()
        if again:
            self.ctx.log.warning("executor_restarted")
            await self.act(Reaction(commands=self.mind.intentions.executor_restarted()))

    async def watch_group(self) -> None:
        """Tell an agent that appears our standing claims (it missed them); not one back
        with our own session (nothing was missed: `cbdi.peers`)."""
        claims = self.mind.claims
        if claims is None:
            return
        peers = Peers(keys.alive(keys.service_id("scheduler", self.agent)))
        async for event in self.ctx.bus.watch_alive(keys.alive(keys.service_id("scheduler", "*"))):
            if peers.observe(event) in ("first", "again"):
                for claim in claims.mine():
                    await publish(
                        self.ctx.bus, keys.scheduler_claims(self.agent), claim, block=True
                    )

    async def on_request(self, key: str, req: AgentRequest) -> Message:
        """Serve another agent's request (the next cycle reacts to what it changed).

        Asked on `.../rpc/request/<group>` (the router lets only that group's identities
        ask there), the group is the key's: a request naming another is refused. An
        agent's ask (it names its epoch) is held until our next epoch (`asking`).
        """
        group = keys.request_group(key)
        if group and group != req.group:
            why = f"group {req.group!r} named, but asked under {group!r} (the key {key})"
            reply = AgentReply(accepted=False, reason=why)
        else:
            served = prepare_request(self.mind, req)
            reply = served.reply
            if served.apply is not None:
                self.held.take(req.epoch, self.mind.epoch, served.apply)
        log = self.ctx.log.info if reply.accepted else self.ctx.log.warning
        log(
            "agent_request",
            from_agent=req.from_agent,
            group=req.group,
            op=req.op,
            accepted=reply.accepted,
            reason=reply.reason,
        )
        return reply

    async def on_state(self, key: str, req: StateRequest) -> AgentState:
        """Tell what the agent believes, desires and intends now (`cbdi ctl show`)."""
        return agent_state(self.mind, self.plan_log, req.beliefs)

    def react(self, msg: Message) -> Reaction:
        mind = self.mind
        if isinstance(msg, Percept):
            return mind.on_percepts(msg)
        if isinstance(msg, ActionOutcome):
            return mind.on_outcome(msg)
        if isinstance(msg, PartialPlan):
            return mind.on_plan(msg)
        if isinstance(msg, SearchStatus):
            if msg.request_id == self.search_id and msg.status == "failed":
                return mind.on_search_failed(msg.reason, msg.blocked)
            return Reaction()
        if isinstance(msg, ActionStatus):
            self.plan_log.reported(msg)
            return mind.on_status(msg)
        if isinstance(msg, Claim):
            return mind.on_claim(msg)
        assert isinstance(msg, ArrestReport)
        return mind.on_arrested(msg)

    async def act(self, reaction: Reaction) -> None:
        bus, a = self.ctx.bus, self.agent
        for claim in reaction.claims:
            self.ctx.log.info(
                "claim",
                item=claim.item,
                epoch=claim.epoch,
                cost=claim.cost,
                released=claim.released,
            )
            await publish(bus, keys.scheduler_claims(a), claim, block=True)
        for event in reaction.events:
            self.ctx.log.info("desire", desire=event.desire, what=event.event, reason=event.reason)
            await publish(bus, keys.scheduler_desires(a), event, block=True)
        for ask in reaction.asks:
            req = ask_request(a, self.mind.spec.group, ask, self.mind.epoch)
            await send_ask(bus, self.ctx.log, req, ask.agent)
        for c in reaction.commands:
            msg = self.message(c)
            if msg is None:
                continue
            self.ctx.log.info("command", kind=c.kind, reason=c.reason)
            key = {
                SearchRequest: keys.planner_requests(a),
                PartialPlan: keys.scheduler_plans(a),
                EarlyArrest: keys.scheduler_arrest(a),
            }[type(msg)]
            await publish(bus, key, msg, block=True)

    def message(self, c: Command) -> Message | None:
        a = self.agent
        if c.kind == "start_search" and c.desire is not None:
            revise = c.reason == "goal revised" and self.search_id
            if not revise:
                self.search_id = f"{a}-search-{next(self.search_ids)}"
            req = SearchRequest(
                agent=a,
                request_id=self.search_id,
                kind="revise" if revise else "start",
                desire=c.desire.name,
                goal=[list(g.atom) for g in c.desire.goal],
                beliefs=self.beliefs_out.seq,  # the planner waits for these (or later)
            )
            self.last_search = replace(req, kind="start")
            return req
        if c.kind in ("cancel_search", "drop", "achieved") and self.search_id:
            request_id, self.search_id = self.search_id, ""
            self.last_search = None
            return SearchRequest(agent=a, request_id=request_id, kind="cancel")
        if c.kind == "execute" and c.plan is not None:
            cur = self.mind.intentions.current
            self.plan_log.sent(c.plan, cur.steps if cur is not None else [])
            return c.plan
        if c.kind == "arrest":
            return EarlyArrest(agent=a, plan_id=c.plan_id, after_step=c.after_step)
        return None


def scheduler_main(mind: Mind, settings: SchedulerSettings) -> ServiceMain:
    """Return the service body of one agent's scheduler."""

    async def body(ctx: ServiceContext) -> None:
        service = SchedulerService(ctx, mind, settings.ack_timeout)
        stream = sequenced_inputs(ctx.bus, service.input_keys(), INPUTS, ctx)
        rpc = keys.component_rpc(mind.agent, "scheduler", "request")
        every = keys.agent_request(mind.agent, "**")
        asked = serve(ctx.bus, every, AgentRequest, service.on_request, ctx, trace_as=rpc)
        ctx.start(asked, name="requests")  # `**`: the bare key and `.../request/<group>`
        state = keys.component_rpc(mind.agent, "scheduler", "state")
        ctx.start(
            serve(ctx.bus, state, StateRequest, service.on_state, ctx, trace=False), name="state"
        )  # read-only: not recorded (a watching operator would flood the recording)
        ctx.start(service.run(stream, settings.load_map), name="scheduler")
        ctx.start(service.watch_peers(), name="peers-watch")
        ctx.start(service.watch_group(), name="group-watch")

    return body
