"""The monitor service: record everything on `cbdi/**` and every liveliness change.

Zenoh subscribers see publications only, so requests and replies reach the file through
the trace keys every typed request endpoint publishes on. Services appearing and
disappearing are logged, recorded and announced on `cbdi/monitor/health`. Heartbeats
(`cbdi/heartbeat/**`) are not recorded: wall-clock noise, two a second per service,
that a replay would only republish; the launcher's verdicts on them
(`ServiceFrozen` on `cbdi/launcher/health`) are.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.bus.base import AliveEvent, Sample, Subscription
from cbdi.runtime import ServiceContext, ServiceSettings
from cbdi.runtime.service import ServiceMain
from cbdi.wire.base import encode
from cbdi.wire.common import Liveliness, ServiceHealth
from cbdi_monitor.recorder import McapRecorder, Rotation
from cbdi_monitor.resume import Recorded, recorded_before

__all__ = ["MonitorSettings", "monitor_main"]

ALL = keys.ALL
DRAIN_LIMIT = 30.0  # seconds a stopping monitor may spend writing its backlog
# A restarted recorder asks the publishers' caches a second time this long after it
# began, and takes what they send for CATCH_UP_LIMIT s: the first history a subscription
# gets can lack a publisher's samples (seen once in CI: two ticks sent while no recorder
# ran were missing while the ticks after them were there), and a sample missing before
# the first one delivered is never asked for again.
CATCH_UP_AFTER = 3.0
CATCH_UP_LIMIT = 10.0


@dataclass(frozen=True)
class MonitorSettings(ServiceSettings):
    """Settings of `cbdi-monitor`."""

    output: str = field(default="run.mcap", metadata={"help": "MCAP file to write"})
    rotate_mb: float = field(default=0.0, metadata={"help": "start a new file every N MB"})
    rotate_seconds: float = field(default=0.0, metadata={"help": "new file every N seconds"})
    drain: float = field(default=0.3, metadata={"help": "seconds to drain in-flight at stop"})
    flush_every: float = field(
        default=0.5, metadata={"help": "write what was recorded every N wall s (0: at chunks)"}
    )
    restart: int = field(
        default=0,
        metadata={
            "help": "restarts so far (cbdi up sets CBDI_RESTART): above 0 the recording goes "
            "on in its next part instead of replacing the file"
        },
    )


class Monitor:
    """Glue between the bus and one `McapRecorder`."""

    def __init__(
        self,
        ctx: ServiceContext,
        recorder: McapRecorder,
        drain: float,
        before: Recorded | None = None,
    ) -> None:
        self.ctx, self.recorder, self.drain = ctx, recorder, drain
        self.alive: set[str] = set()
        # A restart: what the earlier parts hold, and when this recorder began (samples
        # sent before are history, logged at their publish time, in their place).
        self.before = before
        self.began_ns = time.time_ns()
        # (key, sent_ns, seq) of every sample this part took from history: the catch-up
        # writes only what is in neither this set nor the earlier parts.
        self.recovered: set[tuple[str, int, int]] = set()

    async def record(self, sub: Subscription) -> None:
        """Write every sample; on stop, drain what is still arriving, then finish the file."""
        it = aiter(sub)
        try:
            while True:
                self.write(await anext(it))
        except asyncio.CancelledError:
            await self.drain_rest(it)
            raise
        finally:
            self.recorder.close()
            self.ctx.log.info(
                "recorded",
                files=",".join(map(str, self.recorder.files)),
                messages=sum(self.recorder.counts.values()),
                garbage_dropped=sum(self.recorder.dropped.values()),
                recovered=self.ctx.counters["recovered"],
                already_recorded=self.before.skipped if self.before else 0,
            )

    async def flush(self, every: float) -> None:
        """Write what was recorded every `every` wall seconds: a recorder killed outright
        loses no more than that (its file is read up to its last record)."""
        while not self.recorder.closed:
            await asyncio.sleep(every)
            self.recorder.flush()

    async def catch_up(self, after: float, limit: float) -> None:
        """After `after` s, subscribe with history once more for `limit` s and write what
        was sent before this recorder began and is still missing (`write` skips the
        rest); log how many that was."""
        await asyncio.sleep(after)
        sub = self.ctx.bus.subscribe(ALL, history=True)
        before = self.ctx.counters["recovered"]
        try:
            async with asyncio.timeout(limit):
                async for sample in sub:
                    if 0 < sample.sent_ns < self.began_ns and not keys.is_heartbeat(sample.key):
                        self.write(sample)
        except TimeoutError:
            pass
        finally:
            await sub.close()
        caught = self.ctx.counters["recovered"] - before
        self.ctx.counters["caught_up"] += caught
        (self.ctx.log.warning if caught else self.ctx.log.info)("caught_up", samples=caught)

    async def drain_rest(self, it: object) -> None:
        """Write what is queued or still arriving until `drain` s pass with nothing new."""
        try:
            async with asyncio.timeout(DRAIN_LIMIT):
                while True:
                    sample = await asyncio.wait_for(anext(it), self.drain)  # type: ignore[call-overload]
                    self.write(sample)
        except (TimeoutError, StopAsyncIteration):
            pass

    def write(self, sample: Sample) -> None:
        if keys.is_heartbeat(sample.key):
            return
        log_ns = time.time_ns()
        if self.before is not None and 0 < sample.sent_ns < self.began_ns:
            mark = (sample.key, sample.sent_ns, sample.seq)
            if mark in self.recovered or self.before.has(*mark):
                return
            self.recovered.add(mark)
            log_ns = sample.sent_ns  # recovered: sent while no recorder ran
            self.ctx.counters["recovered"] += 1
        written = self.recorder.write(
            sample.key, sample.payload, log_ns, sample.sent_ns, sample.seq
        )
        if not written and not self.recorder.closed:
            dropped = sum(self.recorder.dropped.values())
            self.ctx.counters["garbage_dropped"] = dropped
            if _sampled(dropped):
                self.ctx.log.warning("garbage_dropped", key=sample.key, dropped=dropped)

    async def health(self, events: object) -> None:
        async for event in events:  # type: ignore[attr-defined]
            await self.on_alive(event)

    async def on_alive(self, event: AliveEvent) -> None:
        service = keys.service_of_alive(event.key)
        (self.alive.add if event.alive else self.alive.discard)(service)
        self.recorder.write(
            event.key, encode(Liveliness(key=event.key, alive=event.alive)), time.time_ns()
        )
        log = self.ctx.log.info if event.alive else self.ctx.log.warning
        log("service_up" if event.alive else "service_down", service=service)
        health = ServiceHealth(service=service, alive=event.alive, alive_now=sorted(self.alive))
        await self.ctx.bus.publish(keys.monitor_stream("health"), encode(health), block=True)


def _sampled(n: int) -> bool:
    """Log the 1st, 10th, 100th, ... drop: a flood costs a few log lines, not one each."""
    return n > 0 and 10 ** (len(str(n)) - 1) == n


def monitor_main(settings: MonitorSettings) -> ServiceMain:
    """Return the service body of the monitor."""

    async def body(ctx: ServiceContext) -> None:
        rotation = Rotation(
            max_bytes=int(settings.rotate_mb * 1e6), max_seconds=settings.rotate_seconds
        )
        resume = settings.restart > 0
        before = None
        if resume:  # subscribe first: what is sent while the parts are read waits
            sub = ctx.bus.subscribe(ALL, history=True)
            before, why = recorded_before(settings.output)
            if why:
                ctx.log.warning("earlier_parts_unreadable", output=settings.output, reason=why)
        else:
            sub = ctx.bus.subscribe(ALL)
        recorder = McapRecorder(settings.output, rotation, resume=resume)
        monitor = Monitor(ctx, recorder, settings.drain, before)
        ctx.start(monitor.record(sub), name="record")
        if settings.flush_every > 0:
            ctx.start(monitor.flush(settings.flush_every), name="flush")
        ctx.start(monitor.health(ctx.bus.watch_alive(keys.ALIVE_ALL)), name="health")
        if resume:
            ctx.start(monitor.catch_up(CATCH_UP_AFTER, CATCH_UP_LIMIT), name="catch_up")
        ctx.log.info(
            "recording",
            output=settings.output,
            resume=resume,
            recorded_before=len(before.latest) if before else 0,
        )

    return body
