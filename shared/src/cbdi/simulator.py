"""A domain's simulator, hosted by the world service (`cbdi-world --simulator NAME`).

The host gives a simulator what every simulated run needs: the epoch clock and its pace,
lockstep with the agents, the start barrier, the request trace, the end of the run, and
publication of what it produces (ticks, outcomes, percepts, snapshots, statistics), so
recording, replay, `cbdi inspect` and the views work for it unchanged. The simulator
itself is pure and deterministic: the same map, agents and seed give the same run.

A domain's package registers its simulator class under the entry-point group
`cbdi.simulators`; a scenario names it (`[run] simulator = "courier"`):

    class CourierSimulator:
        actions = ("drive", "grab", "drop", "charge")   # the PDDL actions it performs

        def __init__(self, config: SimulatorConfig) -> None: ...
        def info(self) -> WorldInfo: ...          # static: map, agents, initial beliefs
        def request(self, req: ActionRequest) -> ActionReply: ...  # start one now
        def initial(self) -> EpochResult: ...     # epoch 0
        def step(self) -> EpochResult: ...        # advance one epoch
        def stats(self, agent: str = "") -> WorldStats: ...

`request` gets grounded PDDL actions (`req.action`, `req.args`) for agents of `info()`
only (the host answers `unknown_agent` for any other); it rejects what it cannot do with
an `ActionReply(accepted=False, reason=...)`, and raises for nothing a client sends.
Percepts are `Sensed` belief changes (read by the generic knowledge, `cbdi.literals`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Protocol, cast

from cbdi.plugins import load_plugin
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    Percepts,
    Sensed,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)

__all__ = [
    "SIMULATORS",
    "EpochResult",
    "Simulator",
    "SimulatorClass",
    "SimulatorConfig",
    "load_simulator",
]

SIMULATORS = "cbdi.simulators"


@dataclass(frozen=True)
class SimulatorConfig:
    """What a simulator is made from: its map file, the agents to place, the seed."""

    map: str
    agents: tuple[str, ...]
    seed: int = 0


@dataclass(frozen=True)
class EpochResult:
    """What one epoch produced, for the host to publish."""

    epoch: int
    time: float
    outcomes: Sequence[ActionOutcome]
    percepts: Sequence[Percepts | Sensed]
    snapshot: WorldSnapshot
    spawned: Sequence[str] = field(default_factory=list)


class Simulator(Protocol):
    """A world the host steps epoch by epoch."""

    @property
    def epoch(self) -> int: ...

    @property
    def time(self) -> float: ...

    @property
    def done(self) -> bool:
        """True when the run's goals are all met (the run ends, `done`)."""
        ...

    def info(self) -> WorldInfo: ...

    def request(self, req: ActionRequest) -> ActionReply: ...

    def initial(self) -> EpochResult: ...

    def step(self) -> EpochResult: ...

    def stats(self, agent: str = "") -> WorldStats: ...


class SimulatorClass(Protocol):
    """What `cbdi.simulators` entry points name: a class with its actions."""

    actions: ClassVar[tuple[str, ...]]

    def __call__(self, config: SimulatorConfig) -> Simulator: ...


def load_simulator(name: str, source: str = "world") -> SimulatorClass:
    """Return the simulator class `name` (entry-point group `cbdi.simulators`);
    ConfigError naming what is installed if there is none."""
    found = load_plugin(SIMULATORS, name, source, "simulator", "simulator")
    if not callable(found) or not isinstance(getattr(found, "actions", None), tuple):
        from cbdi.errors import ConfigError

        raise ConfigError(source, "simulator", f"{name!r} is not a simulator class with actions")
    return cast(SimulatorClass, cast(Callable[..., object], found))
