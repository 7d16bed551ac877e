"""World epochs per second on the 15x15 warehouse with 8 agents, not waiting for agents.

Three figures (target: at least 1000 epochs/s):
- core: `World.step()` alone (with percepts, snapshot and pymunk bodies), agents moving;
- service: a real `cbdi-world` process at `--speed 0` publishing every epoch's tick,
  percepts (8), snapshot and statistics over Zenoh through a `cbdi router`, timed by a
  subscriber from the first tick to `RunFinished`;
- the same, saving its state file every epoch (`--state`, as under `cbdi up`).

    .venv/bin/python benchmarks/world_epochs.py [--epochs 3000]
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import uvloop
from cbdi_recycling.maps import load_map
from cbdi_recycling.world import AgentSpec, World

from cbdi import keys
from cbdi.bus import BusConfig, LogSink, messages, open_bus
from cbdi.wire.common import RunFinished
from cbdi.wire.world import ActionRequest, Tick

MAP = Path(__file__).resolve().parents[1] / "domains/recycling/maps/warehouse-15x15.toml"
BIN = Path(sys.executable).parent


def core(epochs: int) -> float:
    m = load_map(MAP)
    specs = [AgentSpec(f"robot{i + 1}", c, 2) for i, c in enumerate(m.agent_starts[:8])]
    w = World(m, specs, seed=1)
    start = time.perf_counter()
    for e in range(epochs):
        for s in specs:  # every idle robot steps down or up its column
            a = w.agents[s.name]
            if a.action is None:
                x, y = a.cell
                target = (x, y + 1) if (e // 2) % 2 == 0 else (x, y - 1)
                w.request(
                    ActionRequest(agent=s.name, action="move", request_id=str(e), target=target)
                )
        w.step()
    return epochs / (time.perf_counter() - start)


async def _follow(endpoint: str, ready: asyncio.Event) -> tuple[int, float]:
    bus = await open_bus(BusConfig(connect=(endpoint,)))
    try:
        ticks = messages(bus, keys.world_stream("clock"), Tick, LogSink())
        done = messages(bus, keys.world_stream("events"), RunFinished, LogSink())
        ready.set()
        _, first = await anext(ticks)
        t0 = time.perf_counter()
        _, end = await asyncio.wait_for(anext(done), 120)
        return end.epoch - first.epoch, time.perf_counter() - t0
    finally:
        await bus.close()


async def service(epochs: int, state: str = "") -> float:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    router = subprocess.Popen(
        [str(BIN / "cbdi"), "router", "--listen", endpoint, "--log-level", "warning"]
    )
    world = None
    try:
        await asyncio.sleep(1.0)
        ready = asyncio.Event()
        follower = asyncio.create_task(_follow(endpoint, ready))
        await ready.wait()
        await asyncio.sleep(0.3)
        agents = [a for i in range(8) for a in ("--agent", f"robot{i + 1}")]
        world = subprocess.Popen(
            [
                str(BIN / "cbdi-world"),
                "--simulator",
                "recycling",
                "--map",
                str(MAP),
                *agents,
                "--speed",
                "0",
                "--wait-agents",
                "0",
                "--max-time",
                str(epochs),
                "--no-stop-when-done",
                "--connect",
                endpoint,
                "--log-level",
                "warning",
                *(["--state", state] if state else []),
            ]
        )
        count, seconds = await follower
        return count / seconds
    finally:
        for proc in (world, router):
            if proc is not None:
                proc.send_signal(signal.SIGTERM)
                proc.wait(10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--epochs", type=int, default=3000)
    args = parser.parse_args()
    c = core(args.epochs)
    s = uvloop.run(service(args.epochs))
    with tempfile.TemporaryDirectory() as tmp:
        kept = uvloop.run(service(args.epochs, f"{tmp}/world.state"))
    print(f"world epochs/s, warehouse-15x15, 8 agents, {args.epochs} epochs (target >= 1000)")
    print(f"  core (World.step, agents moving):            {c:8.0f}")
    print(f"  service over Zenoh (speed 0, not waiting):   {s:8.0f}")
    print(f"  the same, saving its state every epoch:      {kept:8.0f}")


if __name__ == "__main__":
    main()
