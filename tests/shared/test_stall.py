"""A stalled event loop is named in the log: where it stands, how long, whose fault."""

from __future__ import annotations

import asyncio
import io
import time
from pathlib import Path

import pytest

from cbdi.runtime.log import Log
from cbdi.runtime.stall import Counters, LoopTurns, Resumed, Stalled, StallJudge, watch_loop


def _c(loop: float, process: float = 0.0, wanted: float | None = None) -> Counters:
    return Counters(loop, process, wanted)


def test_a_stall_is_reported_once_then_its_end_with_the_cpu_used() -> None:
    judge = StallJudge(1.0)
    assert judge.check(now=10.5, turned=10.0, clocks=_c(3.0)) is None
    assert judge.check(now=11.2, turned=10.0, clocks=_c(3.2)) == Stalled(1.2, 0.2)
    assert judge.check(now=15.0, turned=10.0, clocks=_c(7.0)) is None  # the same stall
    resumed = judge.check(now=16.1, turned=16.0, clocks=_c(8.5))
    assert resumed == Resumed(6.0, 5.5)
    assert resumed.busy == pytest.approx(5.5 / 6.0)
    assert judge.check(now=16.3, turned=16.2, clocks=_c(8.6)) is None
    assert judge.check(now=17.5, turned=16.2, clocks=_c(8.6)) == Stalled(1.3)  # a new one


def test_a_starved_loop_is_told_from_a_busy_one() -> None:
    judge = StallJudge(0.5)
    judge.check(now=2.0, turned=1.0, clocks=_c(0.0))
    assert judge.check(now=9.0, turned=8.9, clocks=_c(0.4)).busy == pytest.approx(0.4 / 7.9)


def test_another_thread_holding_the_interpreter_shows_in_the_process_cpu() -> None:
    judge = StallJudge(0.5)
    judge.check(now=1.0, turned=1.0, clocks=_c(2.0, 5.0))
    assert judge.check(now=2.0, turned=1.0, clocks=_c(2.01, 6.0)) == Stalled(1.0, 0.01)
    resumed = judge.check(now=4.1, turned=4.0, clocks=_c(2.02, 8.0))
    assert resumed == Resumed(3.0, 0.02, 3.0)


def test_a_lasting_stall_is_told_every_period_with_the_share_the_process_wanted() -> None:
    judge = StallJudge(1.0, every=0.5)
    assert judge.check(now=0.9, turned=0.0, clocks=_c(1.0, 1.0, 10.0)) is None
    first = judge.check(now=1.1, turned=0.0, clocks=_c(1.0, 1.1, 10.3))
    assert first == Stalled(1.1, 0.0, 1.5, first=True)  # 0.3 s wanted over 0.2 s
    assert judge.check(now=1.4, turned=0.0, clocks=_c(1.0, 1.2, 10.6)) is None
    again = judge.check(now=1.6, turned=0.0, clocks=_c(1.01, 1.3, 11.4))
    assert again == Stalled(1.6, 0.01, 2.0, first=False)  # 1.4 s over 0.7 s: starved
    assert judge.stalling
    resumed = judge.check(now=1.9, turned=1.8, clocks=_c(1.02, 1.4, 12.3))
    assert resumed == Resumed(1.8, 0.02, 0.4, 2.3)
    assert not judge.stalling  # the watcher reads the share only near a stall


def test_an_asleep_process_wants_no_cpu_and_an_unknown_share_stays_unknown() -> None:
    judge = StallJudge(1.0, every=0.5)
    judge.check(now=0.9, turned=0.0, clocks=_c(1.0, 1.0, 10.0))
    assert judge.check(now=1.9, turned=0.0, clocks=_c(1.0, 1.0, 10.0)).wanted == 0.0
    judge = StallJudge(1.0, every=0.5)
    judge.check(now=0.9, turned=0.0, clocks=_c(1.0))  # no schedstat on this system
    assert judge.check(now=1.9, turned=0.0, clocks=_c(1.0)).wanted is None


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


