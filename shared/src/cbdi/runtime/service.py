"""The service runtime: every cbdi service is `run_service(settings, component, main)`.

It runs on uvloop, opens the bus, lets `main` declare its subscriptions and start its
tasks in the one TaskGroup, then declares the service's liveliness token (so "alive"
means "ready to receive") and starts its heartbeat (so a frozen loop shows), reports bad
input on the service's error stream, and shuts down cleanly on SIGTERM/SIGINT, closing
the bus in any case. Started by a supervisor, it also stops when that one dies
(`cbdi.runtime.parent`).
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import itertools
import math
import os
import signal
import threading
import time
import traceback
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from dataclasses import dataclass, field
from typing import Any

import uvloop

from cbdi import keys
from cbdi.bus.base import Bus
from cbdi.bus.typed import messages
from cbdi.bus.zenoh_bus import DEFAULT_ENDPOINT, BusConfig, open_bus
from cbdi.clock import Clock, WallClock
from cbdi.errors import CbdiError
from cbdi.runtime.fault import Fault, parse_faults, planned_fault, strike
from cbdi.runtime.life import end_cleanly
from cbdi.runtime.log import Log
from cbdi.runtime.parent import ParentGuard, guard_parent, take_niceness
from cbdi.runtime.stall import LoopTurns, Stalled, watch_loop
from cbdi.security.secrets import read_credentials, read_zenoh_settings
from cbdi.wire.base import encode
from cbdi.wire.common import ErrorReport, Heartbeat
from cbdi.wire.world import Tick

__all__ = ["Hosted", "ServiceContext", "ServiceSettings", "run_service", "run_services"]

MAX_PENDING_REPORTS = 1000  # error reports waiting to be published
MARK = 0.1  # s between turns of the stall watcher's marker, at most (heartbeat / 2 if less)


@dataclass(frozen=True)
class ServiceSettings:
    """Settings every service takes (flags `--connect`, `--mode`, ... or `CBDI_*`)."""

    connect: tuple[str, ...] = field(
        default=(DEFAULT_ENDPOINT,), metadata={"help": "Zenoh endpoint(s) to connect to"}
    )
    mode: str = field(default="client", metadata={"help": "Zenoh mode: client or peer"})
    listen: tuple[str, ...] = field(default=(), metadata={"help": "endpoints to listen on"})
    connect_timeout: float = field(default=10.0, metadata={"help": "seconds to wait for a router"})
    log_level: str = field(default="info", metadata={"help": "debug, info, warning or error"})
    log_format: str = field(default="kv", metadata={"help": "kv or json"})
    heartbeat: float = field(
        default=0.5, metadata={"help": "wall seconds between heartbeats (0: none)"}
    )
    stall_limit: float = field(
        default=1.0,
        metadata={
            "help": "wall seconds the event loop may stand before its log names the code "
            "that keeps it (loop_stalled, loop_resumed; 0: not watched)"
        },
    )
    credentials: str = field(
        default="",
        metadata={"help": "file with this service's Zenoh user and password (docs/security.md)"},
    )
    zenoh_config: str = field(
        default="",
        metadata={"help": 'JSON file of more Zenoh settings, {"path/of/key": value} (TLS)'},
    )
    fault: tuple[str, ...] = field(
        default=(),
        metadata={
            "help": "faults to inject, SERVICE:KIND@EPOCH (kill or stop, e.g. world:kill@12); "
            "the ones naming this service strike in its first life (cbdi.runtime.fault)"
        },
    )

    def bus_config(self) -> BusConfig:
        """Return the bus part of these settings (ConfigError: unreadable credentials)."""
        user = password = ""
        if self.credentials:
            found = read_credentials(self.credentials)
            user, password = found.user, found.password
        return BusConfig(
            mode=self.mode,
            connect=tuple(self.connect),
            listen=tuple(self.listen),
            connect_timeout=self.connect_timeout,
            extra=read_zenoh_settings(self.zenoh_config) if self.zenoh_config else {},
            user=user,
            password=password,
        )


class _Stop(Exception):
    """Raised inside the TaskGroup to end the service cleanly."""


class ServiceContext:
    """What a service body gets: the bus, the log, the TaskGroup and an error sink."""

    def __init__(self, service: str, bus: Bus, log: Log, settings: Any = None) -> None:
        self.service = service
        self.settings = settings
        self.bus = bus
        self.log = log
        self.counters: collections.Counter[str] = collections.Counter()
        self.turns: LoopTurns | None = None  # the loop's turns (`Heartbeat.held`, `late`)
        self.exit_code = 0
        self._tg: asyncio.TaskGroup | None = None
        self._stopping = asyncio.Event()
        # Bounded: a flood of bad input costs counted, dropped reports, not memory.
        self._reports: asyncio.Queue[ErrorReport] = asyncio.Queue(MAX_PENDING_REPORTS)

    def start(self, coro: Coroutine[Any, Any, Any], name: str | None = None) -> asyncio.Task[Any]:
        """Run `coro` as a task of the service's TaskGroup."""
        if self._tg is None:
            raise RuntimeError("the service is not running")
        return self._tg.create_task(coro, name=name)

    def stop(self, exit_code: int = 0) -> None:
        """Ask the service to end: every task is cancelled, the bus closed."""
        self.exit_code = exit_code
        self._stopping.set()

    # ErrorSink: bad input is logged, counted and reported; the service goes on.
    def bad_input(self, key: str, error: CbdiError) -> None:
        code = getattr(error, "code", type(error).__name__)
        self.counters[f"bad_input.{code}"] += 1
        sender = getattr(error, "sender", "") or "unknown"
        self.log.warning("bad_input", key=key, sender=sender, code=code, error=str(error))
        self._report(key, str(code), str(error))

    def crashed(self, key: str, error: Exception) -> None:
        self.counters["handler_crash"] += 1
        self.log.error(
            "handler_crash", key=key, error=repr(error), trace=traceback.format_exc(limit=5)
        )
        self._report(key, "internal", repr(error))

    def _report(self, key: str, code: str, message: str) -> None:
        total = sum(v for k, v in self.counters.items() if k.startswith("bad_input"))
        report = ErrorReport(service=self.service, key=key, code=code, message=message, count=total)
        try:
            self._reports.put_nowait(report)
        except asyncio.QueueFull:
            self.counters["error_reports_dropped"] += 1

    async def _publish_reports(self) -> None:
        while True:
            report = await self._reports.get()
            await self.bus.publish(keys.errors(self.service), encode(report))

    async def _flush_reports(self) -> None:
        while not self._reports.empty():
            await self.bus.publish(keys.errors(self.service), encode(self._reports.get_nowait()))

    async def _until_stopped(self) -> None:
        await self._stopping.wait()
        raise _Stop


