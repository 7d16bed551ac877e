"""Bind the recycling domain's PDDL actions to what the grid world simulates.

An executor sends a grounded PDDL action (`ActionRequest` with `args`); the world turns
it into its own action with `RecyclingBinding.primitive`:

- `move ?r ?from ?to`: move to the cell `?to` (named `c_X_Y`);
- `litter_pickup ?r ?l ?c`: pick up item `?l`;
- `recycle ?r ?l ?bin ?c ?binc`: put held item `?l` into the bin.

Anything else is not an action this world performs: the request is rejected with the
reason, and `cbdi up` refuses a domain with such an action before it starts anything.
"""

from __future__ import annotations

import re
from typing import Protocol

from cbdi.errors import CbdiError
from cbdi.plugins import load_plugin
from cbdi.wire.world import ActionRequest, Cell

__all__ = [
    "ACTIONS",
    "BINDINGS",
    "ActionBinding",
    "RecyclingBinding",
    "UnboundActionError",
    "cell_of",
    "load_binding",
]

_CELL = re.compile(r"^c_(\d+)_(\d+)$")

# PDDL action -> (the world's action, how many arguments it needs)
_PRIMITIVES = {"move": ("move", 3), "litter_pickup": ("pickup", 2), "recycle": ("recycle", 2)}
ACTIONS: tuple[str, ...] = tuple(_PRIMITIVES)

# The entry-point group of bindings (another domain's PDDL actions on this grid); the
# grid's option `binding` names one.
BINDINGS = "cbdi.bindings"


class UnboundActionError(CbdiError):
    """A PDDL action the world does not perform, or arguments it cannot read."""

    code = "unbound_action"


def cell_of(name: str) -> Cell:
    """Return the cell of a PDDL cell object `c_X_Y`."""
    m = _CELL.match(name)
    if m is None:
        raise UnboundActionError(f"{name!r} is not a cell name (c_X_Y)")
    return (int(m.group(1)), int(m.group(2)))


class RecyclingBinding:
    """The recycling domain's actions, as the grid world performs them."""

    actions: tuple[str, ...] = ACTIONS

    def primitive(self, req: ActionRequest) -> ActionRequest:
        """Return the world's own request for the PDDL action `req` (its `args` set)."""
        name = req.action.lower()
        found = _PRIMITIVES.get(name)
        call = f"({' '.join([req.action, *req.args])})"
        if found is None:
            known = ", ".join(ACTIONS)
            raise UnboundActionError(f"the world performs no action {req.action!r} ({known})")
        action, needed = found
        if len(req.args) < needed:
            raise UnboundActionError(f"{call}: too few arguments ({needed} needed)")
        if action == "move":
            return ActionRequest(
                agent=req.agent,
                action="move",
                request_id=req.request_id,
                target=cell_of(req.args[2]),
            )
        return ActionRequest(
            agent=req.agent, action=action, request_id=req.request_id, item=req.args[1]
        )


class ActionBinding(Protocol):
    """How the grid world performs a domain's PDDL actions."""

    actions: tuple[str, ...]  # the PDDL actions it performs

    def primitive(self, req: ActionRequest) -> ActionRequest:
        """The world's own request for the grounded PDDL action `req`; raise CbdiError
        (the reason the world rejects it) for an action or arguments it cannot perform."""
        ...


def load_binding(name: str, source: str = "world") -> ActionBinding:
    """Return a new binding `name` (entry-point group `cbdi.bindings`)."""
    factory = load_plugin(BINDINGS, name, source, "binding", "action binding")
    binding: ActionBinding = factory()  # type: ignore[operator]
    return binding
