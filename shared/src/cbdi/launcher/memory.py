"""How much memory a run's processes hold: sampled while it runs, the peaks reported.

`cbdi up` samples every running process's resident set (Linux `/proc/PID/statm`) once a
`period`, and keeps each service's peak and the peak of their sum at one sample (what
the machine had to hold at once; the sum of the peaks can only be larger). The summary
reports both, in MB (`RunSummary.memory`). Where the system does not say, nothing is
counted.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from cbdi.clock import Clock, WallClock
from cbdi.launcher.process import ManagedProcess

__all__ = ["PERIOD", "MemoryPeaks", "resident_bytes", "watch_memory"]

PERIOD = 1.0  # wall seconds between samples
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
_MB = 1024 * 1024


def resident_bytes(pid: int) -> int | None:
    """Process `pid`'s resident set in bytes, or None if it is gone or unknown."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as f:
            return int(f.read().split()[1]) * _PAGE
    except (OSError, ValueError, IndexError):
        return None


@dataclass
class MemoryPeaks:
    """The largest resident sets seen: per service and of all services at one sample."""

    total: int = 0
    services: dict[str, int] = field(default_factory=dict)
    samples: int = 0

    def sample(self, resident: Mapping[str, int]) -> None:
        """Note one sample: service -> resident bytes of its current process."""
        self.samples += 1
        self.total = max(self.total, sum(resident.values()))
        for service, size in resident.items():
            self.services[service] = max(self.services.get(service, 0), size)

    def summary(self) -> dict[str, object]:
        """The peaks in MB (one decimal), for `cbdi up --json`."""
        return {
            "peak_total_mb": round(self.total / _MB, 1),
            "peak_mb": {s: round(b / _MB, 1) for s, b in sorted(self.services.items())},
            "samples": self.samples,
        }


async def watch_memory(
    procs: Sequence[ManagedProcess],
    peaks: MemoryPeaks,
    clock: Clock | None = None,
    period: float = PERIOD,
) -> None:
    """Sample every running process's resident set each `period` into `peaks`."""
    clock = clock or WallClock()
    while True:
        resident = {}
        for proc in procs:
            pid = proc.pid
            size = resident_bytes(pid) if pid is not None and proc.running else None
            if size is not None:
                resident[proc.spec.service] = size
        if resident:
            peaks.sample(resident)
        await clock.sleep(period)
