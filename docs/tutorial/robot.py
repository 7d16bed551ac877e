"""The tidying robot's own code: a performer for `carry` and a sensor for `on`.

`Room` stands in for your robot's API; the rest is what you write for a real one.
Run: python robot.py [ROUTER_ENDPOINT]
"""

from __future__ import annotations

import asyncio
import signal
import sys

from cbdi.performer import ActionCall, Outcome
from cbdi.robot import Robot
from cbdi.security.login import open_as
from cbdi.sensor import Prototype


class Room:
    """Where each thing lies (your robot's API would look, grasp and move)."""

    def __init__(self) -> None:
        self.where = {"cup": "table"}


class Carry:
    """Performs (carry ?robot ?thing ?from ?to)."""

    def __init__(self, room: Room) -> None:
        self.room = room

    async def perform(self, call: ActionCall) -> Outcome:
        _robot, thing, here, there = call.args
        if self.room.where.get(thing) != here:
            return Outcome.failure(f"no {thing} on the {here}")
        del self.room.where[thing]  # picked up
        print(f"carrying the {thing} from the {here} to the {there}", flush=True)
        await call.sleep(call.duration)  # on its way (here: as long as planned)
        self.room.where[thing] = there
        print(f"put the {thing} on the {there}", flush=True)
        return Outcome.success()


class Things:
    """Senses (on ?thing ?place): what lies where, as the robot sees it."""

    prototype = Prototype("on", 2)

    def __init__(self, room: Room) -> None:
        self.room = room

    async def read(self) -> list[tuple[str, ...]]:
        return list(self.room.where.items())


async def main(router: str) -> None:
    room = Room()
    bus = await open_as("robot1/performer", [router], timeout=60.0)  # docs/security.md
    # Ctrl-C (or SIGTERM) ends main, whichever thread the signal lands on (Zenoh's own
    # threads take signals too: only the loop's handler is sure to wake the loop).
    loop, me = asyncio.get_running_loop(), asyncio.current_task()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, me.cancel)  # type: ignore[union-attr]
    robot = Robot(bus, "robot1")  # in a lockstep run, a member the run waits for
    robot.perform("carry", Carry(room))
    robot.sense(Things(room), rate=4.0)
    try:
        await robot.run()
    except asyncio.CancelledError:
        pass  # stopped: the bus is closed, then exit
    finally:
        await bus.close()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "tcp/127.0.0.1:7447"))
