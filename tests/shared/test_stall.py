"""A stalled event loop is named in the log: where it stands, how long, whose fault."""

from __future__ import annotations

import asyncio
import io
import time

import pytest

from cbdi.runtime.log import Log
from cbdi.runtime.stall import Resumed, Stalled, StallJudge, watch_loop


def test_a_stall_is_reported_once_then_its_end_with_the_cpu_used() -> None:
    judge = StallJudge(1.0)
    assert judge.check(now=10.5, turned=10.0, cpu=3.0) is None
    assert judge.check(now=11.2, turned=10.0, cpu=3.2) == Stalled(1.2)
    assert judge.check(now=15.0, turned=10.0, cpu=7.0) is None  # still the same stall
    resumed = judge.check(now=16.1, turned=16.0, cpu=8.5)
    assert resumed == Resumed(6.0, 5.5)
    assert resumed.busy == pytest.approx(5.5 / 6.0)
    assert judge.check(now=16.3, turned=16.2, cpu=8.6) is None
    assert judge.check(now=17.5, turned=16.2, cpu=8.6) == Stalled(1.3)  # a new one


def test_a_starved_loop_is_told_from_a_busy_one() -> None:
    judge = StallJudge(0.5)
    judge.check(now=2.0, turned=1.0, cpu=0.0)
    assert judge.check(now=9.0, turned=8.9, cpu=0.4).busy == pytest.approx(0.4 / 7.9)


def test_another_thread_holding_the_interpreter_shows_in_the_process_cpu() -> None:
    judge = StallJudge(0.5)
    judge.check(now=1.0, turned=1.0, cpu=2.0, process_cpu=5.0)
    assert judge.check(now=2.0, turned=1.0, cpu=2.01, process_cpu=6.0) == Stalled(1.0)
    assert judge.check(now=4.1, turned=4.0, cpu=2.02, process_cpu=8.0) == Resumed(3.0, 0.02, 3.0)


@pytest.mark.parametrize("limit", [0.0, -1.0, float("nan"), float("inf")])
def test_a_nonsensical_limit_is_refused(limit: float) -> None:
    with pytest.raises(ValueError, match="stall limit"):
        StallJudge(limit)


def _hold_the_loop(out: io.StringIO) -> None:
    """Spin on the loop's thread until the watcher has named this function."""
    deadline = time.monotonic() + 60
    while "loop_stalled" not in out.getvalue() and time.monotonic() < deadline:
        sum(range(1000))


def test_the_log_names_the_code_that_holds_the_loop() -> None:
    out = io.StringIO()
    log = Log("robot1/planner", stream=out)

    async def run() -> None:
        watch = asyncio.get_running_loop().create_task(watch_loop(log, limit=0.2, period=0.05))
        await asyncio.sleep(0.1)
        _hold_the_loop(out)
        deadline = time.monotonic() + 60
        while "loop_resumed" not in out.getvalue() and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        watch.cancel()

    asyncio.run(run())
    lines = out.getvalue().splitlines()
    stalled = next(line for line in lines if "event=loop_stalled" in line)
    assert "_hold_the_loop(test_stall.py:" in stalled
    resumed = next(line for line in lines if "event=loop_resumed" in line)
    fields = dict(part.split("=", 1) for part in resumed.split() if "=" in part)
    assert float(fields["stood"]) >= 0.2
    assert float(fields["cpu"]) > 0
    assert float(fields["process_cpu"]) >= float(fields["cpu"])
