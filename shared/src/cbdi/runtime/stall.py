"""Which code stalls a service's event loop, named in its log while it happens.

A loop that does not turn sends no heartbeat, so the launcher's watchdog reports the
service frozen and later kills it. Whether the loop's own thread was busy (some code
held it: a bug, and this names the code) or the process got no CPU (a loaded machine:
slow, not frozen) is told apart by the loop thread's CPU time over the stall.

A task of the loop marks each turn; a daemon thread looks every `period` wall seconds.
When the loop has not turned for `limit` seconds it logs `loop_stalled` once, with where
the loop's thread is (its innermost frames); when the loop turns again it logs
`loop_resumed` with how long it stood and how much CPU its thread used meanwhile
(`busy`: the share of the stall it ran) and the whole process (`process_cpu`: when it
far exceeds `cpu`, another thread of the process held the interpreter; when both are
near 0, the machine gave the process no CPU). The decisions are `StallJudge`'s (pure); the
shell reads the clocks and the frames.
"""

from __future__ import annotations

import asyncio
import math
import sys
import threading
import time
import traceback
from dataclasses import dataclass

from cbdi.runtime.log import Log

__all__ = ["Resumed", "StallJudge", "Stalled", "watch_loop"]

FRAMES = 6  # innermost frames of the loop's thread named in `loop_stalled`


@dataclass(frozen=True)
class Stalled:
    """The loop has not turned for `silent_for` s (reported once per stall)."""

    silent_for: float


@dataclass(frozen=True)
class Resumed:
    """The loop turned again after a reported stall of `stood` s; its thread ran `cpu` s,
    the whole process `process_cpu` s (other threads: the rest)."""

    stood: float
    cpu: float
    process_cpu: float = 0.0

    @property
    def busy(self) -> float:
        """The share of the stall the loop's thread ran (1: it held the loop itself)."""
        return min(1.0, self.cpu / self.stood) if self.stood > 0 else 0.0


class StallJudge:
    """Decide, from the loop's last turn and its thread's CPU clock, when it stalled."""

    def __init__(self, limit: float) -> None:
        if not (math.isfinite(limit) and limit > 0):
            raise ValueError(f"stall limit must be a finite number > 0, got {limit}")
        self.limit = limit
        # (last turn, the loop thread's and the process's CPU then) of a stall
        self._since: tuple[float, float, float] | None = None
        self._cpu: tuple[float, float] | None = None  # the CPU clocks at the last check

    def check(
        self, now: float, turned: float, cpu: float, process_cpu: float = 0.0
    ) -> Stalled | Resumed | None:
        """Judge at `now` a loop last seen turning at `turned`, its thread's CPU clock at
        `cpu`, the process's at `process_cpu`."""
        if self._since is not None and turned > self._since[0]:
            last, cpu_then, process_then = self._since
            self._since = None
            return Resumed(
                round(turned - last, 3),
                round(max(0.0, cpu - cpu_then), 3),
                round(max(0.0, process_cpu - process_then), 3),
            )
        if self._since is None and now - turned > self.limit:
            then = (cpu, process_cpu) if self._cpu is None else self._cpu
            self._since = (turned, *then)
            return Stalled(round(now - turned, 3))
        if self._since is None:
            self._cpu = (cpu, process_cpu)
        return None


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


async def watch_loop(log: Log, limit: float, period: float = 0.1) -> None:
    """Mark the loop's turns every `period` s; a daemon thread logs its stalls."""
    judge = StallJudge(limit)
    loop_thread = threading.get_ident()
    clock = _cpu_clock(loop_thread)
    turned = [time.monotonic()]
    done = threading.Event()

    def cpu() -> float:
        return time.clock_gettime(clock) if clock is not None else 0.0

    def watch() -> None:
        while not done.wait(period):
            decision = judge.check(time.monotonic(), turned[0], cpu(), time.process_time())
            if isinstance(decision, Stalled):
                log.warning(
                    "loop_stalled", silent_for=decision.silent_for, where=_where(loop_thread)
                )
            elif isinstance(decision, Resumed):
                log.warning(
                    "loop_resumed",
                    stood=decision.stood,
                    cpu=decision.cpu,
                    process_cpu=decision.process_cpu,
                    busy=f"{decision.busy:.2f}",
                )

    threading.Thread(target=watch, name="stall-watch", daemon=True).start()
    try:
        while True:
            turned[0] = time.monotonic()
            await asyncio.sleep(period)
    finally:
        done.set()
