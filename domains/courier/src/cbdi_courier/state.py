"""The courier simulator's moving parts: a robot, the action it runs, a cart."""

from __future__ import annotations

from dataclasses import dataclass, field

from cbdi_courier.floor import Cell

__all__ = ["CartState", "RobotState", "RunningAction"]


@dataclass
class RunningAction:
    name: str
    args: tuple[str, ...]
    request_id: str
    starts_at: float
    ends_at: float
    target: Cell | None = None  # drive: the cell taken; open_door: the door
    broken: str = ""  # why it fails at its end ("" it succeeds)


@dataclass
class RobotState:
    name: str
    cell: Cell
    battery: float
    carrying: str = ""
    charged: bool = True
    action: RunningAction | None = None
    busy: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)

    def count(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1


@dataclass
class CartState:
    name: str
    route: tuple[Cell, ...]
    step: int
    index: int = 0
    direction: int = 1

    @property
    def cell(self) -> Cell:
        return self.route[self.index]

    def next_index(self) -> int:
        if len(self.route) == 1:
            return 0
        if not 0 <= self.index + self.direction < len(self.route):
            self.direction = -self.direction
        return self.index + self.direction
