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
or stands in for it. A performer that waits with `call.sleep` (not `asyncio.sleep`)
takes part in lockstep runs too, its process a lockstep member (`cbdi.robot`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Protocol

from cbdi import keys
from cbdi.bus import Bus, ErrorSink
from cbdi.wire.base import Message
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest, Tick

__all__ = [
    "ActionCall",
    "Outcome",
    "Performer",
    "PerformerHost",
    "Sleeper",
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


class Sleeper(Protocol):
    """How a performer waits: wall seconds, or simulated ones in lockstep (`cbdi.robot`)."""

    def sleep(self, seconds: float) -> Awaitable[None]: ...


@dataclass(frozen=True)
class ActionCall:
    """One grounded PDDL action to carry out: `(action *args)`, planned to last `duration`."""

    agent: str
    action: str
    args: tuple[str, ...]
    duration: float
    request_id: str
    clock: Sleeper | None = field(default=None, compare=False, repr=False)

    async def sleep(self, seconds: float) -> None:
        """Wait `seconds` of the run's time: wall seconds in real time, simulated ones in
        lockstep (the run waits for the performer, however long that takes)."""
        if self.clock is None:
            await asyncio.sleep(seconds)
        else:
            await self.clock.sleep(seconds)


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
    clock: Sleeper | None = None  # what `ActionCall.sleep` waits with (None: wall time)
    # Every call's task until its outcome is out (`running` lets go of it before that).
    tasks: set[asyncio.Task[None]] = field(default_factory=set)

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
        call = ActionCall(
            req.agent, req.action, tuple(req.args), req.duration, req.request_id, self.clock
        )
        task = asyncio.create_task(self._run(call))
        self.running[req.request_id] = task
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)
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
    goes to `sink` (default: logged), never ends it. It is a `cbdi.robot.Robot` with
    this one performer (a process with several performers or sensors makes one Robot of
    them all: in lockstep it is one member)."""
    from cbdi.robot import Robot

    robot = Robot(bus, agent, sink=sink)
    robot.perform(action, performer)
    await robot.run()
