"""Faults of a real run (`cbdi up`, real processes, real Zenoh): no orphans, no silent freeze.

- SIGKILL of `cbdi up` leaves no process of the run behind: every service got the
  parent-death signal from Linux (`cbdi.runtime.parent`).
- A service stopped with SIGSTOP is found frozen within the freeze limit (its heartbeat
  stops), reported in the launcher's log and on the bus (recorded by the monitor), killed
  and restarted; the run still recycles everything.
- A world whose run ended stops on its own after `--linger`, launcher or not.
- SIGKILL of an agent's planner, scheduler or executor, or of the router, mid-run (lockstep): the
  launcher restarts it, a restarted agent service joins at the epoch under way
  (`Lockstep.rejoin`), what was sent while the router was down is recovered, and the
  run goes on with no ack timeout: no stalled epoch, everything recycled, the mission
  within 5 epochs of the undisturbed run's, and the recording holds every epoch.
- SIGKILL of the monitor: the restart goes on in a new part and recovers what was sent
  meanwhile; the parts hold every epoch once.
- SIGKILL of the world mid-run: the launcher restarts it, it goes on from its state file
  at the epoch it was killed in (`cbdi_world.recovery`) and every member resynchronises
  (their latest acks sent again, the executor's request asked again): in lockstep the
  run ends done, everything recycled, the mission within 5 epochs of the undisturbed
  run's (the same run, trace and all, when the kill misses a publication), the
  recording holding every epoch and replaying (`cbdi replay --check`); in real time the
  epochs stall only while it restarts.

Timings are generous bounds, not measurements: these pass on a loaded machine.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from tests_support import CBDI, REPO, free_port, wait_for

pytestmark = pytest.mark.e2e

SERVICES = ("router", "world", "robot1/planner", "robot1/scheduler", "robot1/executor")
STARTED = re.compile(r"started service=(\S+) pid=(\d+)")


def _up(log: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [CBDI, "up", "paper-7x7", "--json", *args],
        stdout=subprocess.PIPE,
        stderr=log.open("w"),
        text=True,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        env={**os.environ, **(env or {})},
        start_new_session=True,
    )


def _started(log: Path) -> dict[str, int]:
    """Return each service's latest pid, from the launcher's log."""
    return {s: int(p) for s, p in STARTED.findall(log.read_text())}


def _gone(pid: int) -> bool:
    """True once `pid` is no process, or a zombie nobody reaped yet."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except (FileNotFoundError, ProcessLookupError):
        return True


def _of_run(port: int) -> list[int]:
    """Return the live processes naming the run's router port (argv or CBDI_CONNECT)."""
    mark = f"127.0.0.1:{port}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                text = f.read()
            with open(f"/proc/{entry}/environ", "rb") as f:
                text += f.read()
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
        if (mark in text or f"--port\0{port}\0".encode() in text) and not _gone(int(entry)):
            found.append(int(entry))
    return found


def _kill_all(pids: list[int]) -> None:
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def test_sigkill_of_cbdi_up_leaves_no_process_behind(tmp_path: Path) -> None:
    port = free_port()
    log = tmp_path / "up.log"
    up = _up(log, "--port", str(port), "--quiet")
    try:
        wait_for(
            lambda: set(_started(log)) == set(SERVICES), timeout=120, what="every service started"
        )
        children = list(_started(log).values())
        assert len(_of_run(port)) >= len(children)  # the run's processes can be found
        up.send_signal(signal.SIGKILL)
        up.wait(10)
        killed = time.monotonic()
        wait_for(
            lambda: all(_gone(p) for p in children) and not _of_run(port),
            timeout=15,
            what=f"the run's processes to stop (left: {_of_run(port)})",
        )
        print(f"no process left {time.monotonic() - killed:.2f} s after SIGKILL of cbdi up")
    finally:
        up.kill()
        _kill_all(_of_run(port))


