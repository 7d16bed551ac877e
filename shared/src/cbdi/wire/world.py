"""Wire types of the shared world: clock, actions, percepts, snapshots, statistics.

Cells are `(x, y)` with x the column and y the row, as in the paper's `c_X_Y` names.
Times are simulated seconds (the domain's time units); an epoch lasts `epoch_duration`.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from cbdi.wire.base import Message

__all__ = [
    "ActionOutcome",
    "ActionReply",
    "ActionRequest",
    "AgentStats",
    "AgentView",
    "BinView",
    "Cell",
    "EpochAck",
    "LitterView",
    "Percepts",
    "PersonView",
    "StatsRequest",
    "Tick",
    "WorldInfo",
    "WorldInfoRequest",
    "WorldSnapshot",
    "WorldStats",
]

Cell = tuple[int, int]
Pose = tuple[float, float]

# Action names the world accepts; durations come from the recycling domain.
ACTIONS = ("move", "pickup", "recycle")


class Tick(Message, frozen=True, tag="cbdi.world.Tick/1"):
    """Publish the world's clock once per epoch: the simulated clock follows this."""

    epoch: int
    time: float
    epoch_duration: float
    speed: float
    lockstep: bool


class ActionRequest(Message, frozen=True, tag="cbdi.world.ActionRequest/1"):
    """Ask the world to start an action for `agent`.

    `move` needs `target` (a 4-adjacent cell); `pickup` takes the litter in the agent's cell
    (`item` optional, to pick a specific one); `recycle` puts held litter (`item`, or the
    first held) into a bin next to the agent.
    """

    agent: str
    action: str
    request_id: str
    target: Cell | None = None
    item: str | None = None


class ActionReply(Message, frozen=True, tag="cbdi.world.ActionReply/1"):
    """Answer an `ActionRequest` at once: accepted (with when it ends) or rejected and why."""

    request_id: str
    accepted: bool
    reason: str = ""
    starts_at: float = 0.0
    ends_at: float = 0.0


class ActionOutcome(Message, frozen=True, tag="cbdi.world.ActionOutcome/1"):
    """Report how an accepted action ended: `succeeded` or `failed` with a reason."""

    agent: str
    request_id: str
    action: str
    status: str
    reason: str
    epoch: int
    time: float
    target: Cell | None = None
    item: str | None = None


class LitterView(Message, frozen=True, tag="cbdi.world.LitterView/1"):
    """One litter item lying on a cell; `known` says whether agents knew it from the start."""

    name: str
    cell: Cell
    known: bool = True


class Percepts(Message, frozen=True, tag="cbdi.world.Percepts/1"):
    """What one agent senses this epoch in the (2d+1)x(2d+1) square around it.

    `free` cells are inside the map and hold no wall, bin, person or agent; `blocked` are
    the other in-map cells of the square (the agent's own cell is reported as blocked by
    itself only in `position`). `litter` lists the items lying in the square.
    """

    agent: str
    epoch: int
    time: float
    position: Cell
    depth: int
    free: list[Cell]
    blocked: list[Cell]
    litter: list[LitterView]
    holding: list[str]


class AgentView(Message, frozen=True, tag="cbdi.world.AgentView/1"):
    """One robot in a snapshot: logical cell, continuous pose, load and current action."""

    name: str
    cell: Cell
    pose: Pose
    holding: list[str]
    action: str = ""


class PersonView(Message, frozen=True, tag="cbdi.world.PersonView/1"):
    """One person in a snapshot."""

    name: str
    cell: Cell
    pose: Pose


class BinView(Message, frozen=True, tag="cbdi.world.BinView/1"):
    """One bin."""

    name: str
    cell: Cell


class WorldSnapshot(Message, frozen=True, tag="cbdi.world.WorldSnapshot/1"):
    """Everything that moves, published every epoch for viewers and recorders."""

    epoch: int
    time: float
    agents: list[AgentView]
    people: list[PersonView]
    litter: list[LitterView]
    recycled: list[str]


class WorldInfoRequest(Message, frozen=True, tag="cbdi.world.WorldInfoRequest/1"):
    """Ask for the static part of the world (map geometry)."""


class WorldInfo(Message, frozen=True, tag="cbdi.world.WorldInfo/1"):
    """The static part of the world: size, walls, bins, agents and their sensing depth."""

    map_name: str
    width: int
    height: int
    walls: list[Cell]
    bins: list[BinView]
    agents: list[str]
    detection_depth: dict[str, int]
    capacity: int
    epoch_duration: float
    durations: dict[str, float]
    known_litter: list[LitterView] = []  # litter agents know of at the start
    # The members (`agent/component`) the start barrier, and in lockstep every epoch,
    # waits for.
    members: list[str] = []
    lockstep: bool = False


Name = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
ACK_STAGES = ("ready", "beliefs", "done")


class EpochAck(Message, frozen=True, tag="cbdi.world.EpochAck/1"):
    """Acknowledge an epoch (lockstep): `component` of `agent` has handled epoch `epoch`.

    `stage` is `done` (everything of the epoch handled, its messages sent), `beliefs`
    (the scheduler's first half: beliefs and commands out, the planner may start) or
    `ready` (epoch -1: alive, subscribed, waiting for epoch 0; the start barrier).
    `sent` is what the component had published by then, per key (cumulative counts, the
    `seq` of its last message on that key): a receiver holding fewer of a key's messages
    waits for the rest, so nothing of epoch k arrives after the next epoch starts.
    """

    agent: Name
    epoch: Annotated[int, msgspec.Meta(ge=-1)]
    component: Name = "executor"
    stage: Literal["ready", "beliefs", "done"] = "done"
    sent: Annotated[dict[str, Annotated[int, msgspec.Meta(ge=0)]], msgspec.Meta(max_length=64)] = {}


class AgentStats(Message, frozen=True, tag="cbdi.world.AgentStats/1"):
    """Counters for one agent, the paper's metric (moves) first."""

    agent: str
    moves: int = 0
    pickups: int = 0
    recycled: int = 0
    blocked: int = 0
    failed: int = 0
    rejected: int = 0
    contacts: int = 0


class StatsRequest(Message, frozen=True, tag="cbdi.world.StatsRequest/1"):
    """Ask for statistics, of one agent or (agent empty) of all."""

    agent: str = ""


class WorldStats(Message, frozen=True, tag="cbdi.world.WorldStats/1"):
    """Per-agent counters and the litter totals at `epoch`."""

    epoch: int
    time: float
    agents: list[AgentStats]
    litter_on_ground: int
    litter_held: int
    litter_recycled: int
    litter_spawned: int
    done: bool
