"""Bind PDDL actions of the recycling domain to the world's action requests.

`move ?a ?from ?to` moves to the cell `?to` (named `c_X_Y`); `litter_pickup ?a ?l ?c`
picks up item `?l`; `recycle_plastic ?a ?l ?bin ?c ?binc` recycles item `?l`. Anything
else is not an action this world can do.
"""

from __future__ import annotations

import re

from cbdi.errors import CbdiError
from cbdi.wire.agent import PlanStep
from cbdi.wire.world import ActionRequest, Cell

__all__ = ["UnboundActionError", "cell_of", "to_request"]

_CELL = re.compile(r"^c_(\d+)_(\d+)$")


class UnboundActionError(CbdiError):
    """A plan step the world cannot execute (unknown action or malformed arguments)."""

    code = "unbound_action"


def cell_of(name: str) -> Cell:
    """Return the cell of a PDDL cell object `c_X_Y`."""
    m = _CELL.match(name)
    if m is None:
        raise UnboundActionError(f"{name!r} is not a cell name (c_X_Y)")
    return (int(m.group(1)), int(m.group(2)))


def to_request(agent: str, step: PlanStep, request_id: str) -> ActionRequest:
    """Return the world request that executes `step`."""
    a, args = step.action.lower(), step.args
    try:
        if a == "move":
            return ActionRequest(
                agent=agent, action="move", request_id=request_id, target=cell_of(args[2])
            )
        if a in ("litter_pickup", "pickup"):
            return ActionRequest(agent=agent, action="pickup", request_id=request_id, item=args[1])
        if a.startswith("recycle"):
            return ActionRequest(agent=agent, action="recycle", request_id=request_id, item=args[1])
    except IndexError:
        raise UnboundActionError(f"({step.action} {' '.join(args)}): too few arguments") from None
    raise UnboundActionError(f"the world has no action for {step.action!r}")
