"""Which code stalls a service's event loop, named in its log while it happens, and
whether the process was starved of the CPU or stuck, told to the watchdog.

A loop that does not turn sends no heartbeat, so the launcher's watchdog would report
the service frozen and later kill it. Whether the loop's own thread was busy (some code
held it: a bug, and this names the code), the process was asleep (a deadlock, a blocking
call) or the process wanted the CPU and the machine gave it none (a loaded machine:
slow, not frozen) is told apart by the process's own scheduler counters over the stall.

A task of the loop marks each turn; a daemon thread looks every `period` wall seconds.
When the loop has not turned for `limit` seconds it logs `loop_stalled` once, with where
the loop's thread is (its innermost frames); while the stall lasts it hands the evidence
(`Stalled`) to `pulse` every `every` seconds (the service shell sends it as a heartbeat
from this thread, so the watchdog hears a starved process whose loop stands); when the
loop turns again it logs `loop_resumed` with how long it stood and how much CPU its
thread used meanwhile (`busy`: the share of the stall it ran), the whole process
(`process_cpu`: when it far exceeds `cpu`, another thread of the process held the
interpreter) and `wanted`: the share of the stall the process's threads ran or waited,
runnable, for a CPU (Linux's `/proc/self/task/*/schedstat`; at least 1: some thread of
the process wanted the CPU all along, so the machine starved it; near 0: it was asleep).
The decisions are `StallJudge`'s (pure); the shell reads the clocks and the frames.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import os
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from cbdi.runtime.log import Log

__all__ = [
    "Counters",
    "LoopTurns",
    "Resumed",
    "StallJudge",
    "Stalled",
    "read_counters",
    "watch_loop",
]

FRAMES = 6  # innermost frames of the loop's thread named in `loop_stalled`


@dataclass(frozen=True)
class Counters:
    """A process's cumulative clocks, in seconds: the CPU its loop's thread ran, the CPU
    all its threads ran, and what they ran plus waited runnable for a CPU (`wanted`;
    None where the system does not say)."""

    loop_cpu: float = 0.0
    process_cpu: float = 0.0
    wanted: float | None = None


@dataclass(frozen=True)
class Stalled:
    """The loop has not turned for `silent_for` s; since the stall was found its thread
    ran `loop_cpu` s and the process's threads wanted the CPU `wanted` of the time
    (None: unknown). `first`: the stall was just found (logged once). `sending`: the
    loop stands in a send on the bus, waiting for room on the network (congestion)."""

    silent_for: float
    loop_cpu: float = 0.0
    wanted: float | None = None
    first: bool = True
    sending: bool = False


@dataclass(frozen=True)
class Resumed:
    """The loop turned again after a reported stall of `stood` s; its thread ran `cpu` s,
    the whole process `process_cpu` s (other threads: the rest), and the process's
    threads wanted the CPU `wanted` of the time (None: unknown)."""

    stood: float
    cpu: float
    process_cpu: float = 0.0
    wanted: float | None = None

    @property
    def busy(self) -> float:
        """The share of the stall the loop's thread ran (1: it held the loop itself)."""
        return min(1.0, self.cpu / self.stood) if self.stood > 0 else 0.0


def _share(now: float, then: float, since: float) -> float | None:
    return None if since <= 0 else round(max(0.0, now - then) / since, 3)


class StallJudge:
    """Decide, from the loop's last turn and the process's clocks, when it stalled."""

    def __init__(self, limit: float, every: float | None = None) -> None:
        if not (math.isfinite(limit) and limit > 0):
            raise ValueError(f"stall limit must be a finite number > 0, got {limit}")
        if every is not None and not (math.isfinite(every) and every > 0):
            raise ValueError(f"stall report period must be a finite number > 0, got {every}")
        self.limit = limit
        self.every = every
        # the stall: (its last turn, the clocks at the check before it was found and when)
        self._since: tuple[float, Counters, float] | None = None
        self._last: tuple[Counters, float] | None = None  # the clocks at the last check
        self._told = 0.0  # when the stall was last reported

    @property
    def stalling(self) -> bool:
        """Whether a stall was found and has not ended yet."""
        return self._since is not None

    def check(self, now: float, turned: float, clocks: Counters) -> Stalled | Resumed | None:
        """Judge at `now` a loop last seen turning at `turned`, the clocks at `clocks`."""
        if self._since is not None and turned > self._since[0]:
            last, then, at = self._since
            self._since = None
            wanted = None
            if clocks.wanted is not None and then.wanted is not None:
                wanted = _share(clocks.wanted, then.wanted, now - at)
            return Resumed(
                round(turned - last, 3),
                round(max(0.0, clocks.loop_cpu - then.loop_cpu), 3),
                round(max(0.0, clocks.process_cpu - then.process_cpu), 3),
                wanted,
            )
        if self._since is None:
            if now - turned <= self.limit:
                self._last = (clocks, now)
                return None
            then, at = self._last if self._last is not None else (clocks, now)
            self._since = (turned, then, at)
            self._told = now
            return self._stalled(now, turned, clocks, first=True)
        turned_at, then, at = self._since
        if then.wanted is None and clocks.wanted is not None:  # measured from now on
            self._since = (turned_at, Counters(then.loop_cpu, then.process_cpu, clocks.wanted), now)
        if self.every is not None and now - self._told >= self.every:
            self._told = now
            return self._stalled(now, turned, clocks, first=False)
        return None

    def _stalled(self, now: float, turned: float, clocks: Counters, first: bool) -> Stalled:
        assert self._since is not None
        _, then, at = self._since
        wanted = None
        if clocks.wanted is not None and then.wanted is not None:
            wanted = _share(clocks.wanted, then.wanted, now - at)
        loop_cpu = round(max(0.0, clocks.loop_cpu - then.loop_cpu), 3)
        return Stalled(round(now - turned, 3), loop_cpu, wanted, first)


