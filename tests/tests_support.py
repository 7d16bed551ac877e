"""Helpers for tests that run real processes, or services on the memory bus (importable
as `tests_support`)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from cbdi.launcher.ports import free_port as _free_port
from cbdi.wire.world import WorldInfo

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def free_port() -> int:
    """A free loopback port in this test worker's own range (`CBDI_PORTS`, set by
    conftest): never one another worker or an outgoing connection can take meanwhile."""
    return _free_port()


class Proc:
    """A service process started by a test; its output goes to a log file for diagnosis."""

    def __init__(self, argv: list[str], log: Path, env: dict[str, str] | None = None) -> None:
        self.argv = argv
        self.log_path = log
        self._log = log.open("w")
        self.popen = subprocess.Popen(
            argv,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env={**os.environ, **(env or {})},
            cwd=REPO,
            start_new_session=True,  # its own process group: stop() reaches its children too
        )

    def alive(self) -> bool:
        return self.popen.poll() is None

    def output(self) -> str:
        self._log.flush()
        return self.log_path.read_text()

    def stop(self, timeout: float = 10.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        with contextlib.suppress(ProcessLookupError):  # children left by wrapper scripts
            os.killpg(self.popen.pid, signal.SIGKILL)
        self._log.close()
        return self.popen.returncode


def wait_for(predicate: object, timeout: float = 90.0, what: str = "condition") -> None:
    """Poll `predicate` until true or fail the test after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


async def settle(turns: int = 20) -> None:
    """Let the loop's other tasks run until they wait: `turns` passes, no wall-clock time.

    For code on the memory bus, which delivers at once: there a sleep only ever meant
    "after what is ready has run", and a loaded machine cannot make this one too short.
    """
    for _ in range(turns):
        await asyncio.sleep(0)


CBDI = str(BIN / "cbdi") if (BIN / "cbdi").exists() else "cbdi"


def cbdi_up(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run `cbdi up ARGS` from the repository; return what it printed and its exit code."""
    return subprocess.run(
        [CBDI, "up", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
    )


@contextlib.contextmanager
def cpu_load(burners: int = 2) -> Iterator[None]:
    """Keep `burners` processes spinning on the CPU (both cores of these machines) while
    the block runs: results that hang on how busy the machine is show up here."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", "while True: pass"],
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        for _ in range(burners)
    ]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def grid_info(
    width: int,
    height: int,
    walls: list[tuple[int, int]] | None = None,
    bins: dict[str, tuple[int, int]] | None = None,
    agents: tuple[str, ...] = ("robot1",),
    map_name: str = "m",
    **rest: Any,
) -> WorldInfo:
    """A recycling grid's `WorldInfo` (its `GridMap` in `map`, its drawing in `view`):
    capacity 3, sensing depth 1, epochs of 1 s; `rest` are more `WorldInfo` fields."""
    from cbdi_recycling.wire import BinView, GridMap, with_map

    grid = GridMap(
        width=width,
        height=height,
        walls=sorted(walls or []),
        bins=[BinView(name=n, cell=c) for n, c in (bins or {}).items()],
        capacity=3,
        detection_depth=dict.fromkeys(agents, 1),
    )
    info = WorldInfo(
        map_name=map_name,
        agents=list(agents),
        epoch_duration=1.0,
        durations={},
        **rest,
    )
    return with_map(info, grid)
