"""Which code stalls a service's event loop, named in its log while it happens.

A loop that does not turn sends no heartbeat, so the launcher's watchdog reports the
service frozen and later kills it. Whether the loop's own thread was busy (some code
held it: a bug, and this names the code) or the process got no CPU (a loaded machine:
slow, not frozen) is told apart by the loop thread's CPU time over the stall.

A task of the loop marks each turn; a daemon thread looks every `period` wall seconds.
When the loop has not turned for `limit` seconds it logs `loop_stalled` once, with where
the loop's thread is (its innermost frames); when the loop turns again it logs
`loop_resumed` with how long it stood and how much CPU its thread used meanwhile
(`busy`: the share of the stall it ran). The decisions are `StallJudge`'s (pure); the
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
    """The loop turned again after a reported stall of `stood` s; its thread ran `cpu` s."""

    stood: float
    cpu: float

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
        self._since: tuple[float, float] | None = None  # (last turn, cpu then) of a stall
        self._cpu: float | None = None  # the CPU clock at the last check outside a stall

    def check(self, now: float, turned: float, cpu: float) -> Stalled | Resumed | None:
        """Judge at `now` a loop last seen turning at `turned`, its thread's CPU at `cpu`."""
        if self._since is not None and turned > self._since[0]:
            last, cpu_then = self._since
            self._since = None
            return Resumed(round(turned - last, 3), round(max(0.0, cpu - cpu_then), 3))
        if self._since is None and now - turned > self.limit:
            self._since = (turned, cpu if self._cpu is None else self._cpu)
            return Stalled(round(now - turned, 3))
        if self._since is None:
            self._cpu = cpu
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
            decision = judge.check(time.monotonic(), turned[0], cpu())
            if isinstance(decision, Stalled):
                log.warning(
                    "loop_stalled", silent_for=decision.silent_for, where=_where(loop_thread)
                )
            elif isinstance(decision, Resumed):
                log.warning(
                    "loop_resumed",
                    stood=decision.stood,
                    cpu=decision.cpu,
                    busy=f"{decision.busy:.2f}",
                )

    threading.Thread(target=watch, name="stall-watch", daemon=True).start()
    try:
        while True:
            turned[0] = time.monotonic()
            await asyncio.sleep(period)
    finally:
        done.set()