class LoopTurns:
    """The loop's recent turns as its marker saw them: per turn, the CPU the loop's own
    thread ran since the turn before (`held`: what the code between two turns cost, the
    longest any one piece of work held the loop at most, whatever the machine's load)
    and how much later than asked the marker woke (`late`: wall time, the load's share
    included). Kept for the last `keep` turns; read by the heartbeats (`worst`)."""

    def __init__(self, keep: int = 512) -> None:
        if keep < 1:
            raise ValueError(f"keep must be at least 1, got {keep}")
        self._turns: deque[tuple[float, float, float]] = deque(maxlen=keep)

    def turn(self, at: float, held: float, late: float) -> None:
        """Note a turn of the marker at `at` (monotonic s)."""
        self._turns.append((at, max(0.0, held), max(0.0, late)))

    def worst(self, since: float) -> tuple[float, float]:
        """The most `held` and `late` of the turns after `since` (0.0 each: none)."""
        held = late = 0.0
        for at, h, lt in reversed(self._turns):
            if at <= since:
                break
            held, late = max(held, h), max(late, lt)
        return round(held, 4), round(late, 4)


def _where(thread: int) -> str:
    frame = sys._current_frames().get(thread)
    if frame is None:
        return "unknown"
    stack = traceback.extract_stack(frame)[-FRAMES:]
    return " < ".join(f"{f.name}({f.filename.rsplit('/', 1)[-1]}:{f.lineno})" for f in stack[::-1])


def _cpu_clock(thread: int) -> int | None:
    try:
        return time.pthread_getcpuclockid(thread)
    except (AttributeError, OSError):  # not on this platform
        return None


_TASKS = "/proc/self/task"


def _wanted() -> float | None:
    """All threads' CPU plus run-queue wait, in seconds (Linux schedstat); None if unknown.

    Threads that ended take their share with them: a judge takes no negative difference.
    """
    try:
        tids = os.listdir(_TASKS)
    except OSError:
        return None
    total = 0
    for tid in tids:
        try:
            with open(f"{_TASKS}/{tid}/schedstat", "rb") as f:
                ran, waited, _ = f.read().split()
        except (OSError, ValueError):  # the thread ended meanwhile, or no schedstat
            continue
        total += int(ran) + int(waited)
    return total / 1e9 if total else None


def read_counters(loop_clock: int | None, wanted: bool = True) -> Counters:
    """The process's clocks now; `loop_clock` is the loop thread's CPU clock id; `wanted`
    (a file per thread) is read only when asked."""
    loop_cpu = time.clock_gettime(loop_clock) if loop_clock is not None else 0.0
    return Counters(loop_cpu, time.process_time(), _wanted() if wanted else None)


async def watch_loop(
    log: Log,
    limit: float,
    period: float = 0.1,
    pulse: Callable[[Stalled], None] | None = None,
    every: float | None = None,
    sending: Callable[[], bool] | None = None,
    turns: LoopTurns | None = None,
) -> None:
    """Mark the loop's turns every `period` s; a daemon thread logs its stalls and hands
    the evidence to `pulse` (called in that thread) every `every` s while one lasts;
    `sending` tells whether the loop is in a send on the bus (`Bus.sending`); each turn
    goes to `turns` (what the loop's thread ran since the last, how late it came)."""
    judge = StallJudge(limit, every if pulse is not None else None)
    loop_thread = threading.get_ident()
    clock = _cpu_clock(loop_thread)
    turned = [time.monotonic()]
    done = threading.Event()

    def watch() -> None:
        while not done.wait(period):
            now = time.monotonic()
            # A stall may come (or one ends now): read what it will need.
            near = judge.stalling or now - turned[0] > limit / 2
            decision = judge.check(now, turned[0], read_counters(clock, near))
            if isinstance(decision, Stalled):
                if sending is not None and sending():
                    decision = dataclasses.replace(decision, sending=True)
                if decision.first:
                    log.warning(
                        "loop_stalled",
                        silent_for=decision.silent_for,
                        sending=decision.sending,
                        where=_where(loop_thread),
                    )
                if pulse is not None:
                    pulse(decision)
            elif isinstance(decision, Resumed):
                log.warning(
                    "loop_resumed",
                    stood=decision.stood,
                    cpu=decision.cpu,
                    process_cpu=decision.process_cpu,
                    busy=f"{decision.busy:.2f}",
                    wanted="unknown" if decision.wanted is None else f"{decision.wanted:.2f}",
                )

    threading.Thread(target=watch, name="stall-watch", daemon=True).start()
    try:
        cpu = time.thread_time()
        while True:
            now = time.monotonic()
            if turns is not None:
                ran = time.thread_time()
                turns.turn(now, ran - cpu, now - turned[0] - period)
                cpu = ran
            turned[0] = now
            await asyncio.sleep(period)
    finally:
        done.set()
