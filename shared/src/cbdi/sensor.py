"""Sensors: code that turns readings into an agent's beliefs (ROS2-BDI's `Sensor`).

A sensor senses one prototype belief of the agent's domain, a name with its arity, of
one of three kinds, and `run_sensor` reads it at its rate and tells the agent through
its request endpoint (`rpc/request`, group `sensors`, which the agent file must list in
`allowed_groups`). The scheduler checks each belief against the domain as it checks an
operator's, and the rules fire on the change.

- `Prototype("door_open", 1)`: a predicate. `read` says which instances hold now,
  `[("d1",)]`; the agent is told what changed, as belief additions and deletions.
- `Prototype("battery", 1, kind="function", threshold=0.5)`: a function (a numeric
  fluent). `read` gives values, `{("robot1",): 42.5}` -> `(= (battery robot1) 42.5)`.
  A value within `threshold` of the one last told is not sent, and the scheduler takes
  none within `threshold` of the value it believes: noise changes no belief and
  retries no search. An instance no longer read keeps its last value.
- `Prototype("bumped", 1, kind="event")`: one-off events. `read` gives the events since
  the last read, `[("robot1",)]`; each is told once (op `event`): the rules of the
  agent's next cycle see `(bumped robot1)` as a belief, and then it is gone. It is never
  a standing belief, and the planner never sees it.

    from cbdi.sensor import Prototype, run_sensor

    class Doors:
        prototype = Prototype("door_open", 1)

        async def read(self) -> list[tuple[str, ...]]:
            return [(d,) for d in await open_doors()]      # ("d1",) -> (door_open d1)

    await run_sensor(bus, "robot1", Doors(), rate=2.0)

A reading that does not fit the prototype (another arity, an argument that is no name,
a value that is not a finite number) is left out and logged with what and why; a change
the agent refuses is logged with the reason and not sent again until the reading
changes; a change or event the agent does not answer is sent again at the next reading,
so nothing sensed is lost while the scheduler restarts.
"""

from __future__ import annotations

import asyncio
import math
import re
from collections.abc import Awaitable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from cbdi import keys
from cbdi.bus import Bus, request
from cbdi.errors import CbdiError
from cbdi.runtime.log import Log
from cbdi.wire.agent import AgentReply, AgentRequest, RequestOp

__all__ = [
    "KINDS",
    "Change",
    "Prototype",
    "Sensor",
    "SensorLoop",
    "read_and_tell",
    "run_sensor",
]

Kind = Literal["predicate", "function", "event"]
KINDS: tuple[str, ...] = ("predicate", "function", "event")
MAX_PENDING = 1000  # events kept for an agent that does not answer; older ones are lost
_ARG = re.compile(r"[^\s()]{1,256}")  # an object name: what the scheduler reads as one


