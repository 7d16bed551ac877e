"""Action performers: the code that carries out one PDDL action on a robot.

The executor dispatches each plan step at its time, after checking its conditions. A
step whose action an agent file lists under `performers` goes to the performer serving
that action for the agent, not to the world:

    from cbdi.performer import ActionCall, Outcome, serve_performer

    class Charge:
        async def perform(self, call: ActionCall) -> Outcome:
            await dock(call.args[1])          # talk to the robot; raise nothing
            return Outcome.success()          # or Outcome.failure("dock busy")

    await serve_performer(bus, "robot1", "charge", Charge())

`serve_performer` answers the executor's request at once (accepted, ending after the
plan's duration), runs `perform` as a task, and publishes how it ended on the agent's
performer outcome stream; a `perform` that raises fails the step with the exception as
the reason, and the performer goes on serving. Time comes from the world's clock (the
outcome is stamped with the latest tick), so a performer sits beside a simulated world
or stands in for it; performers act in real time (not in a lockstep run).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Protocol

from cbdi import keys
from cbdi.bus import Bus, ErrorSink, LogSink, messages, publish, serve
from cbdi.wire.agent import ExecutorStop
from cbdi.wire.base import Message
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest, Tick

__all__ = [
    "ActionCall",
    "Outcome",
    "Performer",
    "PerformerHost",
    "outcomes_key",
    "performer_key",
    "serve_performer",
    "stop_key",
]


def performer_key(agent: str, action: str) -> str:
    """The request endpoint of the performer of `action` for `agent`."""
    return keys.component_rpc(agent, "performer", action.lower())


def stop_key(agent: str) -> str:
    """The stream on which `agent`'s executor tells its performers of a safe stop."""
    return keys.agent_stream(agent, "executor", "stop")


def outcomes_key(agent: str) -> str:
    """The stream on which `agent`'s performers say how their actions ended."""
    return keys.agent_stream(agent, "performer", "outcomes")


@dataclass(frozen=True)
class ActionCall:
    """One grounded PDDL action to carry out: `(action *args)`, planned to last `duration`."""

    agent: str
    action: str
    args: tuple[str, ...]
    duration: float
    request_id: str


@dataclass(frozen=True)
class Outcome:
    """How an action ended: succeeded, or failed with the reason."""

    succeeded: bool
    reason: str = ""

    @staticmethod
    def success() -> Outcome:
        return Outcome(True)

    @staticmethod
    def failure(reason: str) -> Outcome:
        return Outcome(False, reason or "failed")


class Performer(Protocol):
    """Carries out an action; returns how it ended (or raises: it failed)."""

    def perform(self, call: ActionCall) -> Awaitable[Outcome]: ...


@dataclass
class PerformerHost:
    """The bus side of one performer: requests in, outcomes out, the clock followed."""

    agent: str
    action: str
    performer: Performer
    publish_outcome: Callable[[ActionOutcome], Awaitable[None]]
    epoch: int = 0
    time: float = 0.0
    running: dict[str, asyncio.Task[None]] = field(default_factory=dict)

    def on_tick(self, tick: Tick) -> None:
        if tick.epoch >= self.epoch:
            self.epoch, self.time = tick.epoch, tick.time

    def on_request(self, req: ActionRequest) -> Message:
        """Accept a call for this agent and action (and start it); refuse anything else."""
        if req.agent != self.agent or req.action.lower() != self.action:
            why = f"this performer does {self.action!r} for {self.agent!r}"
            return ErrorReply(code="bad_request", message=f"{why}, not {req.action!r}")
        if req.request_id in self.running:
            return ActionReply(request_id=req.request_id, accepted=False, reason="already running")
        call = ActionCall(req.agent, req.action, tuple(req.args), req.duration, req.request_id)
        self.running[req.request_id] = asyncio.create_task(self._run(call))
        ends = self.time + req.duration
        return ActionReply(
            request_id=req.request_id, accepted=True, starts_at=self.time, ends_at=ends
        )

    async def _run(self, call: ActionCall) -> None:
        try:
            outcome = await self.performer.perform(call)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # the user's code failed: the step fails, we go on
            outcome = Outcome.failure(f"{type(exc).__name__}: {exc}")
        finally:
            self.running.pop(call.request_id, None)
        await self.publish_outcome(
            ActionOutcome(
                agent=call.agent,
                request_id=call.request_id,
                action=call.action,
                status="succeeded" if outcome.succeeded else "failed",
                reason="" if outcome.succeeded else outcome.reason,
                epoch=self.epoch,
                time=self.time,
            )
        )

    def cancel(self) -> None:
        for task in self.running.values():
            task.cancel()

    async def stop(self) -> None:
        """A safe stop: end what runs now, each as failed "stopped" (what was started
        may be half done: the scheduler plans again from what it then believes)."""
        for request_id, task in list(self.running.items()):
            task.cancel()
            self.running.pop(request_id, None)
            await self.publish_outcome(
                ActionOutcome(
                    agent=self.agent,
                    request_id=request_id,
                    action=self.action,
                    status="failed",
                    reason="stopped by a safe stop",
                    epoch=self.epoch,
                    time=self.time,
                )
            )


async def serve_performer(
    bus: Bus, agent: str, action: str, performer: Performer, sink: ErrorSink | None = None
) -> None:
    """Serve `performer` as `agent`'s performer of `action` until cancelled; bad input
    goes to `sink` (default: logged), never ends it."""
    keys.validate_name(agent)
    keys.validate_name(action, "action")
    errors = sink or LogSink()

    async def out(outcome: ActionOutcome) -> None:
        await publish(bus, outcomes_key(agent), outcome, block=True)

    host = PerformerHost(agent, action.lower(), performer, out)

    async def clock() -> None:
        async for _key, tick in messages(bus, keys.world_stream("clock"), Tick, errors):
            host.on_tick(tick)

    async def stops() -> None:
        async for _key, stop in messages(bus, stop_key(agent), ExecutorStop, errors):
            if stop.op == "stop":
                await host.stop()

    async def answer(_key: str, req: ActionRequest) -> Message:
        return host.on_request(req)

    followers = [asyncio.create_task(clock()), asyncio.create_task(stops())]
    try:
        await serve(bus, performer_key(agent, action), ActionRequest, answer, errors)
    finally:
        for task in followers:
            task.cancel()
        host.cancel()
