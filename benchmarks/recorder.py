"""The monitor's sustained recording rate with no loss, and the file size per message.

A publisher sends small messages (a 40-byte EpochAck) at a set rate through a `cbdi
router` to a real `cbdi-monitor` process; after each run the MCAP file is read back and
counted. Target: at least 50,000 messages/s with no loss.

    .venv/bin/python benchmarks/recorder.py [--count 100000] [--rates 25000,50000,100000]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import uvloop

from cbdi.bus import BusConfig, open_bus
from cbdi.wire import encode
from cbdi.wire.world import EpochAck
from cbdi_monitor.reader import read_messages

BIN = Path(sys.executable).parent
KEY = "cbdi/robot1/executor/ack"


def _endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


async def _publish(endpoint: str, count: int, rate: float) -> float:
    bus = await open_bus(BusConfig(connect=(endpoint,)))
    payload = encode(EpochAck(agent="robot1", epoch=1))
    try:
        await asyncio.sleep(0.5)
        start = time.perf_counter()
        batch = 500
        for i in range(0, count, batch):
            for _ in range(min(batch, count - i)):
                await bus.publish(KEY, payload, block=True)
            due = start + (i + batch) / rate
            delay = due - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
        elapsed = time.perf_counter() - start
        await asyncio.sleep(0.5)
        return count / elapsed
    finally:
        await bus.close()


def one_run(count: int, rate: float, folder: Path) -> tuple[float, int, float]:
    endpoint = _endpoint()
    out = folder / f"bench-{int(rate)}.mcap"
    quiet = ["--log-level", "warning"]
    router = subprocess.Popen([str(BIN / "cbdi"), "router", "--listen", endpoint, *quiet])
    time.sleep(1.0)
    monitor = subprocess.Popen(
        [str(BIN / "cbdi-monitor"), "--output", str(out), "--connect", endpoint, *quiet]
    )
    try:
        time.sleep(1.5)
        achieved = uvloop.run(_publish(endpoint, count, rate))
        time.sleep(1.0)
    finally:
        for proc in (monitor, router):
            proc.send_signal(signal.SIGTERM)
            proc.wait(30)
    got = sum(1 for m in read_messages(out, [KEY]))
    return achieved, count - got, out.stat().st_size / max(1, got)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=100_000)
    parser.add_argument("--rates", default="25000,50000,100000")
    args = parser.parse_args()
    print(f"recorder: {args.count} EpochAck messages per run ({os.cpu_count()} cores)")
    print(f"{'target/s':>10}{'sent/s':>10}{'lost':>8}{'bytes/msg':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for rate in (float(r) for r in args.rates.split(",")):
            achieved, lost, size = one_run(args.count, rate, Path(tmp))
            print(f"{rate:10.0f}{achieved:10.0f}{lost:8d}{size:11.1f}")


if __name__ == "__main__":
    main()
