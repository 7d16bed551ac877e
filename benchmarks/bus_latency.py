"""Bus overhead against raw Zenoh, measured in the same run through the same router.

Prints the median and p90 of one-way pub/sub latency and request/reply round trip, for
raw zenoh-python (callbacks and a blocking get) and for cbdi's `Bus` (asyncio bridge),
and the ratio of medians (target: at most 1.5x raw).

    .venv/bin/python benchmarks/bus_latency.py [--n 2000]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import uvloop
import zenoh

from cbdi.bus import BusConfig, open_bus
from cbdi.bus.zenoh_bus import zenoh_config


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _router(endpoint: str) -> subprocess.Popen[bytes]:
    exe = Path(sys.executable).parent / "cbdi"
    proc = subprocess.Popen([str(exe), "router", "--listen", endpoint, "--log-level", "warning"])
    time.sleep(1.5)
    return proc


def _stats(samples: list[float]) -> tuple[float, float]:
    s = sorted(samples)
    return statistics.median(s) * 1e6, s[int(len(s) * 0.9)] * 1e6


def raw_pubsub(endpoint: str, n: int) -> list[float]:
    cfg = zenoh_config(BusConfig(connect=(endpoint,)))
    a, b = zenoh.open(cfg), zenoh.open(cfg)
    got = threading.Event()
    lat: list[float] = []

    def on_sample(s: zenoh.Sample) -> None:
        lat.append(time.perf_counter() - float(s.payload.to_string()))
        got.set()

    sub = b.declare_subscriber("bench/raw", on_sample)
    time.sleep(0.3)
    for _ in range(n):
        got.clear()
        a.put("bench/raw", str(time.perf_counter()))
        got.wait(2)
    sub.undeclare()
    a.close()
    b.close()
    return lat


def raw_rpc(endpoint: str, n: int) -> list[float]:
    cfg = zenoh_config(BusConfig(connect=(endpoint,)))
    a, b = zenoh.open(cfg), zenoh.open(cfg)

    def on_query(q: zenoh.Query) -> None:
        q.reply(q.key_expr, q.payload.to_bytes() if q.payload else b"")

    qbl = b.declare_queryable("bench/raw/rpc", on_query)
    time.sleep(0.3)
    lat = []
    for _ in range(n):
        t0 = time.perf_counter()
        for reply in a.get("bench/raw/rpc", payload=b"x" * 32):
            _ = reply.ok
        lat.append(time.perf_counter() - t0)
    qbl.undeclare()
    a.close()
    b.close()
    return lat


async def bus_pubsub(endpoint: str, n: int) -> list[float]:
    cfg = BusConfig(connect=(endpoint,))
    a, b = await open_bus(cfg), await open_bus(cfg)
    sub = b.subscribe("bench/bus")
    it = aiter(sub)
    await asyncio.sleep(0.3)
    lat = []
    for _ in range(n):
        await a.publish("bench/bus", str(time.perf_counter()).encode())
        sample = await it.__anext__()
        lat.append(time.perf_counter() - float(sample.payload))
    await a.close()
    await b.close()
    return lat


async def bus_rpc(endpoint: str, n: int) -> list[float]:
    cfg = BusConfig(connect=(endpoint,))
    a, b = await open_bus(cfg), await open_bus(cfg)

    async def echo(key: str, payload: bytes) -> bytes:
        return payload

    server = asyncio.create_task(b.serve("bench/bus/rpc", echo))
    await asyncio.sleep(0.3)
    lat = []
    for _ in range(n):
        t0 = time.perf_counter()
        await a.request("bench/bus/rpc", b"x" * 32)
        lat.append(time.perf_counter() - t0)
    server.cancel()
    await a.close()
    await b.close()
    return lat


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=2000)
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{_port()}"
    router = _router(endpoint)
    try:
        rows = [
            (
                "one-way pub/sub",
                raw_pubsub(endpoint, args.n),
                uvloop.run(bus_pubsub(endpoint, args.n)),
            ),
            ("request/reply", raw_rpc(endpoint, args.n), uvloop.run(bus_rpc(endpoint, args.n))),
        ]
    finally:
        router.send_signal(signal.SIGTERM)
        router.wait(10)
    print(
        f"bus latency, {args.n} messages each, via a cbdi router on loopback "
        f"({os.cpu_count()} cores)"
    )
    print(f"{'':18}{'raw med us':>12}{'raw p90':>10}{'bus med us':>12}{'bus p90':>10}{'ratio':>8}")
    for name, raw, bus in rows:
        rm, r9 = _stats(raw)
        bm, b9 = _stats(bus)
        verdict = "ok" if bm / rm <= 1.5 else "over target"
        print(f"{name:18}{rm:12.1f}{r9:10.1f}{bm:12.1f}{b9:10.1f}{bm / rm:7.2f}x  {verdict}")


if __name__ == "__main__":
    main()
