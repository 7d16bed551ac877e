"""The compiled core's search loops: one call runs a whole loop (issue 29).

`hill_climbing.enforced_hill_climbing` and `best_first.best_first` hand their loop to the compiled
core (`cbdi_planner_core.Search`) when the expander runs it: the nodes stay there, and
Python sees the loop's result only. The loops expand the same nodes in the same order
as the Python reference and count the same (`tests/planner/test_compiled_core.py`).

A loop runs without the interpreter lock. A clock that only counts expansions is counted
in the compiled core; any other (a pace, seconds, a worker's credits) is called before
each expansion, as the Python loop calls it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

from cbdi_planner.expansion import Expander, Node

__all__ = ["Clock", "best_first", "hill_climb", "runs"]


class Clock(Protocol):
    """What a loop needs of `search._Clock`."""

    def tick(self) -> None: ...

    def allowance(self) -> tuple[bool, int | None]: ...

    def counted(self, expansions: int, ran_out: bool) -> None: ...


def runs(ex: Expander, root: Node) -> bool:
    """Tell whether the compiled core runs the loops of `ex` from `root`."""
    return (
        ex.native is not None
        and root.handle is not None
        and root.timeline.oracle is ex.oracle  # made with this expander's snap codes
    )


def hill_climb(ex: Expander, root: Node, clock: Clock) -> Node | None:
    """`hill_climbing.enforced_hill_climbing`, in one call."""
    return _run(ex, clock, lambda tick, left: ex.native.hill_climb(root.handle, tick, left))


def best_first(
    ex: Expander, root: Node, clock: Clock, bound: float = math.inf, limit: int | None = None
) -> Node | None:
    """`best_first.best_first`, in one call."""
    return _run(
        ex,
        clock,
        lambda tick, left: ex.native.best_first(root.handle, bound, limit, tick, left),
    )


def _run(
    ex: Expander, clock: Clock, loop: Callable[[Callable[[], None] | None, int | None], Any]
) -> Node | None:
    native, left = clock.allowance()
    try:
        handle, counted, ran_out = loop(None if native else clock.tick, left)
    finally:
        ex.sync()
    clock.counted(counted, ran_out)
    return None if handle is None else ex.node_of(handle)
