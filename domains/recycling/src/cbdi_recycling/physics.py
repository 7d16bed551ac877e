"""Bodies of robots and people in pymunk, gliding between cell centres.

The logical grid decides where everything is; physics only moves each body toward the
centre of its logical cell over an epoch, with a fixed time step, and detects when a robot
comes close to a person (sensor shapes of radius `RADIUS`: a contact means two bodies came
within 2 * RADIUS of each other). Same inputs, same poses, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable

import pymunk

from cbdi.wire.world import Cell

__all__ = ["RADIUS", "Physics"]

RADIUS = 0.4
_ROBOT, _PERSON = 1, 2


def centre(cell: Cell) -> tuple[float, float]:
    """Return the centre of a cell in world coordinates (cell (x, y) spans [x, x+1))."""
    return (cell[0] + 0.5, cell[1] + 0.5)


class Physics:
    """A pymunk space with one body per robot and person."""

    def __init__(self, substeps: int, on_contact: Callable[[str, str], None]) -> None:
        self.substeps = max(1, substeps)
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self.bodies: dict[str, pymunk.Body] = {}
        self._names: dict[pymunk.Shape, str] = {}
        self._on_contact = on_contact
        self.space.on_collision(_ROBOT, _PERSON, begin=self._begin)

    def add(self, name: str, cell: Cell, robot: bool) -> None:
        """Add a body for `name` at the centre of `cell`."""
        body = pymunk.Body(1.0, float("inf"))
        body.position = centre(cell)
        shape = pymunk.Circle(body, RADIUS)
        shape.sensor = True
        shape.collision_type = _ROBOT if robot else _PERSON
        self.space.add(body, shape)
        self.bodies[name] = body
        self._names[shape] = name

    def _begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        a, b = arbiter.shapes
        robot, person = (a, b) if a.collision_type == _ROBOT else (b, a)
        self._on_contact(self._names[robot], self._names[person])

    def glide(self, targets: dict[str, Cell], duration: float) -> None:
        """Move every body to its target cell's centre over `duration` seconds."""
        dt = duration / self.substeps
        goals = {name: centre(cell) for name, cell in targets.items()}
        for k in range(self.substeps):
            left = duration - k * dt
            for name, body in self.bodies.items():
                gx, gy = goals[name]
                px, py = body.position
                body.velocity = ((gx - px) / left, (gy - py) / left) if left > 0 else (0, 0)
            self.space.step(dt)
        for name, body in self.bodies.items():  # remove float drift: centres are exact
            body.position = goals[name]
            body.velocity = (0.0, 0.0)

    def pose(self, name: str) -> tuple[float, float]:
        x, y = self.bodies[name].position
        return (round(x, 4), round(y, 4))
