"""Running Table I: one `cbdi up --json` process per task, `jobs` at a time.

Every run gets a router port no other run of this harness holds at the same time:
`cbdi up --port 0` picks a port that was free a moment ago, and two runs started together
can pick the same one; the second router then fails, and its world and robot join the
first run's router, silently corrupting both runs (seen on this machine). A run past
its wall limit is killed with its whole process group (router, world, agents).
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TextIO

from table1_model import Run, Task, run_from_summary, summary_of, with_reason

from cbdi.agentfile import PlanningSettings
from cbdi.launcher.run import ROUTER_NOT_LISTENING

__all__ = [
    "CBDI",
    "PortPool",
    "Progress",
    "UpOptions",
    "agent_planning_speed",
    "check_planning_speeds",
    "execute",
    "run_all",
    "run_task",
    "stop_all",
    "up_argv",
    "up_supports",
]

CBDI = str(Path(sys.executable).parent / "cbdi")
REALTIME_ARGS = ("--speed", "1", "--no-lockstep")
GRACE = 30.0  # seconds past `cbdi up --timeout` before the harness kills the group
PORT_TRIES = 3  # runs of a task whose router could not take its port, at most

Runner = Callable[[Task], Run]


@dataclass(frozen=True)
class UpOptions:
    """How every `cbdi up` of a table is called beyond its task."""

    scenario: str = "paper-7x7"
    up_args: tuple[str, ...] = ()
    default_speed: float | None = None  # the agent file's planning_speed
    pass_speed: bool = False  # `cbdi up` has --planning-speed and the default is known
    run_timeout: float = 900.0  # wall seconds per run (`cbdi up --timeout`)
    lockstep_speed: float | None = None  # --speed of lockstep runs (None: the scenario's)


def agent_planning_speed(agent_file: Path | None) -> float | None:
    """Return the agent's planning speed (expansions per simulated second), if it has one.

    The agent file's `[planning] planning_speed` when it sets one, else the default the
    agent-file reader fills in (`PlanningSettings`), which is what the planner then uses.
    """
    if agent_file is None or not agent_file.is_file():
        return None
    with agent_file.open("rb") as handle:
        value = tomllib.load(handle).get("planning", {}).get("planning_speed")
    if isinstance(value, int | float):
        return float(value)
    default = getattr(PlanningSettings(), "planning_speed", None)
    return float(default) if isinstance(default, int | float) else None


def up_supports(flag: str) -> bool:
    """Tell whether `cbdi up --help` lists `flag` (asked once per table)."""
    done = subprocess.run([CBDI, "up", "--help"], capture_output=True, text=True, timeout=60)
    return re.search(re.escape(flag) + r"(?![\w-])", done.stdout) is not None


def check_planning_speeds(factors: Sequence[float], default: float | None, supported: bool) -> str:
    """Return why the factors cannot be run ("" if they can).

    Factor 1 runs as the agent file says even without the flag; any other factor needs
    both `cbdi up --planning-speed` and the agent file's default to scale.
    """
    other = [f for f in factors if f != 1]
    if not other:
        return ""
    if not supported:
        return "`cbdi up` has no --planning-speed flag yet: run with --planning-speeds 1"
    if default is None:
        return (
            "the agent file has no [planning] planning_speed to scale: run with --planning-speeds 1"
        )
    return ""


def planning_speed_of(task: Task, options: UpOptions) -> float | None:
    """Return the absolute --planning-speed of a task (None: leave the agent's own)."""
    if not options.pass_speed or options.default_speed is None:
        return None
    return task.factor * options.default_speed


def up_argv(task: Task, options: UpOptions, port: int) -> list[str]:
    """Build the `cbdi up` command of a task (pass-through arguments before the clock's)."""
    s = task.situation
    argv = [CBDI, "up", options.scenario, "--json", "--quiet", "--mode", task.mode]
    argv += ["--seed", str(task.seed), "--option", f"move_step={s.move_step}"]
    argv += ["--option", f"det_area={s.det_area}", "--option", f"known_litter={s.known_litter}"]
    argv += ["--port", str(port), "--timeout", f"{options.run_timeout:g}"]
    speed = planning_speed_of(task, options)
    if speed is not None:
        argv += ["--planning-speed", f"{speed:g}"]
    if task.clock == "lockstep" and options.lockstep_speed is not None:
        argv += ["--speed", f"{options.lockstep_speed:g}"]
    argv += list(options.up_args)
    if task.clock == "realtime":
        argv += list(REALTIME_ARGS)  # last, so a pass-through --speed cannot undo it
    return argv


def execute(argv: Sequence[str], limit: float) -> tuple[int, str, str, float]:
    """Run a command in its own process group; kill the group after `limit` seconds.

    Return (exit code, -9 if killed; stdout; stderr; wall seconds).
    """
    started = time.monotonic()
    proc = subprocess.Popen(
        list(argv),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # Ctrl-C reaches the harness only: it stops the groups
    )
    with _LIVE_LOCK:
        _LIVE.add(proc)
    try:
        out, err = proc.communicate(timeout=limit)
        return proc.returncode, out, err, time.monotonic() - started
    except subprocess.TimeoutExpired:
        _kill_group(proc)
        out, err = proc.communicate()
        return -9, out or "", err or "", time.monotonic() - started
    finally:
        with _LIVE_LOCK:
            _LIVE.discard(proc)


_LIVE: set[subprocess.Popen[str]] = set()
_LIVE_LOCK = threading.Lock()


def stop_all() -> None:
    """Stop the process group of every command still running (on Ctrl-C)."""
    with _LIVE_LOCK:
        live = list(_LIVE)
    for proc in live:
        _kill_group(proc)


def _kill_group(proc: subprocess.Popen[str]) -> None:
    for sig, wait in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 10.0)):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


