"""Fixtures shared by the test suites: real routers and service processes for e2e tests."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests_support import BIN, Proc, free_port


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[object]:
    """Start processes that are stopped (SIGTERM, then SIGKILL) when the test ends."""
    procs: list[Proc] = []

    def start(name: str, *argv: str, env: dict[str, str] | None = None) -> Proc:
        exe = str(BIN / argv[0]) if (BIN / argv[0]).exists() else argv[0]
        proc = Proc([exe, *argv[1:]], tmp_path / f"{name}.log", env)
        procs.append(proc)
        return proc

    yield start
    for proc in reversed(procs):
        proc.stop()


@pytest.fixture
def router(spawn: object) -> Iterator[str]:
    """A real `cbdi router` on a free loopback port; yields its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = spawn("router", "cbdi", "router", "--listen", endpoint)  # type: ignore[operator]
    deadline = time.monotonic() + 15
    while "event=ready" not in proc.output():
        assert proc.alive(), proc.output()
        assert time.monotonic() < deadline, "router did not come up"
        time.sleep(0.05)
    yield endpoint