def test_a_frozen_planner_is_reported_killed_restarted_and_the_run_completes(
    tmp_path: Path,
) -> None:
    log, record = tmp_path / "up.log", tmp_path / "run.mcap"
    # The planner freezes itself (SIGSTOP) at epoch 8, the robot acting by then. The world
    # waits for its ack up to the (shortened) ack timeout; in lockstep the planner is
    # killed at that same limit (30 s: a member starved on a loaded machine is not killed
    # sooner) and its restart joins the next epoch.
    up = _up(
        log,
        "--record",
        str(record),
        "--fault",
        "robot1/planner:stop@8",
        env={"CBDI_ACK_TIMEOUT": "30"},
    )
    try:
        out, _ = up.communicate(timeout=300)
    finally:
        up.kill()
        first = [int(p) for s, p in STARTED.findall(log.read_text()) if s == "robot1/planner"]
        _kill_all(first[:1])  # a stopped process takes no SIGTERM, not even its parent-death one
    text = log.read_text()
    summary = json.loads(out)
    planner = first[0]
    assert "event=fault_injected fault=robot1/planner:stop@8 epoch=8" in text, text[-3000:]
    report = rf"frozen service=robot1/planner pid={planner} silent_for=(\S+) limit=2 action=report"
    found = re.search(report, text)
    assert found, text[-3000:]
    print(f"frozen planner reported after {found.group(1)} s of silence")
    # Reported at the 2 s limit, before the 30 s kill (how long after is the machine's).
    assert float(found.group(1).rstrip("s")) < 30.0, text
    killed = rf"pid={planner} silent_for=\S+ limit=30 action=kill"
    assert re.search(killed, text), text[-3000:]
    assert "restarting service=robot1/planner exit_code=-9 restart=1" in text
    assert up.returncode == 0, text[-3000:]
    assert summary["result"] == "done" and summary["stats"]["litter_recycled"] == 3
    frozen = {s: n for s, n in summary["freezes"].items() if n}
    assert frozen == {"robot1/planner": 1}
    assert {s: n for s, n in summary["freeze_kills"].items() if n} == {"robot1/planner": 1}
    inspected = subprocess.run(
        [CBDI, "inspect", str(record), "--json"], capture_output=True, text=True, cwd=REPO
    )
    assert "cbdi/launcher/health" in inspected.stdout, inspected.stdout[-2000:]
    assert "cbdi/heartbeat/" not in inspected.stdout  # heartbeats are not recorded


UNDISTURBED: dict[str, float] = {}


@pytest.mark.timeout(400)
@pytest.mark.parametrize(
    "service", ["robot1/executor", "robot1/planner", "robot1/scheduler", "router"]
)
def test_a_killed_service_is_restarted_and_the_run_completes_as_undisturbed(
    tmp_path: Path, service: str
) -> None:
    """An agent's service rejoins at the epoch under way; a killed router loses nothing:
    what was published while it was down is recovered from the publishers' caches once
    the sessions are back (Zenoh advanced pub/sub), so no gate waits for it."""
    if not UNDISTURBED:
        plain = _up(tmp_path / "plain.log", "--quiet")
        out, _ = plain.communicate(timeout=300)
        plain_summary = json.loads(out)
        UNDISTURBED.update(sim_time=plain_summary["sim_time"], digest=plain_summary["trace_digest"])
    log = tmp_path / "up.log"
    rec = tmp_path / "run.mcap"
    fault = f"{service}:kill@8"
    up = _up(log, "--record", str(rec), "--fault", fault, env={"CBDI_ACK_TIMEOUT": "60"})
    try:
        out, _ = up.communicate(timeout=300)
    finally:
        up.kill()
    text = log.read_text()
    summary = json.loads(out)
    assert f"event=fault_injected fault={fault} epoch=8" in text, text[-3000:]
    assert f"restarting service={service} exit_code=-9 restart=1" in text
    assert up.returncode == 0 and summary["result"] == "done", text[-3000:]
    assert summary["stats"]["litter_recycled"] == 3
    assert "ack_timeout" not in text and not any(summary["stalls"].values()), text[-3000:]
    assert "upstream_late" not in text, text[-3000:]
    # The fault costs a few epochs, not an ack timeout (60 s here). A restarted agent
    # service plans afresh from where the robot is, which may be better or worse than
    # the plan it lost (seed 1 takes 50 s undisturbed; 12 runs with a service killed at
    # epoch 8 or so took 42 to 55 s). A router restart changes nothing: the run is the
    # undisturbed one, request for request.
    print(service, "mission", summary["sim_time"], "undisturbed", UNDISTURBED["sim_time"])
    # Costs at most 5 epochs (a replan from where the robot is may also save some).
    assert summary["sim_time"] <= UNDISTURBED["sim_time"] + 5.0
    if service == "router":
        assert summary["trace_digest"] == UNDISTURBED["digest"], text[-3000:]
    from cbdi.wire import decode
    from cbdi.wire.world import Tick
    from cbdi_monitor.reader import read_messages

    ticks = [decode(m.payload, Tick).epoch for m in read_messages(rec, ["cbdi/world/clock"])]
    assert ticks == list(range(summary["epochs"] + 1)), ticks  # every epoch, once


