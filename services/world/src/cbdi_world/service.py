"""The world service: a domain's pure simulator (`cbdi.simulator`) behind the bus.

Every epoch it steps the simulator and publishes the tick, action outcomes, each agent's
percepts, a snapshot and (periodically) statistics. Requests (`act`, `stats`, `info`) are
answered at once on the same event loop, so they never race with a step. Pacing comes
from the injected clock: `speed` simulated seconds per wall second, or as fast as possible
(speed 0), and in lockstep mode only once every agent acknowledged the epoch before.

With `--state FILE` it saves its state every epoch and notes every request it serves
(`cbdi_world.recovery`); restarted (`--restart` above 0, `CBDI_RESTART` from `cbdi up`)
it goes on from that file at the epoch it was killed in, without the start barrier: the
members send their latest acks again when its liveliness token comes back
(`cbdi.lockstep.announce_ready`), a request it already served (an executor asking
again after losing the reply) gets the same reply, once, and the epoch it was killed
in goes out again (a member that had it takes the repeat as had; in real time, its
outcomes may be all that tells an executor its running action ended).
"""

from __future__ import annotations

import asyncio
from collections import Counter
from collections.abc import AsyncIterator

from msgspec.structs import replace

from cbdi import keys
from cbdi.bus import messages, publish, serve
from cbdi.bus.typed import dropping
from cbdi.clock import Clock, WallClock
from cbdi.errors import CbdiError
from cbdi.performer import outcomes_key
from cbdi.robot import MEMBER
from cbdi.runtime import ServiceContext
from cbdi.runtime.service import ServiceMain
from cbdi.simulator import EpochResult, Simulator
from cbdi.wire.base import Message
from cbdi.wire.common import ErrorReply, RunFinished
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    ClockRequest,
    EpochAck,
    StatsRequest,
    Tick,
    WorldInfoRequest,
)
from cbdi_world.acks import AckTracker, members_of
from cbdi_world.errors import UnknownAgentError
from cbdi_world.lateness import Lateness
from cbdi_world.recovery import (
    Entry,
    Keeper,
    Published,
    Recovered,
    Served,
    Stepped,
    WorldState,
    simulator_state,
)
from cbdi_world.settings import RESUME_IF_FOUND, WorldSettings, agent_entries, build_world
from cbdi_world.trace import RequestTrace

# The settings and `build_world` live in `cbdi_world.settings`; imported from here too.
ACT = keys.world_rpc("act")  # every agent's action requests are traced under this key

__all__ = ["WorldService", "WorldSettings", "agent_entries", "build_world", "world_main"]


