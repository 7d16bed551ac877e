"""The rules of the recycling actions: when a request is accepted, how an action ends.

They follow the recycling domain: `move` to a 4-adjacent cell (it fails if, when it
completes, the cell holds a wall, a bin, a person or another agent); `litter_pickup` of an
item in the agent's cell while it holds fewer than `capacity` items (the item leaves the
cell at start, is held at end); `recycle` of a held item from a cell next to a bin (it
leaves the hand at start, is recycled at end). An action the world fails at random
(`fail`) ends as if it never happened: the robot stays, the item is back where it was.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from cbdi.wire.world import ActionRequest, Cell, OutcomeStatus

if TYPE_CHECKING:
    from cbdi_recycling.world import AgentState, World

__all__ = ["Action", "check_request", "complete", "fail"]

_DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1))


@dataclass(frozen=True)
class Action:
    """An accepted action in progress."""

    name: str
    request_id: str
    starts_at: float
    ends_at: float
    source: Cell
    target: Cell | None = None
    item: str | None = None


def _adjacent(a: Cell, b: Cell) -> bool:
    return abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1


def check_request(world: World, agent: AgentState, req: ActionRequest) -> tuple[str, Action | None]:
    """Return ("", action) if `req` can start now, else (reason, None)."""
    duration = world.map.durations.get(req.action)
    if duration is None:
        return f"unknown action {req.action!r} (move, pickup, recycle)", None
    check = {"move": _check_move, "pickup": _check_pickup, "recycle": _check_recycle}[req.action]
    reason, target, item = check(world, agent, req)
    if reason:
        return reason, None
    if agent.action is not None:  # one action at a time
        return f"busy with {agent.action.name} until t={agent.action.ends_at:g}", None
    return "", Action(
        name=req.action,
        request_id=req.request_id,
        starts_at=world.time,
        ends_at=world.time + duration,
        source=agent.cell,
        target=target,
        item=item,
    )


def _check_move(
    world: World, agent: AgentState, req: ActionRequest
) -> tuple[str, Cell | None, None]:
    if req.target is None:
        return "move needs a target cell", None, None
    target = (int(req.target[0]), int(req.target[1]))
    if not world.map.inside(target):
        return f"target {list(target)} is outside the map", None, None
    if not _adjacent(agent.cell, target):
        return f"target {list(target)} is not next to {list(agent.cell)}", None, None
    return "", target, None


def _check_pickup(
    world: World, agent: AgentState, req: ActionRequest
) -> tuple[str, None, str | None]:
    if len(agent.holding) >= world.map.capacity:
        return f"already holding {world.map.capacity} items (capacity)", None, None
    here = sorted(n for n, c in world.litter.items() if c == agent.cell)
    if req.item is not None:
        if req.item not in here:
            return f"no litter {req.item!r} in cell {list(agent.cell)}", None, None
        return "", None, req.item
    if not here:
        return f"no litter in cell {list(agent.cell)}", None, None
    return "", None, here[0]


def _check_recycle(
    world: World, agent: AgentState, req: ActionRequest
) -> tuple[str, None, str | None]:
    if not agent.holding:
        return "holding nothing to recycle", None, None
    item = req.item if req.item is not None else agent.holding[0]
    if item not in agent.holding:
        return f"not holding {item!r}", None, None
    if not any(_adjacent(agent.cell, b) for b in world.map.bins.values()):
        return f"no bin next to {list(agent.cell)}", None, None
    return "", None, item


def complete(world: World, agent: AgentState, action: Action) -> tuple[OutcomeStatus, str]:
    """Apply the end of `action`; return (status, reason)."""
    if action.name == "move":
        return _complete_move(world, agent, action)
    if action.name == "pickup":
        agent.holding.append(action.item or "")
        agent.count("pickups")
        return "succeeded", ""
    world.in_hand.discard(action.item or "")
    world.recycled.append(action.item or "")
    agent.count("recycled")
    return "succeeded", ""


def fail(world: World, agent: AgentState, action: Action, reason: str) -> tuple[OutcomeStatus, str]:
    """End `action` as failed, undoing what it did at start; return (status, reason).

    A move leaves the robot in its cell; a pickup leaves the item on the ground of the cell
    it was taken from; a recycle leaves the item in the hand.
    """
    item = action.item or ""
    if action.name == "pickup":
        world.in_hand.discard(item)
        world.litter[item] = action.source
    elif action.name == "recycle":
        agent.holding.append(item)  # still counted in `world.in_hand`, as while recycling
    agent.count("failed")
    return "failed", reason


def _complete_move(world: World, agent: AgentState, action: Action) -> tuple[OutcomeStatus, str]:
    target = action.target
    assert target is not None
    reason = ""
    if target in world.map.walls:
        reason = "wall"
    elif target in world.map.bins.values():
        reason = "bin"
    elif target in world.occupant:
        who = world.occupant[target]
        kind = "agent" if who in world.agents else "person"
        reason = f"blocked by {kind} {who}"
        agent.count("blocked")
    if reason:
        agent.count("failed")
        return "failed", reason
    del world.occupant[agent.cell]
    agent.cell = target
    world.occupant[target] = agent.spec.name
    agent.count("moves")
    return "succeeded", ""