def test_a_finished_world_stops_after_lingering(tmp_path: Path, router: str, spawn: object) -> None:
    corridor = str(REPO / "domains/recycling/maps/corridor-6x3.toml")
    world = spawn(
        "world",
        "cbdi-world",
        "--simulator",
        "recycling",
        "--map",
        corridor,
        "--agent",
        "robot1",
        "--speed",
        "20",
        "--max-time",
        "1",
        "--no-stop-when-done",
        "--wait-agents",
        "0",
        "--linger",
        "1",
        env={"CBDI_CONNECT": router},
    )
    wait_for(lambda: not world.alive(), timeout=60, what="the world to stop by itself")
    assert world.popen.returncode == 0
    assert "event=finished reason=time_limit" in world.output()
    assert "event=lingered" in world.output()


@pytest.mark.timeout(300)
def test_a_killed_recorder_keeps_what_it_recorded_and_its_restart_goes_on(
    tmp_path: Path,
) -> None:
    """SIGKILL of the monitor: nothing it recorded is lost (it flushes twice a second and
    the reader takes a file with no footer up to its last record), the restarted monitor
    goes on in the next part (`run-001.mcap`) instead of overwriting, and the readers read
    the parts as one recording. What was published while no monitor ran is recovered from
    the publishers' caches (history), each message once: every epoch is in the file."""
    rec = tmp_path / "run.mcap"
    log = tmp_path / "up.log"
    # At speed 2 the monitor has flushed (every 0.5 wall s) several epochs by epoch 10.
    up = _up(log, "--speed", "2", "--record", str(rec), "--fault", "monitor:kill@10")
    try:
        out, _ = up.communicate(timeout=240)
    finally:
        up.kill()
    text = log.read_text()
    summary = json.loads(out)
    assert "restarting service=monitor exit_code=-9 restart=1" in text
    assert up.returncode == 0 and summary["result"] == "done", text[-3000:]
    assert rec.exists() and (tmp_path / "run-001.mcap").exists()
    from cbdi.wire import decode
    from cbdi.wire.world import Tick
    from cbdi_monitor.reader import read_messages

    def epochs(path: Path) -> list[int]:
        return [decode(m.payload, Tick).epoch for m in read_messages(path, ["cbdi/world/clock"])]

    whole = epochs(rec)
    # The killed recorder's file alone (its part moved aside): epoch 0 on, none missing.
    (tmp_path / "run-001.mcap").rename(tmp_path / "later.mcap")
    before = epochs(rec)
    (tmp_path / "later.mcap").rename(tmp_path / "run-001.mcap")
    assert before[0] == 0 and before == list(range(len(before))) and len(before) >= 5, before
    # The two parts: every epoch of the run, once, in order.
    assert whole == list(range(summary["epochs"] + 1)), whole
    recovered = re.findall(r"event=recorded .*recovered=(\d+) already_recorded=(\d+)", text)
    print("recorded epochs 0 ..", before[-1], "then the rest; recovered, skipped:", recovered)
    assert recovered and int(recovered[-1][0]) > 0, text[-3000:]
    inspected = subprocess.run(
        [CBDI, "inspect", str(rec)], capture_output=True, text=True, timeout=120
    )
    assert inspected.returncode == 0 and "result: done" in inspected.stdout, inspected.stderr


def _ticks(record: Path) -> list[tuple[int, float]]:
    """Each recorded tick's epoch and publication time (wall s), in recorded order."""
    from cbdi.wire import decode
    from cbdi.wire.world import Tick
    from cbdi_monitor.reader import read_messages

    found = read_messages(record, ["cbdi/world/clock"])
    return [(decode(m.payload, Tick).epoch, m.publish_ns / 1e9) for m in found]


def _story(text: str) -> str:
    """What a failed run's log says of what went wrong: its warnings and errors, and the
    agent's last commands and steps (the tail of a log is only the shutdown)."""
    lines = text.splitlines()
    bad = [ln for ln in lines if "level=warning" in ln or "level=error" in ln]
    acts = [ln for ln in lines if "event=command" in ln or "event=step" in ln]
    return "\n".join(["warnings and errors:", *bad[:40], "last commands and steps:", *acts[-40:]])


