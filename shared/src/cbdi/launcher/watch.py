"""The launcher's liveness watchdog: heartbeats in, frozen services reported and killed.

The decisions are `cbdi.launcher.liveness.Watchdog`'s; this shell feeds it what it
hears on `cbdi/heartbeat/**` with the wall clock, and acts on each `Frozen`: a log line
(`frozen service=... pid=... silent_for=... action=report|kill`) and a `ServiceFrozen`
message on `cbdi/launcher/health` (which the monitor records); at the kill limit also
SIGKILL, after which the service's supervisor restarts it by its restart policy, as after
a crash. On each `Starved`: a log line (`starved service=... pid=... stalled_for=...
wanted=... cause=cpu|bus action=none`), a `ServiceStarved` message there too, and a
count in the run's summary (`starved`); nothing is killed.
"""

from __future__ import annotations

import os
import time
from collections.abc import AsyncIterator, Sequence

from cbdi import keys
from cbdi.bus import LogSink, messages, publish
from cbdi.bus.base import Bus
from cbdi.clock import Clock, WallClock
from cbdi.errors import WireError
from cbdi.launcher.liveness import Frozen, Stall, Starved, Watchdog
from cbdi.launcher.process import ManagedProcess
from cbdi.wire.base import decode
from cbdi.wire.common import Heartbeat, ServiceFrozen, ServiceStarved

__all__ = ["TICK", "watch_heartbeats", "watch_processes"]

TICK = 0.1  # seconds between checks: a freeze is found within the limit of the last beat
LOOP_WANTED = 0.05  # the share of a silence a starved loop's thread ran or waited to run


async def watch_heartbeats(bus: Bus, dog: Watchdog, clock: Clock | None = None) -> None:
    """Note every heartbeat heard on the bus, at the time it is heard."""
    clock = clock or WallClock()
    beats: AsyncIterator[tuple[str, Heartbeat]] = messages(
        bus, keys.HEARTBEAT_ALL, Heartbeat, LogSink()
    )
    async for _, beat in beats:
        stall = None
        if beat.stalled_for > 0:
            stall = Stall(beat.stalled_for, beat.loop_cpu, beat.wanted, beat.sending)
        dog.beat(beat.service, beat.pid, clock.now(), stall)


async def watch_processes(
    bus: Bus,
    dog: Watchdog,
    procs: Sequence[ManagedProcess],
    clock: Clock | None = None,
) -> None:
    """Check the running processes every tick; report and kill each one judged frozen."""
    clock = clock or WallClock()
    by_service = {member: p for p in procs for member in p.spec.members}
    seen: dict[str, float] = {}  # stall file -> the modification time read
    since: dict[int, tuple[float, tuple[int, int, int]]] = {}  # pid -> when, its clocks
    while True:
        await clock.sleep(dog.tick)
        running = {m: p.pid for p in procs if p.pid and p.running for m in p.spec.members}
        for p in procs:
            if p.stall_file and p.pid and p.running:
                _read_stall(dog, p, p.pid, clock.now(), seen)
            if p.pid and p.running:
                _look_at(dog, p, p.pid, clock.now(), since)
        for frozen in dog.check(clock.now(), running):
            await _act(bus, dog, by_service[frozen.service], frozen)


def _read_stall(
    dog: Watchdog, proc: ManagedProcess, pid: int, now: float, seen: dict[str, float]
) -> None:
    """Note the stall evidence `proc` left in its file since the last look, if fresh and
    its current process's: the heartbeat that carried it may have been dropped by a
    congested network (`cbdi.runtime.service`)."""
    path = proc.stall_file
    try:
        mtime = os.stat(path).st_mtime
        if seen.get(path) == mtime or time.time() - mtime > dog.limit:
            return
        seen[path] = mtime
        with open(path, "rb") as f:
            beat = decode(f.read(), Heartbeat)
    except (OSError, WireError):  # none yet, or being replaced
        return
    if beat.pid != pid or beat.stalled_for <= 0:
        return
    stall = Stall(beat.stalled_for, beat.loop_cpu, beat.wanted, beat.sending)
    for member in proc.spec.members:
        dog.beat(member, pid, now, stall)