class WorldService:
    """Adapter between the bus and one `World`."""

    def __init__(
        self,
        ctx: ServiceContext,
        world: Simulator,
        settings: WorldSettings,
        clock: Clock | None = None,
        keeper: Keeper | None = None,
    ) -> None:
        self.ctx = ctx
        self.world = world
        self.settings = settings
        self.clock = clock or WallClock()
        self.agents = [a for a in world.info().agents]
        self.members = members_of(settings.member, self.agents)
        self.acks = AckTracker(self.members)
        actions = getattr(world, "actions", ())  # the PDDL actions the simulator performs
        self.info = replace(
            world.info(),
            members=list(self.members),
            lockstep=settings.lockstep,
            actions=list(actions),
            simulator=settings.simulator,
        )
        self.finished: RunFinished | None = None
        self.sent_before: dict[str, int] = {}  # lockstep: RunFinished.sent
        self.lateness = Lateness(self.epoch_wall())
        self.trace = RequestTrace()
        self.performed: Counter[str] = Counter()  # performer outcomes seen, per agent
        self.last_tick: Tick | None = None  # for members that join late (rpc/clock)
        self.keeper = keeper
        self.served: dict[str, Served] = {}  # this epoch's requests, by id: served once
        self.resumed: tuple[EpochResult, bool] | None = None  # the epoch, and if it went out
        self.saved_at = -1  # the epoch of the last whole save

    def start(self) -> None:
        """Declare every endpoint now and start the tasks of the service."""
        ctx, bus = self.ctx, self.ctx.bus
        act = serve(bus, keys.world_act("**"), ActionRequest, self.on_act, ctx, trace_as=ACT)
        ctx.start(act, name="act")
        ctx.start(
            serve(bus, keys.world_rpc("stats"), StatsRequest, self.on_stats, ctx), name="stats"
        )
        ctx.start(
            serve(bus, keys.world_rpc("info"), WorldInfoRequest, self.on_info, ctx), name="info"
        )
        clock = serve(bus, keys.world_rpc("clock"), ClockRequest, self.on_clock, ctx, trace=False)
        ctx.start(clock, name="clock")
        acks = messages(bus, keys.epoch_ack_all(), EpochAck, ctx)
        ctx.start(self.follow_acks(acks), name="acks")
        performed = messages(bus, outcomes_key("*"), ActionOutcome, ctx)
        ctx.start(self.follow_performed(performed), name="performed")
        ctx.start(self.run(), name="epochs")

    async def on_act(self, key: str, req: ActionRequest) -> Message:
        """Perform an agent's action; one asked on another agent's key is refused (the
        router lets only an agent's executor ask on `cbdi/world/rpc/act/<agent>`)."""
        scope = keys.world_rpc_scope(key, "act")
        if scope and scope != req.agent:
            self.ctx.counters["act_not_own"] += 1
            why = f"an action of {req.agent!r} asked on {scope!r}'s key {key}"
            self.ctx.log.warning("act_refused", key=key, agent=req.agent, reason=why)
            return ErrorReply(code="not_own_agent", message=why)
        before = self.served.get(req.request_id)
        if before is not None and before.request == req:  # asked again: the reply was lost
            self.ctx.log.info("act_repeated", epoch=self.world.epoch, agent=req.agent)
            return before.reply
        if req.agent not in self.agents:
            self.ctx.counters["unknown_agent"] += 1
            self.ctx.log.warning("unknown_agent", key=key, agent=req.agent)
            return ErrorReply(code="unknown_agent", message=str(UnknownAgentError(req.agent)))
        reply = self.serve_act(req)
        self.note(Served(self.world.epoch, req, reply))  # on file before the reply goes out
        self.ctx.log.info(
            "act",
            epoch=self.world.epoch,
            agent=req.agent,
            action=req.action,
            accepted=reply.accepted,
            reason=reply.reason,
        )
        return reply

    def serve_act(self, req: ActionRequest) -> ActionReply:
        """Start `req` (of a known agent) in the simulator; trace it; remember the reply."""
        try:
            reply = self.world.request(req)
        except CbdiError as exc:  # an action (or arguments) the simulator does not perform
            reply = ActionReply(request_id=req.request_id, accepted=False, reason=str(exc))
        self.trace.record(self.world.epoch, req, reply)
        self.served[req.request_id] = Served(self.world.epoch, req, reply)
        return reply

    async def on_stats(self, key: str, req: StatsRequest) -> Message:
        try:
            if req.agent and req.agent not in self.agents:
                raise UnknownAgentError(req.agent)
            return self.world.stats(req.agent)
        except UnknownAgentError as exc:
            return ErrorReply(code="unknown_agent", message=str(exc))

    async def on_info(self, key: str, req: WorldInfoRequest) -> Message:
        return self.info

    async def on_clock(self, key: str, req: ClockRequest) -> Message:
        if self.last_tick is None:
            return ErrorReply(code="not_started", message="epoch 0 has not started")
        return self.last_tick

    async def follow_acks(self, acks: AsyncIterator[tuple[str, EpochAck]]) -> None:
        async for key, ack in acks:
            if ack.agent not in self.agents:
                self.ctx.bad_input(key, UnknownAgentError(ack.agent))
                continue
            with dropping(self.ctx, key, ack):
                await self.acks.observe(ack)

    async def follow_performed(self, outcomes: AsyncIterator[tuple[str, ActionOutcome]]) -> None:
        """Fold the outcomes of actions performed outside the world into the trace."""
        async for key, outcome in outcomes:
            if outcome.agent not in self.agents or keys.describe(key)["agent"] != outcome.agent:
                self.ctx.bad_input(key, UnknownAgentError(outcome.agent))
                continue
            self.trace.performed(outcome)
            self.performed[outcome.agent] += 1

    async def all_performed(self, timeout: float = 5.0) -> None:
        """Wait (up to `timeout` wall s) for the performer outcomes the members' latest
        acks say were sent: the last epoch's may come after its ack."""
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while loop.time() < end:
            missing = [
                agent
                for agent in self.agents
                if self.acks.sent.get(keys.member(agent, MEMBER), {}).get(outcomes_key(agent), 0)
                > self.performed[agent]
            ]
            if not missing:
                return
            await asyncio.sleep(0.01)
        self.ctx.log.warning("performed_missing", agents=",".join(missing))

    async def run(self) -> None:
        """Publish epoch 0 (or go on from the state file), then step until the run ends;
        keep serving requests after, `linger` wall seconds (then stop: a run's world does
        not outlive it) or until stopped."""
        if self.resumed is None:
            await self.wait_for_agents()
            # The static world once, for recorders and viewers (also on request: rpc/info).
            await publish(self.ctx.bus, keys.world_stream("info"), self.info, block=True)
            await self.advance(self.world.initial())
            start = self.clock.now()
        else:
            await self.go_on(*self.resumed)
            # The epoch under way began before the kill: the next one is due at once.
            start = self.clock.now() - (self.world.epoch + 1) * self.epoch_wall()
        while self.finished is None:
            await self.pace(start)
            due = start + (self.world.epoch + 1) * self.epoch_wall()
            woke = self.clock.now()
            await self.advance(self.world.step(), due, woke)
        self.ctx.log.info("finished", reason=self.finished.reason, epoch=self.finished.epoch)
        if self.keeper is not None:
            if self.settings.resume == RESUME_IF_FOUND:
                # Found again, the file would make the next run in this place (a
                # container started again) go on with this one, ended.
                self.keeper.discard()
            else:
                self.keeper.close()
        if self.settings.linger > 0:
            await WallClock().sleep(self.settings.linger)
            self.ctx.log.info("lingered", seconds=self.settings.linger)
            self.ctx.stop()

    async def advance(
        self, result: EpochResult, due: float | None = None, woke: float | None = None
    ) -> None:
        """Save the epoch the simulator reached, publish it, note that, see if the run
        ended; `due`, `woke`: when it was due (paced) and the world woke to step it."""
        self.served.clear()
        begin = self.clock.now()
        self.save(result)
        await self.publish_epoch(result)
        if due is not None:
            late = self.lateness.observe(due, self.clock.now(), woke, begin)
            if late is not None:  # what the agents act on came late: say which and why
                self.ctx.log.warning("epoch_late", epoch=result.epoch, **late)
        self.note(Published(result.epoch))
        await self.check_end()

    def resume(self, recovered: Recovered) -> None:
        """Take back the host's part of a saved state (the simulator is restored already),
        then replay on it what followed, in order: requests served, steps, publications."""
        state = recovered.state
        self.trace, self.saved_at = state.trace, state.result.epoch
        self.restore_marks(state.acked, state.behind, state.stalls)
        result, published = state.result, False
        for entry in recovered.entries:
            if isinstance(entry, Stepped):
                self.served.clear()
                result, published = self.world.step(), False
                self.restore_marks(entry.acked, entry.behind, entry.stalls)
            elif isinstance(entry, Served):
                if self.serve_act(entry.request) != entry.reply:  # not deterministic
                    self.ctx.log.warning("replay_differs", request=entry.request.request_id)
            else:
                published = entry.epoch == result.epoch
        if published:
            self.last_tick = self.tick_of(result)
        self.resumed = (result, published)

    def restore_marks(
        self, acked: dict[str, tuple[int, int]], behind: dict[str, int], stalls: dict[str, int]
    ) -> None:
        """Take the lockstep marks of the state file; an ack seen since it started (a
        member sends its latest again as soon as the world's token is back, which may
        be before the state file is read) is not taken back: the later mark stays."""
        marks = self.acks.acked
        for m, a in acked.items():
            if m in marks:
                marks[m] = max(marks[m], (int(a[0]), int(a[1])))
        self.acks.behind = {m: e for m, e in behind.items() if m not in marks or marks[m][0] < e}
        self.acks.stalls = Counter(stalls)

    async def go_on(self, result: EpochResult, published: bool) -> None:
        """Carry on at the epoch reached: publish it if it did not go out, then wait for
        its acks as usual (the members send theirs again: `cbdi.lockstep`)."""
        self.ctx.log.info(
            "recovered",
            state=self.settings.state,
            epoch=result.epoch,
            saved=self.saved_at,
            published=published,
        )
        # It goes out again even if it went out: a crash right after the publication
        # may lose what Zenoh had not sent yet. In lockstep every member waits for its
        # percepts, and a member that had them takes the repeat as had (`EpochGate`). In
        # real time the next epoch comes anyway, but the outcomes of this one do not:
        # an executor would wait for good for the end of its running action (a member
        # that had them ignores them: the step ended already).
        await self.publish_epoch(result)
        if not published:
            self.note(Published(result.epoch))
        await self.check_end()

    def save(self, result: EpochResult) -> None:
        """Keep the state (with `--state`): all of it every `state_every` epochs, else
        the step and the lockstep marks."""
        if self.keeper is None:
            return
        marks = dict(self.acks.acked), dict(self.acks.behind), dict(self.acks.stalls)
        if self.saved_at >= 0 and result.epoch - self.saved_at < self.settings.state_every:
            self.keeper.note(Stepped(result.epoch, *marks))
            return
        simulator = simulator_state(self.world)
        self.keeper.save(WorldState(simulator, result, self.trace, *marks))
        self.saved_at = result.epoch

    def note(self, entry: Entry) -> None:
        if self.keeper is not None:
            self.keeper.note(entry)

    def epoch_wall(self) -> float:
        """Wall seconds per epoch (0: flat out)."""
        speed = self.settings.speed
        return self.world.info().epoch_duration / speed if speed > 0 else 0.0

    async def wait_for_agents(self) -> None:
        """The start barrier: epoch 0 waits until every member said it is ready."""
        if self.settings.wait_agents <= 0 or not self.members:
            return
        missing = await self.acks.wait(-1, "ready", self.settings.wait_agents)
        if missing:
            self.ctx.log.warning("members_missing", missing=",".join(missing))
        else:
            self.ctx.log.info("members_ready", members=",".join(self.members))

    async def pace(self, start: float) -> None:
        """Wait until the next epoch may start: every ack (lockstep), then its due time."""
        s = self.settings
        if s.lockstep:
            await self.wait_acks(self.world.epoch)
        if s.speed > 0:
            await self.clock.sleep_until(start + (self.world.epoch + 1) * self.epoch_wall())
        else:
            await asyncio.sleep(0)  # flat out, but let requests in between epochs

    async def wait_acks(self, epoch: int) -> None:
        late = await self.acks.wait(epoch, "done", self.settings.ack_timeout)
        if late:
            self.ctx.log.warning("ack_timeout", epoch=epoch, late=",".join(late))

    def sent_so_far(self) -> dict[str, int]:
        """Return what the world and (by their latest acks) the members published so far,
        per key; heartbeats aside."""
        own = {k: n for k, n in self.ctx.bus.sent.items() if not keys.is_heartbeat(k)}
        return {**self.acks.published(), **own}

    def tick_of(self, result: EpochResult) -> Tick:
        return Tick(
            epoch=result.epoch,
            time=result.time,
            epoch_duration=self.world.info().epoch_duration,
            speed=self.settings.speed,
            lockstep=self.settings.lockstep,
        )

    async def publish_epoch(self, result: EpochResult) -> None:
        bus, w = self.ctx.bus, self.world
        if self.settings.lockstep:
            # What went before this epoch (every member acknowledged the last one): if
            # this epoch ends the run, what its tick sets off is not the run's.
            self.sent_before = self.sent_so_far()
        tick = self.last_tick = self.tick_of(result)
        await publish(bus, keys.world_stream("clock"), tick, block=True)
        for outcome in result.outcomes:
            await publish(bus, keys.world_outcomes(outcome.agent), outcome, block=True)
        for p in result.percepts:
            # The outcomes they close (not the tick: a gate that held the tick of the
            # epoch as well would run a member's clock ahead of its peers' beliefs).
            outcomes = keys.world_outcomes(p.agent)
            sent = {outcomes: bus.sent[outcomes]} if bus.sent[outcomes] else {}
            await publish(bus, keys.world_percepts(p.agent), replace(p, sent=sent), block=True)
        await publish(bus, keys.world_stream("snapshot"), result.snapshot)
        if result.epoch % max(1, self.settings.stats_every) == 0:
            await publish(bus, keys.world_stream("stats"), w.stats())

    async def check_end(self) -> None:
        w, s = self.world, self.settings
        reason = ""
        if s.stop_when_done and w.done:
            reason = "done"
        elif s.max_time > 0 and w.time >= s.max_time:
            reason = "time_limit"
        if reason:
            if self.settings.lockstep:
                await self.all_performed()
            self.finished = RunFinished(
                reason=reason,
                epoch=w.epoch,
                time=w.time,
                stalls=dict(self.acks.stalls),
                requests=self.trace.count,
                trace_digest=self.trace.digest(),
                lateness=self.lateness.summary(),
                sent=self.sent_before,
            )
            await publish(self.ctx.bus, keys.world_stream("stats"), w.stats(), block=True)
            await publish(self.ctx.bus, keys.world_stream("events"), self.finished, block=True)


def world_main(world: Simulator, clock: Clock | None = None) -> ServiceMain:
    """Return the service body serving `world` (built before the bus is opened); `clock`
    paces it (default: wall time; in lockstep flat out, `--speed 0`, none is read). A
    restart with a state file goes on from it (`Keeper.recover`)."""

    async def body(ctx: ServiceContext) -> None:
        settings: WorldSettings = ctx.settings
        keeper = Keeper(settings.state, ctx.log) if settings.state else None
        recovered = keeper.recover(world) if keeper and settings.resumes() else None
        simulator = recovered[0] if recovered else world
        ctx.log.info(
            "world",
            map=settings.map,
            agents=",".join(simulator.info().agents),
            speed=settings.speed,
            lockstep=settings.lockstep,
            seed=settings.seed,
            simulator=settings.simulator,
            options=",".join(settings.option),
        )
        service = WorldService(ctx, simulator, settings, clock, keeper)
        if recovered:
            service.resume(recovered[1])
        service.start()

    return body
