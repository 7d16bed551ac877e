"""`cbdi wait`: wait for the world's end of run and exit with the run's result.

A compose file's `wait` service (`cbdi compose`), so that `docker-compose up
--exit-code-from wait` returns what `cbdi up` would: 0 the run ended as asked (the world
done, or the time of a timed run), 3 the time limit came first, 1 it never ended
(stopped, or `--timeout` wall seconds passed). The world keeps running after its end,
so this service is the first to exit and the others are stopped after it.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.bus import messages, request
from cbdi.errors import CbdiError
from cbdi.runtime import ServiceContext, ServiceSettings, load_config, run_service
from cbdi.wire.common import RunFinished
from cbdi.wire.world import StatsRequest, WorldStats

__all__ = ["WaitSettings", "exit_code", "main"]

EXIT_OK, EXIT_FAILED, EXIT_INCOMPLETE = 0, 1, 3
UNTIL = ("done", "time_limit")


@dataclass(frozen=True)
class WaitSettings(ServiceSettings):
    """Settings of `cbdi wait` (flags or `CBDI_*` environment)."""

    until: str = field(
        default="done",
        metadata={"help": "the end that succeeds: done (the world's goals met) or time_limit"},
    )
    timeout: float = field(default=0.0, metadata={"help": "wall seconds at most (0: no limit)"})


def exit_code(reason: str, until: str) -> int:
    """Return the exit code of a run that ended for `reason` when `until` was asked."""
    if reason == until:
        return EXIT_OK
    return EXIT_INCOMPLETE if reason == "time_limit" else EXIT_FAILED


async def _wait(ctx: ServiceContext) -> None:
    settings: WaitSettings = ctx.settings
    if settings.until not in UNTIL:
        raise CbdiError(f"--until must be one of {', '.join(UNTIL)}, got {settings.until!r}")
    result = [EXIT_FAILED]  # stopped before the end: the run failed
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):  # keep the result (the runtime would say 0)
        loop.add_signal_handler(sig, lambda: ctx.stop(result[0]))
    ctx.start(_follow(ctx, settings, result), name="wait")


async def _follow(ctx: ServiceContext, settings: WaitSettings, result: list[int]) -> None:
    try:
        async with asyncio.timeout(settings.timeout or None):
            finished = await anext(messages(ctx.bus, keys.world_stream("events"), RunFinished, ctx))
    except TimeoutError:
        ctx.log.error("no_end", timeout=settings.timeout)
        ctx.stop(EXIT_FAILED)
        return
    _, end = finished
    result[0] = exit_code(end.reason, settings.until)
    ctx.log.info("run_finished", reason=end.reason, epoch=end.epoch, time=end.time, exit=result[0])
    try:
        stats = await request(
            ctx.bus, keys.world_rpc("stats"), StatsRequest(), WorldStats, timeout=5.0
        )
    except (CbdiError, TimeoutError) as exc:
        ctx.log.warning("no_stats", error=str(exc))
    else:
        per_agent = {
            f"{a.agent}_{name}": count for a in stats.agents for name, count in a.counts.items()
        }
        ctx.log.info("stats", done=stats.done, **stats.totals, **per_agent)
    ctx.stop(result[0])


def main(argv: Sequence[str] | None = None) -> int:
    """Wait for the run's end; return 0 when it ended as asked."""
    settings = load_config(
        WaitSettings,
        argv,
        prog="cbdi wait",
        section="wait",
        description="Wait for the world's end of run and exit with its result: 0 as asked, "
        "3 the time limit came before the world was done, 1 no end seen.",
    )
    return run_service(settings, "wait", _wait)
