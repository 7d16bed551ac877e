"""`cbdi replay run.mcap`: republish a recording on Zenoh with its original timing.

Every recorded publication goes out again on its key with its payload unchanged, spaced
as it was recorded (divided by `--speed`; `--speed 0` sends as fast as possible).
Liveliness changes are not replayed (they were tokens, not publications).

`cbdi replay run.mcap --agent robot1 --check` instead feeds one agent's recorded inputs
to its planner and scheduler, rebuilt in this process, and checks that they decide as
they did (`cbdi_monitor.check`). Exit codes: 0 the same, 1 a difference (named), 2 bad
usage or a file that cannot be replayed.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import uvloop
import zenoh

from cbdi import keys as cbdi_keys
from cbdi.bus.zenoh_bus import open_bus
from cbdi.clock import Clock, WallClock
from cbdi.errors import CbdiError, ConfigError
from cbdi.runtime import ServiceSettings, load_config
from cbdi.runtime.together import TogetherService
from cbdi_monitor.check import load_shells, reenact, report
from cbdi_monitor.difference import compare
from cbdi_monitor.reader import RecordedMessage, read_messages
from cbdi_monitor.reenact import AgentScript, script_of

__all__ = ["ReplaySettings", "main", "replay"]


@dataclass(frozen=True)
class ReplaySettings(ServiceSettings):
    """Settings of `cbdi replay`."""

    file: str = field(default="", metadata={"help": "the MCAP recording"})
    speed: float = field(default=1.0, metadata={"help": "time factor; 0 = as fast as possible"})
    keys: str = field(default=cbdi_keys.ALL, metadata={"help": "replay only keys matching EXPR"})
    check: bool = field(
        default=False,
        metadata={"help": "replay --agent's inputs in this process and compare its decisions"},
    )
    agent: str = field(default="", metadata={"help": "with --check: the agent to replay"})
    agent_file: str = field(
        default="",
        metadata={"help": "with --check: the agent file (the one the launcher recorded if empty)"},
    )
    timeout: float = field(
        default=60.0,
        metadata={"help": "with --check: wall seconds to wait for one epoch's ack"},
    )


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


def prepare_check(settings: ReplaySettings) -> tuple[AgentScript, list[TogetherService]]:
    """Read the recording and build the agent's planner and scheduler, saying how.

    Raise CbdiError (or a shell's ValueError) on bad usage or a file that cannot be
    replayed: `main` exits 2 with it.
    """
    if not settings.agent:
        raise ConfigError("command line", "agent", "--check needs the agent: --agent NAME")
    if settings.timeout <= 0:
        raise ConfigError("command line", "timeout", "must be > 0")
    records = list(read_messages(settings.file))
    script = script_of(records, settings.agent, settings.file)
    services, sources = load_shells(script, settings.agent_file, settings.file)
    for line in sources:
        print(f"replaying {line}", flush=True)
    return script, services


def run_check(script: AgentScript, services: list[TogetherService], timeout: float) -> int:
    """Replay, compare and report: exit 0 if the same, 1 if not (or the replay stalled)."""
    started = time.monotonic()
    replayed = uvloop.run(reenact(script, services, timeout))
    verdict = compare(script.outputs, replayed.outputs)
    for line in report(script, verdict, replayed, time.monotonic() - started):
        print(line)
    ok = verdict.same and not replayed.stalled and not any(replayed.exit_codes.values())
    return 0 if ok else 1


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
        if settings.check:
            checked = prepare_check(settings)
        elif settings.agent or settings.agent_file:
            raise ConfigError("command line", "agent", "--agent and --agent-file go with --check")
        else:
            started = time.monotonic()
            sent = uvloop.run(replay(settings))
    except (CbdiError, ValueError) as exc:  # ValueError: a shell's bad agent name
        print(f"cbdi replay: {exc}", file=sys.stderr)
        return 2
    if settings.check:
        return run_check(*checked, settings.timeout)
    print(f"replayed {sent} messages in {time.monotonic() - started:.1f} s", file=sys.stderr)
    return 0
