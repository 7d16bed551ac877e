"""Fixtures shared by the test suites: real routers and service processes for e2e tests."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from cbdi.launcher.ports import PORTS_ENV
from tests_support import BIN, Proc, free_port

# Each test worker (pytest-xdist: gw0, gw1, ...) takes ports from a range of its own,
# below the kernel's ephemeral ports (32768 on): its routers (the tests' and every `cbdi
# up` it starts, which inherits the variable) cannot collide with another worker's, nor
# with an outgoing connection's source port.
_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)
_SPAN = 1500
os.environ.setdefault(PORTS_ENV, f"{20000 + _WORKER * _SPAN}-{20000 + (_WORKER + 1) * _SPAN - 1}")


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


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Start the container tests first (`--dist loadfile`: one worker runs the file, one
    image build): the build is the suite's longest step, and runs beside the other
    worker's tests."""
    items.sort(key=lambda item: item.path.name != "test_containers.py")