def _look_at(
    dog: Watchdog,
    proc: ManagedProcess,
    pid: int,
    now: float,
    since: dict[int, tuple[float, tuple[int, int, int]]],
) -> None:
    """Look from outside at a process silent for half the limit: what its loop's (main)
    thread ran and what all its threads ran or waited for a CPU since then, from Linux's
    schedstat. A starved process's own word (its stall watcher) comes late or not at
    all, since it gets no CPU to say it; this needs none of it. It only ever tells
    starved: anything else is left to the process's word and the heartbeats. The loop's
    thread must have wanted the CPU too (`LOOP_WANTED` of the time): one asleep (a
    deadlock) beside a thread that spins is frozen, not starved."""
    silent = max(dog.silent_for(m, pid, now) for m in proc.spec.members)
    if silent < dog.limit / 2:
        since.pop(pid, None)
        return
    clocks = _clocks(pid)
    if clocks is None:
        return
    if pid not in since:
        since[pid] = (now, clocks)
        return
    then, (ran0, loop0, all0) = since[pid]
    span = now - then
    if span < dog.tick:
        return
    stall = Stall(silent, (clocks[0] - ran0) / 1e9, (clocks[2] - all0) / 1e9 / span)
    if stall.starved(dog.limit) and (clocks[1] - loop0) / 1e9 / span >= LOOP_WANTED:
        for member in proc.spec.members:
            dog.beat(member, pid, now, stall)


def _clocks(pid: int) -> tuple[int, int, int] | None:
    """A process's main thread's CPU, its CPU plus run-queue wait, and all its threads'
    CPU plus run-queue wait, in ns (Linux schedstat); None if it is gone, stopped
    (SIGSTOP: frozen, not starved) or the system does not say."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rsplit(b")", 1)[1].split()[0]
        if state in (b"T", b"t", b"Z"):
            return None
        main, loop, total = 0, 0, 0
        for tid in os.listdir(f"/proc/{pid}/task"):
            try:
                with open(f"/proc/{pid}/task/{tid}/schedstat", "rb") as f:
                    ran, waited, _ = f.read().split()
            except (OSError, ValueError):
                continue  # ended meanwhile
            total += int(ran) + int(waited)
            if tid == str(pid):
                main, loop = int(ran), int(ran) + int(waited)
        return main, loop, total
    except (OSError, ValueError, IndexError):
        return None


async def _act(bus: Bus, dog: Watchdog, proc: ManagedProcess, frozen: Frozen | Starved) -> None:
    if isinstance(frozen, Starved):
        await _starved(bus, proc, frozen)
        return
    if frozen.kill:
        if not proc.kill_frozen(frozen.pid):
            return
    elif not proc.running or proc.pid != frozen.pid:
        return
    else:
        proc.frozen(frozen.pid)
    action = "kill" if frozen.kill else "report"
    limit = dog.kill_after if frozen.kill else dog.limit
    proc.sink(
        "launcher",
        f"frozen service={frozen.service} pid={frozen.pid} silent_for={frozen.silent_for:.2f}"
        f" limit={limit:g} action={action}",
    )
    report = ServiceFrozen(
        service=frozen.service, pid=frozen.pid, silent_for=frozen.silent_for, limit=limit
    )
    await publish(bus, keys.launcher_stream("health"), report, block=True)


async def _starved(bus: Bus, proc: ManagedProcess, starved: Starved) -> None:
    if not proc.running or proc.pid != starved.pid:
        return
    proc.starved += 1
    proc.sink(
        "launcher",
        f"starved service={starved.service} pid={starved.pid}"
        f" stalled_for={starved.stalled_for:.2f} wanted={starved.wanted:.2f}"
        f" cause={starved.cause} action=none",
    )
    report = ServiceStarved(
        service=starved.service,
        pid=starved.pid,
        stalled_for=starved.stalled_for,
        wanted=min(starved.wanted, 4096.0),
        cause="bus" if starved.cause == "bus" else "cpu",
    )
    await publish(bus, keys.launcher_stream("health"), report, block=True)