@dataclass(frozen=True)
class Prototype:
    """The beliefs a sensor reports: `name` with `arity` arguments, of `kind` predicate
    (instances that hold), function (values, a change beyond `threshold`) or event."""

    name: str
    arity: int
    kind: Kind = "predicate"
    threshold: float = 0.0

    def __post_init__(self) -> None:
        keys.validate_name(self.name, self.kind)
        if not 0 <= self.arity <= 31:
            raise ValueError(f"{self.name}: arity {self.arity} is outside 0..31")
        if self.kind not in KINDS:
            raise ValueError(f"{self.name}: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if not (math.isfinite(self.threshold) and self.threshold >= 0):
            raise ValueError(f"{self.name}: threshold {self.threshold} is not a number >= 0")
        if self.threshold and self.kind != "function":
            raise ValueError(f"{self.name}: only a function's readings have a threshold")

    def atom(self, args: Sequence[str]) -> str:
        return f"({' '.join([self.name, *args])})"

    def literal(self, args: Sequence[str], value: float = 0.0) -> str:
        """The belief as agent files write it: `(name a)`, or `(= (name a) value)`."""
        atom = self.atom(args)
        return f"(= {atom} {value!r})" if self.kind == "function" else atom

    def problem(self, args: Any, value: Any = 0.0) -> str:
        """Say why `args` (and `value`) are no reading of this prototype ("" if they are)."""
        if isinstance(args, str) or not isinstance(args, Sequence):
            return f"expected a sequence of {self.arity} names, got {args!r}"
        if len(args) != self.arity:
            return f"expected {self.arity} argument(s), got {len(args)}: {tuple(args)!r}"
        bad = [a for a in args if not (isinstance(a, str) and _ARG.fullmatch(a))]
        if bad:
            return f"argument {bad[0]!r} is not a name (no spaces or parentheses)"
        if self.kind == "function" and not _finite(value):
            return f"value {value!r} of {self.atom(args)} is not a finite number"
        return ""


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


class Sensor(Protocol):
    """Reads its prototype: instances that hold (a predicate), values by instance (a
    function: a mapping from args to numbers) or the events since the last read."""

    prototype: Prototype

    def read(self) -> Awaitable[Iterable[Sequence[str]] | Mapping[Sequence[str], float]]: ...


@dataclass(frozen=True)
class Change:
    """One thing to tell the agent: `op` (add_belief, del_belief or event) on `args`."""

    args: tuple[str, ...]
    op: RequestOp
    value: float = 0.0


@dataclass
class SensorLoop:
    """One sensor's state: what the agent was told (and took), what it refused, which
    events it has not answered yet. Pure: `run_sensor` does the talking."""

    agent: str
    sensor: Sensor
    sender: str = "sensor"
    group: str = "sensors"
    told: set[tuple[str, ...]] = field(default_factory=set)  # predicates held
    values: dict[tuple[str, ...], float] = field(default_factory=dict)  # functions told
    refused: dict[tuple[tuple[str, ...], str], float] = field(default_factory=dict)
    pending: list[Change] = field(default_factory=list)  # events not answered yet
    rejected: list[str] = field(default_factory=list)  # the last reading's misfits, why
    # In lockstep, the epoch of the reading (`cbdi.robot`): the agent applies what it
    # changes before its percepts of the next epoch. -1: at once (real time).
    epoch: int = -1

    def changes(self, reading: Any) -> list[Change]:
        """What to tell for `reading`; items that do not fit the prototype are left
        out, and said in `rejected`."""
        proto = self.sensor.prototype
        self.rejected = []
        if proto.kind == "function":
            items = self._fitting(reading.items() if isinstance(reading, Mapping) else reading)
            return self._values({a: float(v) for a, v in items})
        items = self._fitting((r, 0.0) for r in reading)
        if proto.kind == "event":
            self.pending += [Change(a, "event") for a, _ in items]
            del self.pending[:-MAX_PENDING]
            return list(self.pending)
        return self._predicates({a for a, _ in items})

    def _fitting(self, items: Iterable[Any]) -> list[tuple[tuple[str, ...], Any]]:
        out = []
        for item in items:
            args, value = item if isinstance(item, tuple) and len(item) == 2 else (item, None)
            why = self.sensor.prototype.problem(args, value)
            if why:
                self.rejected.append(why)
            else:
                out.append((tuple(args), value))
        return out

    def _predicates(self, now: set[tuple[str, ...]]) -> list[Change]:
        wanted = [Change(a, "add_belief") for a in sorted(now - self.told)]
        wanted += [Change(a, "del_belief") for a in sorted(self.told - now)]
        keys_ = {(c.args, c.op) for c in wanted}
        self.refused = {k: v for k, v in self.refused.items() if k in keys_}
        return [c for c in wanted if (c.args, c.op) not in self.refused]

    def _values(self, now: dict[tuple[str, ...], float]) -> list[Change]:
        limit = self.sensor.prototype.threshold
        out = []
        for args, value in sorted(now.items()):
            told = self.values.get(args)
            if told is not None and abs(value - told) <= limit:
                continue
            refused = self.refused.get((args, "add_belief"))
            if refused is not None and abs(value - refused) <= limit:
                continue
            self.refused.pop((args, "add_belief"), None)
            out.append(Change(args, "add_belief", value))
        return out

    def request(self, change: Change) -> AgentRequest:
        proto = self.sensor.prototype
        return AgentRequest(
            from_agent=self.sender,
            group=self.group,
            op=change.op,
            belief=proto.literal(change.args, change.value),
            threshold=proto.threshold,
            epoch=self.epoch,
        )

    def answered(self, change: Change, reply: AgentReply) -> None:
        if change.op == "event":
            self.pending.remove(change)  # told once, taken or refused
        elif not reply.accepted:
            self.refused[(change.args, change.op)] = change.value
        elif change.op == "add_belief" and self.sensor.prototype.kind == "function":
            self.values[change.args] = change.value
        else:
            (self.told.add if change.op == "add_belief" else self.told.discard)(change.args)
            self.refused.pop((change.args, change.op), None)


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
    proto = sensor.prototype
    log = log or Log(f"{agent}/sensor/{proto.name}")
    loop = SensorLoop(agent, sensor, sender, group)
    while True:
        await read_and_tell(bus, loop, timeout, log)
        await asyncio.sleep(1.0 / rate)


async def read_and_tell(bus: Bus, loop: SensorLoop, timeout: float, log: Log) -> None:
    """Read `loop`'s sensor once and tell the agent what changed; a failing `read` is
    logged (the next reading tries again)."""
    try:
        reading = await loop.sensor.read()
    except Exception as exc:  # the user's code failed: say so, read again later
        log.warning("read_failed", reason=f"{type(exc).__name__}: {exc}")
    else:
        await _tell(bus, loop, reading, timeout, log)


async def _tell(bus: Bus, loop: SensorLoop, reading: Any, timeout: float, log: Log) -> None:
    """Tell the agent what `reading` changed; log what did not fit and what it refused."""
    proto = loop.sensor.prototype
    try:
        changes = loop.changes(reading)
    except TypeError as exc:  # not an iterable at all: the user's read returned nonsense
        loop.rejected = [f"a reading must be iterable: {exc}"]
        changes = []
    if loop.rejected:  # the first says why, the count how many
        why, count = loop.rejected[0], len(loop.rejected)
        log.warning("bad_reading", sensor=proto.name, kind=proto.kind, count=count, reason=why)
    key = keys.agent_request(loop.agent, loop.group)
    for change in changes:
        req = loop.request(change)
        try:
            reply = await request(bus, key, req, AgentReply, timeout=timeout)
        except CbdiError as exc:
            log.warning("no_answer", reason=str(exc))  # sent again next time
            return
        loop.answered(change, reply)
        if not reply.accepted:
            log.warning("refused", belief=req.belief, op=change.op, reason=reply.reason)
