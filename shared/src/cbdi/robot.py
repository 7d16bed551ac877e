"""A robot's own process: its performers and sensors, in real time or in lockstep.

    from cbdi.robot import Robot

    robot = Robot(bus, "robot1")
    robot.perform("carry", Carry(room))      # cbdi.performer
    robot.sense(Things(room), rate=4.0)      # cbdi.sensor
    await robot.run()

In real time each performer is served as `serve_performer` serves it and each sensor
read `rate` times per wall second, as `run_sensor` reads it. In a lockstep run (the
world's info says so) the process is the lockstep member `<agent>/performer`: the world
waits for it at every epoch, and so does the agent's executor, whose steps it performs.
At each tick it lets each call started in the epoch before run until it waits, wakes the
calls whose `call.sleep` ends by the tick's time and lets them run until they wait again
or end (their outcomes go out, stamped with the epoch), reads each sensor that is due
(every 1/`rate` simulated seconds: the agent applies what changed before its percepts of
the next epoch), and acknowledges the epoch's first stage (`beliefs`, what the
executor waits for). Once the executor has acknowledged the epoch (its requests of the
epoch are in, their calls started), it lets those calls run until they wait, and then
acknowledges the epoch as `done`, what the world waits for: whatever a call asks the
world before its first wait (a body's move) is served in the call's epoch. What the robot does
so depends only on the run's inputs, not on the machine's pace, provided its performers
wait only with `call.sleep` and its sensors read only the robot's own state: a call that
awaits anything else is waited for up to `settle` wall seconds and logged
(`performer_busy`), and the run then depends on the pace.

One `Robot` per process and agent: it is one member.
"""

from __future__ import annotations

import asyncio
import heapq
import math
import weakref
from dataclasses import dataclass
from itertools import count

from cbdi import keys
from cbdi.bus import Bus, ErrorSink, LogSink, messages, publish, serve
from cbdi.errors import CbdiError
from cbdi.lockstep import announce_ready, send_ack
from cbdi.performer import (
    Performer,
    PerformerHost,
    outcomes_key,
    performer_key,
    stop_key,
)
from cbdi.runtime.log import Log
from cbdi.sensor import Sensor, SensorLoop, read_and_tell, run_sensor
from cbdi.view import world_info
from cbdi.wire.agent import ExecutorStop
from cbdi.wire.base import Message
from cbdi.wire.world import ActionOutcome, ActionRequest, EpochAck, Tick

__all__ = ["MEMBER", "Robot", "SimSleeper"]

MEMBER = "performer"  # the component name of a robot's process in lockstep
EPS = 1e-9
SETTLE = 5.0  # wall s a performer's call may take to reach its next `call.sleep`
ASK_EVERY = 1.0  # wall s between asks of the world's info until it answers
ACK_WAIT = 30.0  # wall s to wait for the executor's ack of an epoch (a killed one: late)


class SimSleeper:
    """Simulated time for performers: a `sleep` ends at the first tick at or past its
    end (`advance`), whatever the wall clock does. A task's sleeps add up from where its
    last one ended, not from the tick that woke it: a call that sleeps its duration in
    pieces ends when one sleep of it would, and a control loop that sleeps 0.05 s at a
    time runs its steps up to the tick's time at once (a sleep that ends by then returns
    at once), then waits for the next tick."""

    def __init__(self) -> None:
        self.now = 0.0
        self._waits: list[tuple[float, int, asyncio.Future[None], asyncio.Task[object] | None]]
        self._waits = []
        self._seq = count()
        self.parked: set[asyncio.Task[object]] = set()  # tasks waiting in `sleep`
        # Each task's own time: where its last sleep ended (a new task: the tick's time).
        self._at: weakref.WeakKeyDictionary[asyncio.Task[object], float]
        self._at = weakref.WeakKeyDictionary()

    async def sleep(self, seconds: float) -> None:
        if not math.isfinite(seconds):
            raise ValueError(f"a sleep of {seconds} s")
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        task = asyncio.current_task()
        start = self._at.get(task, self.now) if task is not None else self.now
        end = start + max(0.0, seconds)
        if end <= self.now + EPS:  # behind the run's time (a control loop catching up)
            if task is not None:
                self._at[task] = end
            await asyncio.sleep(0)
            return
        heapq.heappush(self._waits, (end, next(self._seq), future, task))
        if task is not None:
            self.parked.add(task)
            self._at[task] = end
        try:
            await future
        finally:
            if task is not None:
                self.parked.discard(task)

    def advance(self, time: float) -> None:
        """The run reached `time`: end every sleep due by then, in the order they end."""
        self.now = max(self.now, time)
        while self._waits and self._waits[0][0] <= self.now + EPS:
            _, _, future, task = heapq.heappop(self._waits)
            if task is not None:
                self.parked.discard(task)  # runnable again
            if not future.done():
                future.set_result(None)