def _kill_world(tmp_path: Path, *args: str) -> tuple[dict[str, Any], Path, str]:
    """Run paper-7x7 at speed 4, recorded, the world killed at epoch 10 (with `args`,
    more faults); check it went on from there to done, with no stall; return the
    summary, the recording and the launcher's log."""
    log, record = tmp_path / "up.log", tmp_path / "run.mcap"
    up = _up(log, "--speed", "4", "--record", str(record), "--fault", "world:kill@10", *args)
    try:
        out, _ = up.communicate(timeout=300)
    finally:
        up.kill()
    text = log.read_text()
    assert "restarting service=world exit_code=-9 restart=1" in text, text[-3000:]
    recovered = re.search(r"world .*event=recovered state=\S+ epoch=(\d+)", text)
    assert recovered and int(recovered.group(1)) >= 10, text[-3000:]
    summary = json.loads(out)
    assert up.returncode == 0 and summary["result"] == "done", _story(text)
    assert summary["stats"]["litter_recycled"] == 3
    assert "ack_timeout" not in text and not any(summary["stalls"].values()), text[-3000:]
    return summary, record, text


@pytest.mark.timeout(400)
def test_a_killed_world_goes_on_from_its_state_and_the_run_is_the_same(tmp_path: Path) -> None:
    plain = _up(tmp_path / "plain.log", "--speed", "4", "--quiet")
    out, _ = plain.communicate(timeout=300)
    undisturbed = json.loads(out)
    summary, record, text = _kill_world(tmp_path)
    # Virtual time: the restarted world has the same litter, people, robots, generators
    # and pending actions, so the mission is the undisturbed one's (within 5 epochs).
    same = summary["trace_digest"] == undisturbed["trace_digest"]
    print("mission", summary["sim_time"], "undisturbed", undisturbed["sim_time"], "same", same)
    assert abs(summary["sim_time"] - undisturbed["sim_time"]) <= 5.0  # epochs of 1 s
    epochs = [epoch for epoch, _ in _ticks(record)]
    assert sorted(set(epochs)) == list(range(summary["epochs"] + 1)), epochs
    # The recording replays: the acks sent again to the restarted world are not decisions.
    check = [CBDI, "replay", str(record), "--agent", "robot1", "--check"]
    replayed = subprocess.run(check, capture_output=True, text=True, cwd=REPO, timeout=200)
    assert "note: world restarted" in replayed.stdout, replayed.stdout[-2000:]
    # The same run, the same decisions; unless the scheduler sent its first search again
    # at the start (the planner's token came after it), which a replay does not repeat.
    if same and "event=search_resent" not in text:
        assert replayed.returncode == 0 and "same: " in replayed.stdout, replayed.stdout[-2000:]


@pytest.mark.timeout(400)
def test_the_world_and_a_planner_killed_in_one_epoch_go_on_to_done(tmp_path: Path) -> None:
    """Two faults at once: the restarted planner rejoins while the world is restarting
    too; neither waits for an ack the other's restart lost (issue 15's double fault)."""
    summary, record, text = _kill_world(tmp_path, "--fault", "robot1/planner:kill@10")
    assert "event=fault_injected fault=robot1/planner:kill@10 epoch=10" in text, text[-3000:]
    assert "restarting service=robot1/planner exit_code=-9 restart=1" in text
    assert "upstream_late" not in text, text[-3000:]
    epochs = [epoch for epoch, _ in _ticks(record)]
    assert sorted(set(epochs)) == list(range(summary["epochs"] + 1)), epochs


@pytest.mark.timeout(300)
def test_a_killed_world_stalls_a_real_time_run_only_while_it_restarts(tmp_path: Path) -> None:
    summary, record, text = _kill_world(tmp_path, "--no-lockstep")
    ticks = _ticks(record)
    epochs = [e for e, _ in ticks]
    # Every epoch once, but the one the world was killed in: it went out again.
    recovered = re.search(r"world .*event=recovered state=\S+ epoch=(\d+)", text)
    assert recovered is not None
    again = int(recovered.group(1))
    assert sorted(set(epochs)) == list(range(summary["epochs"] + 1)), epochs
    assert all(n == 1 or e == again for e, n in collections.Counter(epochs).items()), epochs
    # The restarted world tells how late it had each epoch of its life out after the one
    # it went on from (wall time: no bound asserted; the figures are printed).
    late = summary["lateness"]
    print("epochs late", late)
    assert late["epochs"] == summary["epochs"] - again and late["bound"] == 0.025
    gaps = [b - a for (_, a), (_, b) in itertools.pairwise(ticks)]
    # The gap is a restart's (about 1 s on an idle machine; `docs/architecture.md` has
    # the figures): a loaded machine may take longer, a world that never went on forever.
    print(f"longest wall gap between epochs {max(gaps):.2f} s (0.25 s each at speed 4)")
    assert max(gaps) < 30.0
