"""A recycling robot's body in its own process: the example to copy for a real robot.

The body is a pymunk rigid body driven by velocity control: each control step (20 Hz)
it commands a velocity toward where it is going, limited in speed and acceleration, and
reads its pose back with noise, as odometry would. It performs the domain's `move`
(`(move ?r ?from ?to)`) by driving there, and senses its own place, `(in ?r ?c)`, from
its pose once it stands still. Everything else, the litter, the bin, the people and the
other robots, is the simulator's (the world service): the body asks it to move too, so
that the world keeps the cells it knows taken, and a move the world refuses or fails
(a person stepped in) is driven back.

Your robot's code replaces `Body` (its drive and its localisation); `Move` and `Place`
stay as they are. It waits with `call.sleep`, so it runs in real time and in lockstep.

Run: python body.py ROBOT [ROUTER_ENDPOINT] [--seed N]
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import math
import random
import signal

import pymunk
from cbdi_recycling.wire import Percepts

from cbdi import keys
from cbdi.bus import Bus, LogSink, messages, request
from cbdi.performer import ActionCall, Outcome
from cbdi.robot import Robot
from cbdi.security.login import open_as
from cbdi.sensor import Prototype
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest

DT = 0.05  # s: one control step
MAX_SPEED = 1.5  # m/s
MAX_ACCEL = 3.0  # m/s^2
ARRIVED = 0.05  # m: close enough to a cell's centre
POSE_NOISE = 0.01  # m: the standard deviation of the pose's noise
GIVE_UP = 10.0  # s: a drive that has not arrived by then failed


def centre(cell: str) -> tuple[float, float]:
    """The centre of a grid cell `c_X_Y` (cells are 1 m squares)."""
    _, x, y = cell.split("_")
    return float(x), float(y)


def cell_at(x: float, y: float) -> str:
    return f"c_{round(x)}_{round(y)}"


class Body:
    """A wheeled base under velocity control, with a noisy pose."""

    def __init__(self, seed: int) -> None:
        self.space = pymunk.Space()
        self.body = pymunk.Body(mass=20.0, moment=math.inf)
        self.space.add(self.body, pymunk.Circle(self.body, 0.3))
        self.noise = random.Random(seed)
        self.placed = asyncio.Event()  # set once the body knows where it starts

    def place(self, cell: str) -> None:
        self.body.position = centre(cell)
        self.placed.set()

    def pose(self) -> tuple[float, float]:
        """Where the robot believes it is: its position, with noise."""
        x, y = self.body.position
        return x + self.noise.gauss(0, POSE_NOISE), y + self.noise.gauss(0, POSE_NOISE)

    def still(self) -> bool:
        return abs(self.body.velocity) < 1e-3

    def step(self, goal: tuple[float, float]) -> float:
        """One control step toward `goal`; return the distance left (by the pose)."""
        x, y = self.pose()
        dx, dy = goal[0] - x, goal[1] - y
        dist = math.hypot(dx, dy)
        # The fastest speed that can still stop at the goal, within the speed limit.
        speed = min(MAX_SPEED, math.sqrt(2 * MAX_ACCEL * dist)) if dist > ARRIVED else 0.0
        want = pymunk.Vec2d(dx, dy).normalized() * speed if dist > 1e-9 else pymunk.Vec2d(0, 0)
        change = want - self.body.velocity
        limit = MAX_ACCEL * DT
        if abs(change) > limit:
            change = change.normalized() * limit
        self.body.velocity = self.body.velocity + change
        self.space.step(DT)
        return dist

    async def drive(self, goal: tuple[float, float], call: ActionCall) -> bool:
        """Drive to `goal`, one control step per `DT` of the run's time."""
        for _ in range(int(GIVE_UP / DT)):
            if self.step(goal) <= ARRIVED and abs(self.body.velocity) < 0.05:
                self.body.velocity = (0.0, 0.0)
                return True
            await call.sleep(DT)
        self.body.velocity = (0.0, 0.0)
        return False


class Move:
    """Performs (move ?r ?from ?to): drives the body, and asks the world to move too."""

    def __init__(self, bus: Bus, body: Body) -> None:
        self.bus, self.body, self.ids = bus, body, itertools.count(1)

    async def perform(self, call: ActionCall) -> Outcome:
        robot, here, there = call.args
        rid = f"{robot}-body-{next(self.ids)}"
        ends = messages(self.bus, keys.world_outcomes(robot), ActionOutcome, LogSink())
        x, y = (int(v) for v in there.split("_")[1:])
        req = ActionRequest(agent=robot, action="move", request_id=rid, target=(x, y))
        reply = await request(self.bus, keys.world_act(robot), req, ActionReply)
        if not reply.accepted:
            return Outcome.failure(reply.reason)
        await self.body.placed.wait()
        arrived = await self.body.drive(centre(there), call)
        async for _key, out in ends:  # the world's move ends when its duration is up
            if out.request_id == rid:
                if out.status != "succeeded":
                    await self.body.drive(centre(here), call)  # back where the world has us
                    return Outcome.failure(out.reason)
                break
        return Outcome.success() if arrived else Outcome.failure("did not arrive")


class Place:
    """Senses (in ?r ?c): the cell the body stands still in, by its pose."""

    prototype = Prototype("in", 2)

    def __init__(self, robot: str, body: Body) -> None:
        self.robot, self.body, self.last = robot, body, ""

    async def read(self) -> list[tuple[str, ...]]:
        if not self.body.placed.is_set():
            return []
        if self.body.still():  # while driving, the place it left holds until it arrives
            self.last = cell_at(*self.body.pose())
        return [(self.robot, self.last)] if self.last else []


async def main(robot: str, router: str, seed: int) -> None:
    bus = await open_as(keys.member(robot, "performer"), [router], timeout=120.0)
    loop, me = asyncio.get_running_loop(), asyncio.current_task()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, me.cancel)  # type: ignore[union-attr]
    body = Body(seed)
    me_robot = Robot(bus, robot)
    me_robot.perform("move", Move(bus, body))
    me_robot.sense(Place(robot, body), rate=4.0)
    try:
        async with asyncio.TaskGroup() as tasks:
            tasks.create_task(me_robot.run())
            tasks.create_task(place(bus, robot, body))
    except asyncio.CancelledError:
        pass
    finally:
        await bus.close()


async def place(bus: Bus, robot: str, body: Body) -> None:
    """Where the body starts: the cell the world's first percepts put the robot in (a
    real robot knows it from its map and localisation)."""
    async for _key, sensed in messages(bus, keys.world_percepts(robot), Percepts, LogSink()):
        x, y = sensed.position
        body.place(f"c_{x}_{y}")
        print(f"{robot}: the body starts at c_{x}_{y}", flush=True)
        return


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot")
    parser.add_argument("router", nargs="?", default="tcp/127.0.0.1:7447")
    parser.add_argument("--seed", type=int, default=0)
    a = parser.parse_args()
    asyncio.run(main(a.robot, a.router, a.seed))
