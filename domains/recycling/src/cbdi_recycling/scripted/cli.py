"""`cbdi-scripted-agent`: a scripted robot on the real bus (demo and end-to-end tests).

It takes the executor's place of its agent (`cbdi/<agent>/executor`): it receives its
percepts and action outcomes from the world, requests one action at a time, and
acknowledges every epoch (which the world waits for in lockstep mode).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import count

from cbdi import keys
from cbdi.bus import publish, request
from cbdi.errors import CbdiError, ConfigError, WireError
from cbdi.lockstep import announce_ready
from cbdi.runtime import ServiceContext, ServiceSettings, load_config, run_service
from cbdi.runtime.service import ServiceMain
from cbdi.view import world_info
from cbdi.wire.base import decode_any
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    EpochAck,
    WorldInfo,
)
from cbdi_recycling.scripted.policy import Beliefs, Step, greedy_step, parse_script
from cbdi_recycling.wire import Percepts, grid_map

__all__ = ["ScriptedSettings", "main"]


@dataclass(frozen=True)
class ScriptedSettings(ServiceSettings):
    """Settings of `cbdi-scripted-agent`."""

    agent: str = field(default="robot1", metadata={"help": "agent name (as given to the world)"})
    script: str = field(
        default="", metadata={"help": "steps 'move:X,Y pickup recycle ...'; empty: greedy"}
    )
    retries: int = field(default=20, metadata={"help": "script mode: tries per step"})


class ScriptedAgent:
    """Turn percepts into action requests, one action at a time."""

    def __init__(
        self,
        ctx: ServiceContext,
        name: str,
        beliefs: Beliefs,
        script: list[Step] | None,
        retries: int,
    ) -> None:
        self.ctx, self.name, self.beliefs = ctx, name, beliefs
        self.script, self.retries, self.tries = script, retries, 0
        self.busy = False
        self.started = False  # epoch 0 seen: the start barrier is passed
        self.ids = count(1)

    async def run(self, samples: object) -> None:
        async for sample in samples:  # type: ignore[attr-defined]
            try:
                msg = decode_any(sample.payload, (Percepts, ActionOutcome), sample.key)
            except WireError as exc:
                self.ctx.bad_input(sample.key, exc)
                continue
            if isinstance(msg, ActionOutcome):
                self.on_outcome(msg)
            elif isinstance(msg, Percepts):
                await self.on_percepts(msg)

    def on_outcome(self, outcome: ActionOutcome) -> None:
        self.busy = False
        self.ctx.log.info(
            "outcome",
            action=outcome.action,
            status=outcome.status,
            reason=outcome.reason,
            epoch=outcome.epoch,
        )
        if self.script is not None and outcome.status == "succeeded" and self.script:
            self.script.pop(0)
            self.tries = 0

    async def on_percepts(self, p: Percepts) -> None:
        self.started = True
        self.beliefs.revise(p)
        if not self.busy:
            step = self.choose()
            if step is not None:
                await self.act(step)
        await publish(
            self.ctx.bus,
            keys.agent_ack(self.name),
            EpochAck(agent=self.name, epoch=p.epoch),
            block=True,
        )

    def choose(self) -> Step | None:
        if self.script is None:
            return greedy_step(self.beliefs)
        if not self.script:
            return None
        self.tries += 1
        if self.tries > self.retries:
            self.ctx.log.error("script_failed", step=str(self.script[0]), tries=self.retries)
            self.ctx.stop(1)
            return None
        return self.script[0]

    async def act(self, step: Step) -> None:
        req = ActionRequest(
            agent=self.name,
            action=step.action,
            target=step.target,
            item=step.item,
            request_id=f"{self.name}-{next(self.ids)}",
        )
        try:
            reply = await request(self.ctx.bus, keys.world_act(self.name), req, ActionReply)
        except CbdiError as exc:
            self.ctx.log.warning("request_failed", action=step.action, error=str(exc))
            return
        self.busy = reply.accepted
        self.ctx.log.info(
            "requested",
            action=step.action,
            target=step.target,
            item=step.item,
            accepted=reply.accepted,
            reason=reply.reason,
        )


def beliefs_of(info: WorldInfo) -> Beliefs:
    """What the agent knows at the start: the world's static part and the known litter."""
    grid = grid_map(info)
    return Beliefs(
        width=grid.width,
        height=grid.height,
        walls=frozenset(grid.walls),
        bins=frozenset(b.cell for b in grid.bins),
        capacity=grid.capacity,
        litter={item.name: item.cell for item in info.known_items},
    )


def scripted_main(settings: ScriptedSettings, script: list[Step] | None) -> ServiceMain:
    """Return the service body of one scripted agent: it asks the world for its map."""

    async def body(ctx: ServiceContext) -> None:
        samples = ctx.bus.subscribe(keys.world_for_agent(settings.agent))
        beliefs = beliefs_of(await world_info(ctx.bus, timeout=30.0))
        agent = ScriptedAgent(ctx, settings.agent, beliefs, script, settings.retries)
        ctx.start(agent.run(samples), name="agent")
        ready = announce_ready(ctx.bus, settings.agent, "executor", lambda: agent.started)
        ctx.start(ready, name="ready")

    return body


def main(argv: Sequence[str] | None = None) -> int:
    """Run one scripted agent until stopped."""
    try:
        settings = load_config(
            ScriptedSettings,
            argv,
            prog="cbdi-scripted-agent",
            section="scripted",
            description=__doc__ or "",
        )
        keys.validate_name(settings.agent)
        script = parse_script(settings.script) if settings.script else None
    except (ConfigError, ValueError) as exc:
        print(f"cbdi-scripted-agent: {exc}", file=sys.stderr)
        return 2
    service = keys.service_id("executor", settings.agent)
    return run_service(settings, service, scripted_main(settings, script))


if __name__ == "__main__":
    sys.exit(main())
