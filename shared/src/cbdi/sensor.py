"""Sensors: code that turns readings into an agent's beliefs (ROS2-BDI's `Sensor`).

A sensor senses one prototype belief, a predicate of the agent's domain with its arity
(`door_open/1`), and says which instances of it hold now; `run_sensor` reads it at its
rate and sends the agent what changed, as belief additions and deletions through the
agent's request endpoint (`rpc/request`, group `sensors`, which the agent file must
list in `allowed_groups`). The scheduler checks each belief against the domain as it
checks an operator's, and the rules fire on the change:

    from cbdi.sensor import Prototype, run_sensor

    class Doors:
        prototype = Prototype("door_open", 1)

        async def read(self) -> list[tuple[str, ...]]:
            return [(d,) for d in await open_doors()]      # ("d1",) -> (door_open d1)

    await run_sensor(bus, "robot1", Doors(), rate=2.0)

A reading of another arity is left out and logged; a change the agent refuses is logged
with the reason and not sent again until the reading changes; a change the agent does
not answer is sent again at the next reading, so nothing sensed is lost while the
scheduler restarts.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from cbdi import keys
from cbdi.bus import Bus, request
from cbdi.errors import CbdiError
from cbdi.runtime.log import Log
from cbdi.wire.agent import AgentReply, AgentRequest

__all__ = ["Prototype", "Sensor", "SensorLoop", "run_sensor"]


@dataclass(frozen=True)
class Prototype:
    """The belief a sensor may add and delete: `predicate` with `arity` arguments."""

    predicate: str
    arity: int

    def __post_init__(self) -> None:
        keys.validate_name(self.predicate, "predicate")
        if not 0 <= self.arity <= 32:
            raise ValueError(f"arity {self.arity} is outside 0..32")

    def literal(self, args: Sequence[str]) -> str:
        return f"({' '.join([self.predicate, *args])})"


class Sensor(Protocol):
    """Reads which instances of its prototype belief hold now."""

    prototype: Prototype

    def read(self) -> Awaitable[Iterable[Sequence[str]]]: ...


@dataclass
class SensorLoop:
    """One sensor's state: what the agent was last told holds, what it refused."""

    agent: str
    sensor: Sensor
    sender: str = "sensor"
    group: str = "sensors"
    told: set[tuple[str, ...]] = field(default_factory=set)
    refused: dict[tuple[tuple[str, ...], bool], str] = field(default_factory=dict)

    def changes(self, reading: Iterable[Sequence[str]]) -> list[tuple[tuple[str, ...], bool]]:
        """What to tell (args, add?) for `reading`; readings of another arity are left out."""
        arity = self.sensor.prototype.arity
        now = {tuple(r) for r in reading if len(r) == arity}
        wanted = [(a, True) for a in sorted(now - self.told)]
        wanted += [(a, False) for a in sorted(self.told - now)]
        self.refused = {k: v for k, v in self.refused.items() if k in set(wanted)}
        return [c for c in wanted if c not in self.refused]

    def request(self, args: tuple[str, ...], add: bool) -> AgentRequest:
        return AgentRequest(
            from_agent=self.sender,
            group=self.group,
            op="add_belief" if add else "del_belief",
            belief=self.sensor.prototype.literal(args),
        )

    def answered(self, args: tuple[str, ...], add: bool, reply: AgentReply) -> None:
        if reply.accepted:
            (self.told.add if add else self.told.discard)(args)
            self.refused.pop((args, add), None)
        else:
            self.refused[(args, add)] = reply.reason


async def run_sensor(
    bus: Bus,
    agent: str,
    sensor: Sensor,
    rate: float = 1.0,
    *,
    sender: str = "sensor",
    group: str = "sensors",
    timeout: float = 2.0,
    log: Log | None = None,
) -> None:
    """Read `sensor` `rate` times per (wall) second and tell `agent` what changed, until
    cancelled. A failing `read` is logged and tried again at the next period."""
    keys.validate_name(agent)
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"a sensor's rate must be a finite number > 0, not {rate}")
    log = log or Log(f"{agent}/sensor/{sensor.prototype.predicate}")
    loop = SensorLoop(agent, sensor, sender, group)
    key = keys.agent_request(agent, group)
    while True:
        try:
            reading = list(await sensor.read())
        except Exception as exc:  # the user's code failed: say so, read again later
            log.warning("read_failed", reason=f"{type(exc).__name__}: {exc}")
            reading = None
        if reading is not None:
            arity = sensor.prototype.arity
            if any(len(r) != arity for r in reading):
                log.warning("wrong_arity", arity=arity)
            for args, add in loop.changes(reading):
                try:
                    reply = await request(
                        bus, key, loop.request(args, add), AgentReply, timeout=timeout
                    )
                except CbdiError as exc:
                    log.warning("no_answer", reason=str(exc))  # sent again next time
                    break
                loop.answered(args, add, reply)
                if not reply.accepted:
                    log.warning(
                        "refused",
                        belief=sensor.prototype.literal(args),
                        add=add,
                        reason=reply.reason,
                    )
        await asyncio.sleep(1.0 / rate)