def test_a_loop_standing_in_a_send_says_so_in_its_pulses() -> None:
    """`sending` (the bus's sends under way) is read by the watcher's thread: a loop that
    waits in a send for room on the network is told from one held by code."""
    out, pulses, in_send = io.StringIO(), [], [False]
    log = Log("world", stream=out)

    async def run() -> None:
        watcher = watch_loop(
            log,
            limit=0.2,
            period=0.05,
            pulse=pulses.append,
            every=0.1,
            sending=lambda: in_send[0],
        )
        watch = asyncio.get_running_loop().create_task(watcher)
        await asyncio.sleep(0.1)
        in_send[0] = True  # a put that waits (asleep: no CPU)
        deadline = time.monotonic() + 60
        while not pulses and time.monotonic() < deadline:
            time.sleep(0.05)
        in_send[0] = False
        watch.cancel()

    asyncio.run(run())
    assert pulses and pulses[0].sending and pulses[0].loop_cpu < 0.2
    assert "sending=True" in next(x for x in out.getvalue().splitlines() if "loop_stalled" in x)


def test_a_pulse_stuck_on_a_congested_bus_does_not_stop_the_watcher(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bus's send may wait on a congested network: the watcher hands it to a thread
    (one at a time) and goes on writing its evidence for the launcher."""
    import threading
    from types import SimpleNamespace

    from cbdi.runtime.service import _stall_pulse
    from cbdi.runtime.stall import Stalled
    from cbdi.wire.base import decode
    from cbdi.wire.common import Heartbeat

    room, calls = threading.Event(), []

    def stuck(key: str, payload: bytes) -> None:
        calls.append(key)
        room.wait(60)  # no room on the network

    path = tmp_path / "0.heartbeat"
    monkeypatch.setenv("CBDI_STALL_FILE", str(path))
    ctx = SimpleNamespace(service="world", bus=SimpleNamespace(pulse=stuck))
    pulse = _stall_pulse([ctx])  # type: ignore[list-item]
    for k in range(1, 6):
        pulse(Stalled(float(k), sending=True))  # returns at once, each time
        assert decode(path.read_bytes(), Heartbeat).stalled_for == float(k)
    room.set()
    deadline = time.monotonic() + 60
    while not calls and time.monotonic() < deadline:
        time.sleep(0.01)
    assert calls == ["cbdi/heartbeat/world"]  # one send in flight, the others skipped


def test_the_loops_turns_tell_how_long_its_own_code_held_it_not_how_long_it_slept() -> None:
    turns = LoopTurns()
    log = Log("robot1/planner", stream=io.StringIO())

    async def run() -> tuple[tuple[float, float], tuple[float, float]]:
        watch = asyncio.get_running_loop().create_task(
            watch_loop(log, limit=5.0, period=0.01, turns=turns)
        )
        await asyncio.sleep(0.05)
        before = time.monotonic()
        time.sleep(0.15)  # the loop stands, its thread asleep: late, not held
        await asyncio.sleep(0.05)
        asleep = turns.worst(before)
        before = time.monotonic()
        busy = time.thread_time() + 0.15
        while time.thread_time() < busy:  # the loop's own code runs 150 ms of CPU
            pass
        await asyncio.sleep(0.05)
        watch.cancel()
        return asleep, turns.worst(before)

    (held_asleep, late_asleep), (held_busy, late_busy) = asyncio.run(run())
    assert held_asleep < 0.05 and late_asleep >= 0.1
    assert held_busy >= 0.14 and late_busy >= 0.1
    assert turns.worst(time.monotonic()) == (0.0, 0.0)  # nothing since


def test_turns_keep_only_the_latest() -> None:
    turns = LoopTurns(keep=2)
    for at, held in ((1.0, 0.5), (2.0, 0.1), (3.0, 0.2)):
        turns.turn(at, held, -1.0)
    assert turns.worst(0.0) == (0.2, 0.0)  # the first is forgotten, no negative lateness
    with pytest.raises(ValueError):
        LoopTurns(keep=0)