ServiceMain = Callable[[ServiceContext], Awaitable[None]]


def run_service(settings: ServiceSettings, service: str, main: ServiceMain) -> int:
    """Run a service to completion on uvloop and return its exit code."""
    return run_services([Hosted(service, settings, main)])


@dataclass(frozen=True)
class Hosted:
    """One service of a process: its id (`robot1/planner`), settings and body."""

    service: str
    settings: Any
    main: ServiceMain


def run_services(services: Sequence[Hosted]) -> int:
    """Run services in one process on one uvloop loop, each on its own bus session with
    its own liveliness token and heartbeat, until SIGTERM/SIGINT or until one of them
    ends (then the others are stopped too: the process is their unit of restart).

    Return the first non-zero exit code of any, else 0.
    """
    guard = guard_parent()
    take_niceness()  # an agent's process yields the CPU to the bus and the world
    logs = []
    for s in services:
        try:
            logs.append(Log(s.service, level=s.settings.log_level, fmt=s.settings.log_format))
            beat = s.settings.heartbeat
            if not (math.isfinite(beat) and beat >= 0):
                raise ValueError(f"heartbeat must be a finite number >= 0, got {beat}")
            parse_faults(s.settings.fault)
            stall = s.settings.stall_limit
            if not (math.isfinite(stall) and stall >= 0):
                raise ValueError(f"stall_limit must be a finite number >= 0, got {stall}")
        except ValueError as exc:
            print(f"{s.service}: bad settings: {exc}")
            return 2
    if guard.orphaned:  # the supervisor died before the guard was set: no signal will come
        logs[0].warning("orphaned", parent=guard.parent)
        return 1
    code = uvloop.run(_run(services, logs, guard))
    if code == 0:
        end_cleanly()
    return code


