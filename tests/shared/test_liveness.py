"""The launcher's watchdog: who is frozen, from heartbeats and the checks' times alone."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.launcher.liveness import Frozen, Stall, Starved, Watchdog

RUN = {"router": 10, "world": 11, "robot1/planner": 12}


def _beating(dog: Watchdog, until: float, services: dict[str, int], step: float = 0.5) -> None:
    t = 0.0
    while t <= until:
        for service, pid in services.items():
            dog.beat(service, pid, t)
        dog.check(t, RUN)
        t += step


def _checks(
    dog: Watchdog,
    start: float,
    end: float,
    running: dict[str, int] = RUN,
    beating: int = 2,
    stalled: Stall | None = None,
) -> list[Frozen | Starved]:
    """Check every tick from `start` to `end`, the first `beating` services of `running`
    beating all along (the rest, if `stalled`, sending that word every 0.5 s); return
    every verdict."""
    found: list[Frozen | Starved] = []
    t = start
    while t <= end + 1e-9:
        for service, pid in list(running.items())[:beating]:
            dog.beat(service, pid, t)
        if stalled is not None and round(t * 10) % 5 == 0:
            for service, pid in list(running.items())[beating:]:
                dog.beat(service, pid, t, stalled)
        found += dog.check(t, running)
        t = round(t + 0.1, 3)
    return found


def test_a_silent_service_is_judged_frozen_once_within_the_limit() -> None:
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 8.0)
    assert [(f.service, f.pid) for f in found] == [("robot1/planner", 12)]
    assert 1.9 <= found[0].silent_for <= 2.0  # found within the limit of its last beat


def test_beating_services_are_never_frozen() -> None:
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 60.0, RUN)
    assert dog.check(60.1, RUN) == []


def test_a_restarted_service_is_watched_once_its_new_process_beats() -> None:
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 3.0, RUN)
    restarted = {**RUN, "robot1/planner": 13}
    assert _checks(dog, 3.1, 9.0, restarted) == []  # the old pid's silence is not its
    dog.beat("robot1/planner", 13, 9.0)
    found = _checks(dog, 9.1, 12.0, restarted)
    assert [(f.service, f.pid) for f in found] == [("robot1/planner", 13)]


def test_a_late_watchdog_judges_nobody_and_restarts_every_clock() -> None:
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 3.0, RUN)
    assert dog.check(10.0, RUN) == []  # its own loop stalled 7 s: the beats may be queued
    assert dog.check(10.1, RUN) == []


def test_when_everyone_falls_silent_only_the_router_is_judged() -> None:
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 3.0, RUN)
    found: list[Frozen] = []
    for i in range(1, 40):
        found += dog.check(3.0 + i * 0.1, RUN)
    assert [f.service for f in found] == ["router"]
    without_router = {k: v for k, v in RUN.items() if k != "router"}
    dog = Watchdog(2.0, 0.1)
    _beating(dog, 3.0, RUN)
    assert all(dog.check(3.0 + i * 0.1, without_router) == [] for i in range(1, 40))


@pytest.mark.parametrize(("limit", "tick"), [(0.0, 0.1), (2.0, 2.0), (float("inf"), 0.1)])
def test_a_limit_the_checks_cannot_meet_is_refused(limit: float, tick: float) -> None:
    with pytest.raises(ValueError, match="tick"):
        Watchdog(limit, tick)


def test_a_process_that_never_beats_is_judged_after_the_startup_limit() -> None:
    dog = Watchdog(2.0, 0.1, startup=5.0)
    _beating(dog, 3.0, RUN)
    restarted = {**RUN, "robot1/planner": 13}  # frozen while starting: never a beat
    found = _checks(dog, 3.1, 12.0, restarted)
    assert [(f.service, f.pid) for f in found] == [("robot1/planner", 13)]
    assert 5.0 < found[0].silent_for <= 5.2


def test_a_freeze_is_reported_at_the_limit_and_killed_at_the_kill_limit() -> None:
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 20.0)
    assert [(f.service, f.kill) for f in found] == [
        ("robot1/planner", False),
        ("robot1/planner", True),
    ]
    assert 1.9 <= found[0].silent_for <= 2.0 and 9.9 <= found[1].silent_for <= 10.0
    # Starved for a moment, not frozen: reported once, beating again, never killed.
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 6.0)
    found += _checks(dog, 6.1, 20.0, beating=3)  # it beats again
    assert [f.kill for f in found] == [False]
    with pytest.raises(ValueError, match="kill limit"):
        Watchdog(2.0, 0.1, kill_after=1.0)


STARVED = Stall(stalled_for=3.0, loop_cpu=0.05, wanted=1.4)  # waited for a CPU, loop idle


def test_a_starved_process_is_reported_once_and_never_killed() -> None:
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 60.0, stalled=STARVED)
    assert found == [Starved("robot1/planner", 12, found[0].stalled_for, 1.4)]
    assert 1.9 <= found[0].stalled_for <= 2.0
    dog.beat("robot1/planner", 12, 60.1)  # its loop turns again: a new stall is news
    found = _checks(dog, 60.2, 64.0, stalled=STARVED)
    assert [type(f) for f in found] == [Starved]


def test_a_loop_waiting_in_a_send_on_a_congested_bus_is_reported_and_never_killed() -> None:
    """Asleep by the CPU's account (nobody wanted it), but in a send: the network has no
    room (a router starved of CPU); killing the sender would make none."""
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    waiting = Stall(stalled_for=3.0, loop_cpu=0.01, wanted=0.02, sending=True)
    found = _checks(dog, 3.1, 60.0, stalled=waiting)
    assert found == [Starved("robot1/planner", 12, found[0].stalled_for, 0.02, cause="bus")]
    held = Stall(stalled_for=3.0, loop_cpu=2.5, wanted=1.0, sending=True)  # its code ran
    assert not held.congested(2.0) and waiting.congested(2.0) and not waiting.starved(2.0)


@pytest.mark.parametrize(
    "word",
    [
        Stall(stalled_for=3.0, loop_cpu=2.5, wanted=1.0),  # its loop's thread ran: held by code
        Stall(stalled_for=3.0, loop_cpu=0.0, wanted=0.01),  # nobody wanted the CPU: asleep
        Stall(stalled_for=3.0, loop_cpu=0.0, wanted=None),  # the system does not say
    ],
)
def test_a_stalled_loop_that_is_not_starved_is_frozen_and_killed(word: Stall) -> None:
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 20.0, stalled=word)
    assert [(type(f), f.service) for f in found] == [(Frozen, "robot1/planner")] * 2
    assert [f.kill for f in found if isinstance(f, Frozen)] == [False, True]


def test_a_starved_process_that_falls_silent_is_killed_at_the_kill_limit() -> None:
    # Starved, then stopped (SIGSTOP): its last word goes stale, it is frozen after all.
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, RUN)
    found = _checks(dog, 3.1, 8.0, stalled=STARVED)
    found += _checks(dog, 8.1, 20.0)
    assert [type(f) for f in found] == [Starved, Frozen, Frozen]
    frozen = [f for f in found if isinstance(f, Frozen)]
    assert [f.kill for f in frozen] == [False, True]
    assert 6.9 <= frozen[0].silent_for <= 7.2  # once its last word (at 8) is stale
    assert 9.9 <= frozen[1].silent_for <= 10.0


def test_the_evidence_a_process_leaves_in_its_stall_file_is_heard(tmp_path: Path) -> None:
    """A congested network drops the heartbeats that carry a stall's evidence; under
    `cbdi up` the stall watcher also leaves it in a file the watchdog reads: a process
    whose loop waits in a send is then congested, not frozen (the world of a 32-robot
    run was killed four times for want of it)."""
    from cbdi.launcher.process import ManagedProcess, ProcessSpec, RestartPolicy
    from cbdi.launcher.watch import _read_stall
    from cbdi.runtime.service import _leave, _stall_beat
    from cbdi.runtime.stall import Stalled

    members = ("robot1/planner", "robot1/scheduler")
    spec = ProcessSpec.of("robot1/agent", ["cbdi"], [], {}, hosts=members)
    proc = ManagedProcess(spec, RestartPolicy(), lambda *_: None, str(tmp_path / "0.heartbeat"))
    running = {"router": 10, "robot1/planner": 12, "robot1/scheduler": 12}
    dog = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(dog, 3.0, running)
    seen: dict[str, float] = {}
    _read_stall(dog, proc, 12, 3.1, seen)  # no file yet: nothing
    found: list[Frozen | Starved] = []
    t = 3.1
    while t < 20.0:
        stall = Stalled(round(t - 3.0, 3), loop_cpu=0.01, wanted=0.02, sending=True)
        _leave(proc.stall_file, _stall_beat("robot1/planner", 12, stall))
        _read_stall(dog, proc, 12, t, seen)
        dog.beat("router", 10, t)  # the rest of the run beats on
        found += dog.check(t, running)
        t += 0.5
    assert [(type(f), f.service) for f in found] == [(Starved, m) for m in sorted(members)]
    assert all(isinstance(f, Starved) and f.cause == "bus" for f in found)
    _leave(proc.stall_file, _stall_beat("robot1/planner", 99, stall))  # another life's
    other = Watchdog(2.0, 0.1, kill_after=10.0)
    _beating(other, 3.0, running)
    _read_stall(other, proc, 12, 3.5, {})
    assert [type(f) for f in _checks(other, 3.6, 20.0, running, beating=1)] == [Frozen] * 4


def test_an_agents_process_runs_nicer_than_the_shared_ones() -> None:
    """`cbdi up --agent-nice`: the router, world and monitor keep the launcher's
    priority, an agent's process takes the niceness asked (never a higher priority)."""
    import os
    import subprocess
    import sys

    from cbdi.launcher.process import ProcessSpec
    from cbdi.launcher.run import _niced
    from cbdi.runtime.parent import NICE_ENV, take_niceness

    world = ProcessSpec.of("world", ["cbdi-world"], [], {})
    agent = ProcessSpec.of("robot1/agent", ["cbdi"], [], {"X": "1"})
    assert _niced(world, 5) is world and _niced(agent, 0) is agent
    assert _niced(agent, 5).env == {"X": "1", NICE_ENV: "5"}
    assert take_niceness({NICE_ENV: "oops"}) == 0 and take_niceness({NICE_ENV: "40"}) == 0
    code = "from cbdi.runtime.parent import take_niceness as t; import os; t(); print(os.nice(0))"
    base = os.getpriority(os.PRIO_PROCESS, 0)
    env = {**os.environ, NICE_ENV: "7"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert int(out.stdout) == max(base, 7)


def test_a_silent_process_is_looked_at_from_outside() -> None:
    """The launcher reads a silent process's schedstat itself (a starved process's own
    word comes late): a loop's thread that wants the CPU is starved; one asleep beside a
    spinning thread (a deadlock) and a stopped process are left to the heartbeats."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from cbdi.launcher.process import ManagedProcess, ProcessSpec, RestartPolicy
    from cbdi.launcher.watch import _look_at

    spin = "while True: pass"
    asleep = (
        "import threading, time\n"
        "threading.Thread(target=lambda: exec('while 1: pass'), daemon=True).start()\n"
        "time.sleep(600)"
    )
    verdicts = []
    for code, stop in ((spin, False), (asleep, False), (spin, True)):
        child = subprocess.Popen([sys.executable, "-c", code])
        try:
            time.sleep(0.3)
            if stop:
                os.kill(child.pid, signal.SIGSTOP)
            spec = ProcessSpec.of("robot1/agent", ["cbdi"], [], {}, hosts=("robot1/planner",))
            proc = ManagedProcess(spec, RestartPolicy(), lambda *_: None)
            running = {"router": 10, "robot1/planner": child.pid}
            dog = Watchdog(2.0, 0.1, kill_after=10.0)
            _beating(dog, 3.0, running)
            since: dict[int, tuple[float, tuple[int, int, int]]] = {}
            _look_at(dog, proc, child.pid, 3.2, since)  # not silent long enough yet
            assert not since
            found: list[Frozen | Starved] = []
            for k in range(31, 51):  # every tick from 3.1 s to 5 s
                t = k / 10
                dog.beat("router", 10, t)
                if k == 48:
                    time.sleep(0.5)  # what it ran and waited meanwhile
                if k in (41, 48):  # silent 1.1 s: the clocks now; 1.8 s: what since
                    _look_at(dog, proc, child.pid, t, since)
                found += dog.check(t, running)
            verdicts.append([type(f) for f in found])
        finally:
            child.kill()
            child.wait()
    assert verdicts == [[Starved], [Frozen], [Frozen]]
