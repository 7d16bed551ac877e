"""`cbdi replay run.mcap`: republish a recording on Zenoh with its original timing.

Every recorded publication goes out again on its key with its payload unchanged, spaced
as it was recorded (divided by `--speed`; `--speed 0` sends as fast as possible).
Liveliness changes are not replayed (they were tokens, not publications).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import uvloop
import zenoh

from cbdi.bus.zenoh_bus import open_bus
from cbdi.clock import Clock, WallClock
from cbdi.errors import CbdiError, ConfigError
from cbdi.runtime import ServiceSettings, load_config
from cbdi_monitor.reader import RecordedMessage, read_messages

__all__ = ["ReplaySettings", "main", "replay"]


@dataclass(frozen=True)
class ReplaySettings(ServiceSettings):
    """Settings of `cbdi replay`."""

    file: str = field(default="", metadata={"help": "the MCAP recording"})
    speed: float = field(default=1.0, metadata={"help": "time factor; 0 = as fast as possible"})
    keys: str = field(default="cbdi/**", metadata={"help": "replay only keys matching EXPR"})


def selected(messages: Iterable[RecordedMessage], expr: str) -> list[RecordedMessage]:
    """Keep the publications whose key matches `expr` (liveliness records are not)."""
    try:
        ke = zenoh.KeyExpr(expr)
    except zenoh.ZError as exc:
        raise ConfigError("command line", "keys", f"bad key expression {expr!r}: {exc}") from None
    out = []
    for m in messages:
        if m.schema == "cbdi.Liveliness/1":
            continue
        if ke.intersects(zenoh.KeyExpr(m.key)):
            out.append(m)
    return out


async def replay(settings: ReplaySettings, clock: Clock | None = None) -> int:
    """Publish the selected messages; return how many were sent."""
    clock = clock or WallClock()
    messages = selected(read_messages(settings.file), settings.keys)
    bus = await open_bus(settings.bus_config())
    try:
        start = clock.now()
        first = messages[0].log_ns if messages else 0
        for m in messages:
            if settings.speed > 0:
                await clock.sleep_until(start + (m.log_ns - first) / 1e9 / settings.speed)
            await bus.publish(m.key, m.payload, block=True)
        await clock.sleep(0.2)  # let the last publications leave before the session closes
        return len(messages)
    finally:
        await bus.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi replay`."""
    try:
        settings = load_config(
            ReplaySettings,
            argv,
            prog="cbdi replay",
            section="replay",
            description=__doc__ or "",
            positional=("file",),
        )
        if not settings.file:
            raise ConfigError("command line", "file", "give the MCAP file to replay")
        if settings.speed < 0:
            raise ConfigError("command line", "speed", "must be >= 0")
        started = time.monotonic()
        sent = uvloop.run(replay(settings))
    except CbdiError as exc:
        print(f"cbdi replay: {exc}", file=sys.stderr)
        return 2
    print(f"replayed {sent} messages in {time.monotonic() - started:.1f} s", file=sys.stderr)
    return 0
