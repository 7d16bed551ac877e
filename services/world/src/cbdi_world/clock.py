"""The clock world: a simulator with no domain, for robots that act through performers.

A user with a real robot runs performers and sensors, and no simulated world; the
executor and the performers still take their time from a world's clock. `clock` gives
them exactly that (`[run] simulator = "clock"`, no map): epochs of `epoch_duration`
simulated seconds, each agent's (empty) percepts every epoch, snapshots and statistics
for the recording and `cbdi inspect`. It performs no action: a request is refused, so
every action of a domain run on it needs a performer (which `cbdi up` checks at start).
It is never done; a run on it ends at its time (`until = SECONDS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from cbdi.simulator import EpochResult, SimulatorConfig
from cbdi.wire.world import (
    ActionReply,
    ActionRequest,
    AgentStats,
    AgentView,
    Sensed,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)

__all__ = ["ClockOptions", "ClockSimulator"]


@dataclass(frozen=True)
class ClockOptions:
    """The clock's one setting."""

    epoch_duration: float = field(
        default=1.0, metadata={"help": "simulated seconds per epoch (0 < D <= 3600)"}
    )

    def problems(self) -> list[tuple[str, str]]:
        """Return `(option, reason)` for a value out of range."""
        d = self.epoch_duration
        if not (math.isfinite(d) and 0 < d <= 3600):
            return [("epoch_duration", f"expected seconds in (0, 3600], got {d!r}")]
        return []


class ClockSimulator:
    """Epochs and nothing else: no map, no action, never done."""

    actions: tuple[str, ...] = ()
    needs_map = False
    Options = ClockOptions

    def __init__(self, config: SimulatorConfig) -> None:
        self.options = ClockOptions(**config.options)  # type: ignore[arg-type]
        problems = self.options.problems()
        if problems:
            raise ValueError("; ".join(f"{name}: {reason}" for name, reason in problems))
        self.agents = tuple(config.agents)
        self.epoch = 0
        self.time = 0.0

    @property
    def done(self) -> bool:
        """Never: a run on the clock ends at its time."""
        return False

    def info(self) -> WorldInfo:
        """No map: the agents and the epoch's length."""
        return WorldInfo(
            map_name="clock",
            agents=list(self.agents),
            epoch_duration=self.options.epoch_duration,
            durations={},
        )

    def request(self, req: ActionRequest) -> ActionReply:
        """Refuse: the clock performs nothing (a performer does)."""
        reason = f"the clock world performs no action ({req.action!r} needs a performer)"
        return ActionReply(request_id=req.request_id, accepted=False, reason=reason)

    def initial(self) -> EpochResult:
        """Epoch 0."""
        return self._result()

    def step(self) -> EpochResult:
        """The next epoch."""
        self.epoch += 1
        self.time = self.epoch * self.options.epoch_duration
        return self._result()

    def _result(self) -> EpochResult:
        percepts = [Sensed(agent=a, epoch=self.epoch, time=self.time) for a in self.agents]
        agents = [AgentView(name=a, cell=(0, 0), pose=(0.5, 0.5)) for a in self.agents]
        snapshot = WorldSnapshot(
            epoch=self.epoch, time=self.time, agents=agents, people=[], items=[], completed=[]
        )
        return EpochResult(self.epoch, self.time, [], percepts, snapshot)

    def stats(self, agent: str = "") -> WorldStats:
        """Nothing counted but the epoch."""
        names = [agent] if agent else list(self.agents)
        return WorldStats(
            epoch=self.epoch, time=self.time, agents=[AgentStats(agent=n) for n in names]
        )