async def _run(services: Sequence[Hosted], logs: Sequence[Log], guard: ParentGuard) -> int:
    contexts: list[ServiceContext] = []
    try:
        for s, log in zip(services, logs, strict=True):
            try:
                await _credentials_made(s.settings, log)
                bus = await open_bus(s.settings.bus_config())
            except CbdiError as exc:
                log.error("bus_open_failed", error=str(exc))
                return 2
            contexts.append(ServiceContext(s.service, bus, log, s.settings))
    finally:
        if len(contexts) < len(services):
            for ctx in contexts:
                await ctx.bus.close()
    loop = asyncio.get_running_loop()

    def stop() -> None:
        guard.stop_hard_later()  # first: nothing below may keep an orphan alive
        for ctx in contexts:
            ctx.stop(ctx.exit_code)
        if guard.orphaned:
            logs[0].warning("orphaned", parent=guard.parent, grace=guard.grace)

    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop)
    limit, beat = services[0].settings.stall_limit, services[0].settings.heartbeat
    watch = None
    if limit:
        pulse = _stall_pulse(contexts) if beat > 0 else None
        turns = LoopTurns()
        for ctx in contexts:
            ctx.turns = turns
        watcher = watch_loop(
            logs[0],
            limit,
            period=min(MARK, beat / 2) if beat > 0 else MARK,
            pulse=pulse,
            every=beat or None,
            sending=lambda: any(ctx.bus.sending > 0 for ctx in contexts),
            turns=turns,
        )
        watch = loop.create_task(watcher, name="stall-watch")
    try:
        async with asyncio.TaskGroup() as tg:
            for ctx, s in zip(contexts, services, strict=True):
                tg.create_task(_host(ctx, s.main, contexts), name=ctx.service)
    finally:
        if watch is not None:
            watch.cancel()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)
    return next((ctx.exit_code for ctx in contexts if ctx.exit_code), 0)


def _stall_pulse(contexts: Sequence[ServiceContext]) -> Callable[[Stalled], None]:
    """Send each service's heartbeat with the evidence of a stall, from the watcher's
    thread: the watchdog hears the process while its loop stands (see `Heartbeat`).

    Under `cbdi up` (`CBDI_STALL_FILE`) the evidence also goes to a file beside the
    launcher: a congested network drops heartbeats (they are best effort), and a loop
    that waits in a send for room on it is exactly the one to hear about."""
    pid = os.getpid()
    path = os.environ.get("CBDI_STALL_FILE", "")
    sender: list[threading.Thread] = []  # the send under way, if any

    def send(stall: Stalled) -> None:
        for ctx in contexts:
            beat = _stall_beat(ctx.service, pid, stall)
            ctx.bus.pulse(keys.heartbeat(ctx.service), encode(beat))

    def pulse(stall: Stalled) -> None:
        if path:
            _leave(path, _stall_beat(contexts[0].service, pid, stall))
        # Sent from a thread of its own, one at a time: on a congested network the send
        # itself may wait, and the watcher must go on watching (and writing its file).
        if sender and sender[0].is_alive():
            return
        thread = threading.Thread(target=send, args=(stall,), name="stall-pulse", daemon=True)
        sender[:] = [thread]
        thread.start()

    return pulse


def _stall_beat(service: str, pid: int, stall: Stalled) -> Heartbeat:
    return Heartbeat(
        service=service,
        pid=pid,
        beat=0,
        stalled_for=stall.silent_for,
        loop_cpu=stall.loop_cpu,
        wanted=None if stall.wanted is None else min(stall.wanted, 4096.0),
        sending=stall.sending,
    )


def _leave(path: str, beat: Heartbeat) -> None:
    """Write `beat` to `path` whole (a reader never sees half of it); best effort."""
    try:
        with open(f"{path}.tmp", "wb") as f:
            f.write(encode(beat))
        os.replace(f"{path}.tmp", path)
    except OSError:
        pass  # the launcher's directory went (the run ends): nobody reads it


