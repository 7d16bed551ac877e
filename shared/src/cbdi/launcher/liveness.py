"""Which services are frozen: the launcher's watchdog over heartbeats, a pure core.

A service's liveliness token says its Zenoh session lives; Zenoh keeps that session up
from its own threads, so a service whose event loop is blocked keeps its token forever,
and a stopped process (SIGSTOP) keeps it until the router's lease runs out (10 s by
default). Its heartbeat comes from a task of its event loop (`cbdi.runtime.service`),
so it stops with the loop. A service is frozen when its current process, once heard,
has been silent so long that, checked every `tick` seconds, it is found within `limit`
seconds of its last heartbeat (so within `limit` of freezing): reported. Still silent at
`kill_after` seconds, it is killed (and restarted by policy). A planner searching in
worker threads keeps its loop free and beating, so it is never taken for frozen.

A service whose loop stands while its process lives says so: the process's stall
watcher (`cbdi.runtime.stall`) sends its heartbeat from its own thread with the evidence
(`Stall`). A process that wanted the CPU most of the time (`wanted` >= `STARVED`) while
its loop's thread ran less than the limit in CPU time is **starved**: a loaded machine
gave it too little, it is slow, not frozen, so it is reported once (`Starved`) and never
killed while that lasts. So is a loop that stands in a send on the bus (`sending`: the
network has no room, a router starved of CPU): killing the sender makes no room, and
its restart sends more (32 robots on 2 cores: the world, killed this way, restarted
until the run failed). A loop whose own thread ran the limit's worth of CPU without a
turn is held by code (frozen, whatever the load); a process neither running nor waiting
for a CPU is asleep (a deadlock, a blocking call): frozen too. A process that sends
nothing at all (stopped, or a thread that keeps the interpreter) is frozen. Evidence counts
only while fresh (heard within the limit): a stopped process's last word does not
shield it.

Two silences are not a service's fault, and judge nobody:
- the watchdog itself was late by more than half the limit (its own loop starved on a
  loaded machine): what it did not hear meanwhile may be waiting in its queue, so every
  clock restarts;
- every watched service fell silent at once: the bus (its router) is the one frozen, so
  only the router is judged.

The shell (`cbdi.launcher.watch`) feeds it heartbeats and checks; it never reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["STARVED", "Frozen", "Stall", "Starved", "Watchdog"]

ROUTER = "router"
STARVED = 0.5  # a process whose threads wanted the CPU this share of a stall is starved


@dataclass(frozen=True)
class Stall:
    """A process's word that its loop has not turned for `stalled_for` s: its thread ran
    `loop_cpu` s meanwhile, its threads wanted the CPU `wanted` of the time (None:
    unknown), and whether the loop stands in a send on the bus (`sending`)."""

    stalled_for: float
    loop_cpu: float
    wanted: float | None
    sending: bool = False

    def starved(self, limit: float) -> bool:
        """True if the process waited for the CPU, its loop not held by code."""
        return self.wanted is not None and self.wanted >= STARVED and self.loop_cpu < limit

    def congested(self, limit: float) -> bool:
        """True if the loop waits in a send for room on the network, not held by code:
        a congested bus (killing the sender would not make room, and its restart would
        send more)."""
        return self.sending and self.loop_cpu < limit


@dataclass(frozen=True)
class Starved:
    """The decision that process `pid` of `service` is starved, not frozen: its loop has
    stood `stalled_for` s while its threads wanted the CPU `wanted` of the time (`cause`
    `cpu`), or while it waited in a send on a congested bus (`bus`)."""

    service: str
    pid: int
    stalled_for: float
    wanted: float
    cause: str = "cpu"


@dataclass(frozen=True)
class Frozen:
    """The decision that process `pid` of `service` is frozen: silent for `silent_for` s.

    `kill`: silent for the kill limit too, so it is killed (and restarted by policy); the
    first decision (at the freeze limit) only reports it: a service starved on a loaded
    machine may beat again, one really frozen is killed a few seconds later.
    """

    service: str
    pid: int
    silent_for: float
    kill: bool = True


class Watchdog:
    """Judge services frozen within `limit` seconds of their process's last heartbeat,
    checked every `tick` seconds."""

    def __init__(
        self, limit: float, tick: float, startup: float = 30.0, kill_after: float | None = None
    ) -> None:
        if not (math.isfinite(limit) and math.isfinite(tick) and 0 < tick < limit):
            raise ValueError(f"need 0 < tick < limit (finite), got tick {tick}, limit {limit}")
        if kill_after is not None and not (math.isfinite(kill_after) and kill_after >= limit):
            raise ValueError(f"need a finite kill limit >= the limit {limit}, got {kill_after}")
        self.limit = limit
        self.kill_after = limit if kill_after is None else kill_after
        self._killed: set[tuple[str, int]] = set()
        self.tick = tick
        self.startup = max(startup, limit)
        self._seen: dict[tuple[str, int], float] = {}  # process -> first check it ran at
        self._heard: dict[str, tuple[int, float]] = {}  # service -> (pid, last beat)
        self._judged: set[tuple[str, int]] = set()
        self._checked: float | None = None
        self._stalls: dict[str, tuple[int, float, Stall]] = {}  # service -> (pid, heard, word)
        self._starved: set[tuple[str, int]] = set()  # reported starved in this silence

    def beat(self, service: str, pid: int, now: float, stall: Stall | None = None) -> None:
        """Note a heartbeat of process `pid` of `service` heard at `now`: from its loop,
        or (`stall`) from its stall watcher while its loop stands."""
        if stall is not None:
            self._stalls[service] = (pid, now, stall)
            return
        self._heard[service] = (pid, now)
        self._stalls.pop(service, None)
        self._starved.discard((service, pid))

    def silent_for(self, service: str, pid: int, now: float) -> float:
        """How long process `pid` of `service` has not been heard beating (0: never heard,
        or another process)."""
        heard = self._heard.get(service)
        return now - heard[1] if heard is not None and heard[0] == pid else 0.0

    def _starving(self, service: str, pid: int, now: float) -> Stall | None:
        """The fresh word of `service`'s process `pid` that it is starved, if any."""
        word = self._stalls.get(service)
        if word is None or word[0] != pid or now - word[1] > self.limit:
            return None
        stall = word[2]
        return stall if stall.starved(self.limit) or stall.congested(self.limit) else None

    def check(self, now: float, running: Mapping[str, int]) -> list[Frozen | Starved]:
        """Return the services of `running` (service -> current pid) newly judged frozen.

        A service is watched once its current process beat; one that never beats is
        judged `startup` seconds after it was first seen running. Each process is judged
        once.
        """
        late = self._checked is not None and now - self._checked > self.limit / 2
        self._checked = now
        if late:
            self._heard = {s: (pid, now) for s, (pid, _) in self._heard.items()}
            self._stalls = {s: (pid, now, w) for s, (pid, _, w) in self._stalls.items()}
            self._seen = {p: now for p in self._seen}
            return []
        for process in running.items():
            self._seen.setdefault(process, now)
        watched = {
            s: now - self._heard[s][1]
            for s, pid in running.items()
            if s in self._heard and self._heard[s][0] == pid
        }
        silent = {s: t for s, t in watched.items() if t > self.limit - self.tick}
        mute = set()
        for s, pid in running.items():  # never heard: frozen while starting (or mute)
            if s not in watched and now - self._seen[(s, pid)] > self.startup:
                silent[s] = now - self._seen[(s, pid)]
                mute.add(s)
        if len(watched) > 1 and len(silent) == len(watched):
            silent = {s: t for s, t in silent.items() if s == ROUTER}
        found: list[Frozen | Starved] = []
        for s, t in sorted(silent.items()):
            process = (s, running[s])
            starving = None if s in mute else self._starving(s, running[s], now)
            if starving is not None:
                if process not in self._starved:
                    self._starved.add(process)
                    wanted = starving.wanted or 0.0
                    cause = "cpu" if starving.starved(self.limit) else "bus"
                    found.append(Starved(s, running[s], round(t, 3), round(wanted, 3), cause))
                continue
            kill = s in mute or t > self.kill_after - self.tick
            if process in self._killed or (process in self._judged and not kill):
                continue
            found.append(Frozen(s, running[s], round(t, 3), kill))
            self._judged.add(process)
            if kill:
                self._killed.add(process)
        return found