class PortPool:
    """Hand out loopback ports that are free now and held by no other run of ours."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: set[int] = set()

    @contextlib.contextmanager
    def lease(self) -> Iterator[int]:
        """Hold a port for the length of a run."""
        with self._lock:
            port = self._fresh()
            self._held.add(port)
        try:
            yield port
        finally:
            with self._lock:
                self._held.discard(port)

    def _fresh(self) -> int:
        for _ in range(100):
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                port = int(s.getsockname()[1])
            if port not in self._held:
                return port
        raise RuntimeError("no free loopback port not already held")


def run_task(task: Task, options: UpOptions, ports: PortPool) -> Run:
    """Run one task with `cbdi up --json`; a run without a summary says why.

    A run whose router could not take its port (another program on the machine took it
    between the lease and the bind) never started: it runs again on another port, up
    to `PORT_TRIES` times."""
    for _ in range(PORT_TRIES):
        run = _run_once(task, options, ports)
        if not run.reason.startswith(ROUTER_NOT_LISTENING):
            break
    return run


def _run_once(task: Task, options: UpOptions, ports: PortPool) -> Run:
    with ports.lease() as port:
        argv = up_argv(task, options, port)
        code, out, err, wall = execute(argv, options.run_timeout + GRACE)
    given = Run(
        task,
        "no_summary",
        exit=code,
        planning_speed=planning_speed_of(task, options),
        speed=1.0 if task.clock == "realtime" else options.lockstep_speed,
        up_args=shlex.join(options.up_args),
        wall=round(wall, 3),
    )
    summary = summary_of(out)
    if summary is None:
        tail = " | ".join(err.strip().splitlines()[-3:])
        result = "killed" if code == -9 else "no_summary"
        return with_reason(replace(given, result=result), f"exit {code}: {tail}")
    run = run_from_summary(given, summary)
    return with_reason(run, run.reason) if run.reason else run


class Progress:
    """A progress bar with ETA on stderr (a line per step when stderr is not a terminal)."""

    def __init__(
        self,
        total: int,
        title: str,
        stream: TextIO = sys.stderr,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.total, self.title, self.stream, self.clock = total, title, stream, clock
        self.done = 0
        self.started = clock()
        self.tty = stream.isatty()

    def step(self, text: str) -> None:
        """Count one finished task and redraw."""
        self.done += 1
        elapsed = self.clock() - self.started
        eta = elapsed / self.done * (self.total - self.done)
        width = 24
        filled = width * self.done // max(self.total, 1)
        bar = "#" * filled + "." * (width - filled)
        line = (
            f"{self.title} [{bar}] {self.done}/{self.total} "
            f"{_clock(elapsed)} elapsed, ETA {_clock(eta)}  {text}"
        )
        if self.tty:
            columns = shutil.get_terminal_size().columns
            self.stream.write("\r\x1b[2K" + line[: columns - 1])
            if self.done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    s = int(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def run_all(
    tasks: Sequence[Task], runner: Runner, jobs: int, progress: Progress | None = None
) -> list[Run]:
    """Run the tasks `jobs` at a time; return their runs sorted as the tables read."""
    runs: list[Run] = []
    pool = ThreadPoolExecutor(max_workers=jobs)
    try:
        futures = [pool.submit(runner, t) for t in tasks]
        for future in as_completed(futures):
            run = future.result()
            runs.append(run)
            if progress is not None:
                moves = f"{run.moves} moves" if run.moves is not None else ""
                progress.step(f"{run.task.describe()}: {run.result} {moves}".rstrip())
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        stop_all()
        raise
    pool.shutdown()
    return sorted(runs, key=lambda r: r.task.sort_key())