@dataclass
class _Sensing:
    sensor: Sensor
    rate: float
    loop: SensorLoop
    log: Log
    due: float = 0.0  # the simulated time of its next reading (lockstep)


class Robot:
    """An agent's performers and sensors in one process (see the module)."""

    def __init__(
        self,
        bus: Bus,
        agent: str,
        *,
        sink: ErrorSink | None = None,
        timeout: float = 2.0,
        settle: float = SETTLE,
        ack_wait: float = ACK_WAIT,
    ) -> None:
        keys.validate_name(agent)
        self.bus, self.agent = bus, agent
        self.errors = sink or LogSink()
        self.timeout, self.settle, self.ack_wait = timeout, settle, ack_wait
        self.log = Log(keys.member(agent, MEMBER))
        self.hosts: dict[str, PerformerHost] = {}
        self.sensing: list[_Sensing] = []
        self.clock = SimSleeper()
        self.lockstep: bool | None = None  # None: not known yet (the world's info says)
        self.epoch = -1  # the latest epoch acknowledged (lockstep)
        self.dispatched = -1  # the latest epoch the agent's executor acknowledged
        self._executor = asyncio.Condition()

    def perform(self, action: str, performer: Performer) -> None:
        """Serve `performer` as the agent's performer of `action`."""
        keys.validate_name(action, "action")
        name = action.lower()
        if name in self.hosts:
            raise ValueError(f"{self.agent} has a performer of {action!r} already")
        self.hosts[name] = PerformerHost(self.agent, name, performer, self._out)

    def sense(self, sensor: Sensor, rate: float = 1.0, *, sender: str = "sensor") -> None:
        """Read `sensor` `rate` times per second (simulated seconds in lockstep)."""
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"a sensor's rate must be a finite number > 0, not {rate}")
        proto = sensor.prototype
        loop = SensorLoop(self.agent, sensor, sender, "sensors")
        log = Log(f"{self.agent}/sensor/{proto.name}")
        self.sensing.append(_Sensing(sensor, rate, loop, log))

    async def _out(self, outcome: ActionOutcome) -> None:
        await publish(self.bus, outcomes_key(self.agent), outcome, block=True)

    async def run(self) -> None:
        """Serve the performers and read the sensors until cancelled."""
        tasks = [asyncio.create_task(self._serve(h)) for h in self.hosts.values()]
        tasks += [asyncio.create_task(self._ticks()), asyncio.create_task(self._stops())]
        tasks.append(asyncio.create_task(self._executor_acks()))
        tasks.append(asyncio.create_task(self._mode()))
        try:
            await asyncio.gather(*tasks)
        finally:
            for task in tasks:
                task.cancel()
            for host in self.hosts.values():
                host.cancel()

    async def _serve(self, host: PerformerHost) -> None:
        async def answer(_key: str, req: ActionRequest) -> Message:
            return host.on_request(req)

        key = performer_key(self.agent, host.action)
        await serve(self.bus, key, ActionRequest, answer, self.errors)

    async def _mode(self) -> None:
        """Ask the world whether the run is in lockstep with us as a member: then say
        `ready` until epoch 0 (the world's start barrier); else read the sensors in real
        time. A world not up yet is asked again."""
        while self.lockstep is None:
            try:
                info = await world_info(self.bus, ASK_EVERY)
            except (TimeoutError, CbdiError):
                continue
            if self.lockstep is None:  # a real-time tick may have decided first
                self._decide(info.lockstep and keys.member(self.agent, MEMBER) in info.members)
        if self.lockstep:
            await announce_ready(self.bus, self.agent, MEMBER, lambda: self.epoch >= 0)
        else:
            await asyncio.gather(
                *(
                    run_sensor(self.bus, self.agent, s.sensor, s.rate, sender=s.loop.sender)
                    for s in self.sensing
                )
            )

    def _decide(self, lockstep: bool) -> None:
        self.lockstep = lockstep
        if lockstep:
            for host in self.hosts.values():
                host.clock = self.clock
            self.log.info("lockstep_member", member=keys.member(self.agent, MEMBER))

    async def _ticks(self) -> None:
        async for _key, tick in messages(self.bus, keys.world_stream("clock"), Tick, self.errors):
            if self.lockstep is None and not tick.lockstep:
                self._decide(False)
            if self.lockstep and tick.lockstep:
                if tick.epoch > self.epoch:
                    await self._epoch(tick)
            else:
                for host in self.hosts.values():
                    host.on_tick(tick)

    async def _epoch(self, tick: Tick) -> None:
        """Lockstep: the robot's part of epoch `tick.epoch` (see the module)."""
        await self._settled()  # the calls started in the epoch before, to their first wait
        for host in self.hosts.values():
            host.on_tick(tick)
        self.clock.advance(tick.time)
        await self._settled()  # the woken calls, to their next wait or their outcome
        for s in self.sensing:
            if tick.time + EPS >= s.due:
                s.due = max(s.due + 1.0 / s.rate, tick.time)
                s.loop.epoch = tick.epoch
                await read_and_tell(self.bus, s.loop, self.timeout, s.log)
        self.epoch = tick.epoch
        await send_ack(self.bus, self.agent, MEMBER, tick.epoch, "beliefs")
        await self._dispatched(tick.epoch)
        await self._settled()  # the calls the executor started, to their first wait
        await send_ack(self.bus, self.agent, MEMBER, tick.epoch)

    async def _executor_acks(self) -> None:
        key = keys.epoch_ack(self.agent, "executor")
        async for _key, ack in messages(self.bus, key, EpochAck, self.errors):
            async with self._executor:
                self.dispatched = max(self.dispatched, ack.epoch)
                self._executor.notify_all()

    async def _dispatched(self, epoch: int) -> None:
        """Wait until the executor acknowledged `epoch` (its requests of the epoch are
        in), at most `ack_wait` wall seconds: then it is logged, and the epoch goes on."""
        try:
            async with asyncio.timeout(self.ack_wait), self._executor:
                await self._executor.wait_for(lambda: self.dispatched >= epoch)
        except TimeoutError:
            self.log.warning("upstream_late", epoch=epoch, late=keys.member(self.agent, "executor"))

    async def _settled(self) -> None:
        """Let every call run until it waits in `call.sleep` or has ended (at most
        `settle` wall seconds: then it is logged, and the epoch goes on)."""
        loop = asyncio.get_running_loop()
        end = loop.time() + self.settle
        spins = 0
        while True:
            busy = [
                t
                for h in self.hosts.values()
                for t in h.tasks
                if not t.done() and t not in self.clock.parked
            ]
            if not busy:
                return
            if loop.time() > end:
                self.log.warning("performer_busy", calls=len(busy), seconds=self.settle)
                return
            await asyncio.sleep(0 if spins < 100 else 0.001)
            spins += 1

    async def _stops(self) -> None:
        key = stop_key(self.agent)
        async for _key, stop in messages(self.bus, key, ExecutorStop, self.errors):
            if stop.op == "stop":
                for host in self.hosts.values():
                    await host.stop()
