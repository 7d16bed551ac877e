"""The run's memory: each service's peak resident set and the peak of their sum, sampled
from real processes; and a frozen process counted once whether reported or killed."""

from __future__ import annotations

import asyncio
import sys

import pytest

from cbdi.launcher.memory import MemoryPeaks, resident_bytes, watch_memory
from cbdi.launcher.process import ManagedProcess, ProcessSpec, RestartPolicy

MB = 1024 * 1024
# holds N MB, every page touched
HOLD = "import time; b = bytearray({n} << 20); b[::4096] = b'x' * ({n} * 256); time.sleep(30)"


def test_peaks_are_per_service_and_of_the_sum_at_one_sample() -> None:
    peaks = MemoryPeaks()
    peaks.sample({"a": 100 * MB, "b": 10 * MB})
    peaks.sample({"a": 20 * MB, "b": 50 * MB})
    summary = peaks.summary()
    assert summary["peak_total_mb"] == 110.0  # not 150: a and b never peaked together
    assert summary["peak_mb"] == {"a": 100.0, "b": 50.0} and summary["samples"] == 2


def test_a_gone_process_has_no_resident_set() -> None:
    assert resident_bytes(2**22 + 12345) is None


def test_real_processes_are_sampled_with_their_memory() -> None:
    async def run() -> MemoryPeaks:
        said: list[str] = []
        procs = [
            ManagedProcess(
                ProcessSpec(name, (sys.executable, "-c", HOLD.format(n=n))),
                RestartPolicy("never"),
                lambda who, line: said.append(line),
            )
            for name, n in (("big", 120), ("small", 5))
        ]
        for p in procs:
            await p.start()
        peaks = MemoryPeaks()
        task = asyncio.create_task(watch_memory(procs, peaks, period=0.05))
        try:
            for _ in range(200):  # until the big one holds its 120 MB (a loaded machine is slow)
                await asyncio.sleep(0.05)
                if peaks.services.get("big", 0) > 120 * MB:
                    break
        finally:
            task.cancel()
            for p in procs:
                p.stopping = True
                await p.stop()
        return peaks

    peaks = asyncio.run(run())
    assert peaks.services["big"] > 120 * MB > peaks.services["small"]
    assert peaks.total >= peaks.services["big"]


def test_a_frozen_process_counts_once_reported_then_killed() -> None:
    proc = ManagedProcess(ProcessSpec("x", ("true",)), RestartPolicy("never"), lambda *a: None)
    proc.frozen(41)
    proc.frozen(41)  # the kill of the same process after its report
    proc.frozen(42)  # its restart, frozen too
    assert proc.freezes == 2 and proc.freeze_kills == 0


def test_services_run_with_two_malloc_arenas_unless_told_otherwise(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async def arenas() -> str:
        said: list[str] = []
        code = "import os; print(os.environ['MALLOC_ARENA_MAX'])"
        proc = ManagedProcess(
            ProcessSpec("x", (sys.executable, "-c", code)),
            RestartPolicy("never"),
            lambda who, line: said.append(line),
        )
        await proc.start()
        assert proc.proc is not None
        await proc.proc.wait()
        for _ in range(1000):  # the output pump may still be reading
            if len(said) > 1:
                break
            await asyncio.sleep(0.01)
        return said[-1]  # after the launcher's `started` line

    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    assert asyncio.run(arenas()) == "2"
    monkeypatch.setenv("MALLOC_ARENA_MAX", "8")
    assert asyncio.run(arenas()) == "8"