async def _credentials_made(settings: ServiceSettings, log: Log) -> None:
    """Wait, as long as for the router, for a credentials file not there yet: in a
    compose run the router makes them as it starts, beside its peers (an absent file
    after that is refused by `bus_config`, naming it)."""
    path = settings.credentials
    if not path or os.path.exists(path):
        return
    log.info("waiting_for_credentials", path=path, timeout=settings.connect_timeout)
    clock = WallClock()
    deadline = clock.now() + settings.connect_timeout
    while not os.path.exists(path) and clock.now() < deadline:
        await clock.sleep(0.2)


async def _host(ctx: ServiceContext, main: ServiceMain, others: Sequence[ServiceContext]) -> None:
    """Run one service of the process to its end, then stop the rest of the process."""
    bus, log = ctx.bus, ctx.log
    try:
        await _supervise(ctx, main, ctx.settings.heartbeat)
    except* CbdiError as group:
        for err in group.exceptions:
            log.error("service_failed", error=str(err))
        ctx.exit_code = ctx.exit_code or 1
    finally:
        for other in others:
            if other is not ctx:
                other.stop(other.exit_code)
        await ctx._flush_reports()
        await bus.close()
    for key, count in sorted(bus.sent.items()):
        if not keys.is_heartbeat(key):  # not recorded: counted in `stopped` instead
            log.info("sent", key=key, count=count)
    log.info("stopped", exit_code=ctx.exit_code, **_counter_fields(ctx))


async def _supervise(ctx: ServiceContext, main: ServiceMain, heartbeat: float = 0.0) -> None:
    """Run `main` in the service's TaskGroup until stopped; beat every `heartbeat` s."""
    try:
        async with asyncio.TaskGroup() as tg:
            ctx._tg = tg
            tg.create_task(ctx._until_stopped(), name="stop")
            tg.create_task(ctx._publish_reports(), name="error-reports")
            await main(ctx)
            # Let freshly started tasks reach their first await (subscriptions exist
            # from the call that created them); then tell the world we are ready.
            await asyncio.sleep(0)
            await ctx.bus.declare_token(keys.alive(ctx.service))
            ctx.log.info("ready", alive=keys.alive(ctx.service))
            if heartbeat > 0:
                tg.create_task(_beat(ctx, heartbeat, WallClock()), name="heartbeat")
            fault = planned_fault(ctx.service, parse_faults(ctx.settings.fault))
            if fault is not None:
                tg.create_task(fault_at_epoch(ctx, fault), name="fault")
    except* _Stop:
        pass


async def fault_at_epoch(
    ctx: ServiceContext, fault: Fault, act: Callable[[Fault], None] = strike
) -> None:
    """Strike `fault` once the world's tick of its epoch (or a later one) reaches us."""
    ctx.log.info("fault_planned", fault=str(fault))
    async for _, tick in messages(ctx.bus, keys.world_stream("clock"), Tick, ctx):
        if tick.epoch >= fault.epoch:
            ctx.log.warning("fault_injected", fault=str(fault), epoch=tick.epoch)
            act(fault)
            return


async def _beat(ctx: ServiceContext, period: float, clock: Clock) -> None:
    """Send a heartbeat every `period` s while this loop turns (dropped under congestion:
    a late one is worth nothing)."""
    pid, key = os.getpid(), keys.heartbeat(ctx.service)
    last = time.monotonic()
    for beat in itertools.count():
        now = time.monotonic()
        held, late = ctx.turns.worst(last) if ctx.turns is not None else (0.0, 0.0)
        last = now
        msg = Heartbeat(service=ctx.service, pid=pid, beat=beat, held=held, late=late)
        await ctx.bus.publish(key, encode(msg))
        ctx.counters["heartbeats"] += 1
        await clock.sleep(period)


def _counter_fields(ctx: ServiceContext) -> dict[str, int]:
    return {k.replace(".", "_"): v for k, v in sorted(ctx.counters.items())}


def settings_fields(settings: Any) -> dict[str, Any]:
    """Return settings as a plain dict (for the `started` log line)."""
    return dataclasses.asdict(settings)
