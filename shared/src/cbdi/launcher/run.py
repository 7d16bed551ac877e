"""`cbdi up`: run a scenario as separate OS processes and report how it went.

Order: the router; the monitor when recording; the world; every agent's services. Each
start waits until the service's liveliness token appears (so it is ready), then the run
goes on until the world announces `RunFinished`, a service fails beyond its restart
policy, the wall-clock limit passes, or the user presses Ctrl-C. Everything is stopped in
reverse order. Meanwhile a watchdog hears every service's heartbeat and kills one that
froze (`cbdi.launcher.watch`), to be restarted by policy; and should the launcher die,
even by SIGKILL, its children die with it (`cbdi.runtime.parent`). Before the world
starts, the launcher publishes what it starts and with which arguments (`RunLaunched`),
so that a recording says how to build a service again. The world saves its state every
epoch in the run's own temporary directory (`CBDI_STATE`, removed at the end): killed,
it is restarted by policy and goes on from there (`cbdi_world.recovery`).

Meanwhile it listens to every planner (`cbdi.tally`): the summary's `planner` holds each
BDI agent's plans, replans, forecast-triggered repairs and search rounds, and the total.
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path

from cbdi import keys, tally
from cbdi.bus import BusConfig, LogSink, messages, open_bus, publish
from cbdi.bus.base import Bus
from cbdi.bus.typed import sequenced_inputs
from cbdi.clock import WallClock
from cbdi.errors import CbdiError
from cbdi.launcher.liveness import Watchdog
from cbdi.launcher.memory import MemoryPeaks, watch_memory
from cbdi.launcher.ports import free_port
from cbdi.launcher.process import ManagedProcess, ProcessSpec, RestartPolicy
from cbdi.launcher.scenario import AGENT_KINDS, Scenario, agent_groups
from cbdi.launcher.services import plan_services
from cbdi.launcher.specs import run_specs
from cbdi.launcher.summary import ACTS, RunCounts, RunSummary, collect_stats, counted_keys, settle
from cbdi.launcher.watch import TICK, watch_heartbeats, watch_processes
from cbdi.runtime.parent import NICE_ENV
from cbdi.security import (
    RunSecrets,
    create_secrets,
    grants,
    read_credentials,
    run_dir,
)
from cbdi.security.policy import LAUNCHER
from cbdi.wire.agent import ActionStatus
from cbdi.wire.common import RunFinished, RunLaunched
from cbdi.wire.world import ActionRequest, Tick

__all__ = ["ROUTER_NOT_LISTENING", "LaunchOptions", "RunSummary", "launch"]

# How a run that never started because its router could not take its port is told
# (`run.reason` begins with it): nothing ran, the same run may be tried on another port.
ROUTER_NOT_LISTENING = "our router could not listen on"
# Wall seconds the counters get, once the run ended, to hear the messages it says were
# sent (`RunFinished.sent`): they are on their way, so it takes a moment even when loaded.
COVER_TIMEOUT = 10.0


@dataclass(frozen=True)
class LaunchOptions:
    """Options of `cbdi up` beyond the scenario's own run settings."""

    restart: RestartPolicy = field(default_factory=RestartPolicy)
    port: int = 0
    startup_timeout: float = 30.0
    wall_timeout: float = 0.0
    view: str = "none"
    quiet: bool = False
    record: str = ""
    # Start these services (`robot1/scheduler`) this many wall seconds late: any start
    # order must work (the world's start barrier waits for every member).
    delays: dict[str, float] = field(default_factory=dict)
    # Every service beats every `heartbeat` wall seconds (0: no heartbeats, no watchdog);
    # one silent for `freeze_limit` seconds is frozen: reported; still silent after
    # `freeze_kill` seconds, it is killed and restarted by policy.
    heartbeat: float = 0.5
    freeze_limit: float = 2.0
    freeze_kill: float = 10.0
    # One process per BDI agent running its three services (`cbdi agent`), not three.
    agent_process: bool = False
    # An authenticated bus with access control (docs/security.md): per-run credentials
    # per service, under `run_dir` (default: `cbdi.security.run_dir(port)`).
    secure: bool = True
    run_dir: str = ""
    # Faults to inject (`--fault`, `cbdi.runtime.fault`), as `CBDI_FAULT` says them.
    faults: str = ""
    # The agents' processes run at this niceness (`CBDI_NICE`, 0 to 19) and the shared
    # ones (router, world, monitor) at the launcher's: on a machine with too little CPU
    # for every robot, the bus and the world keep pace and the robots slow down.
    agent_nice: int = 5


def _niced(spec: ProcessSpec, nice: int) -> ProcessSpec:
    """`spec`, told to run at niceness `nice` if it is an agent's (`robot1/agent`,
    `robot1/planner`; not the router, world or monitor)."""
    if nice <= 0 or "/" not in spec.service:
        return spec
    return dataclasses.replace(spec, env={**spec.env, NICE_ENV: str(nice)})


class _Liveliness:
    """Track which service ids are alive, from the liveliness tokens."""

    def __init__(self) -> None:
        self.alive: set[str] = set()
        self.changed = asyncio.Condition()

    async def follow(self, bus: Bus) -> None:
        async for event in bus.watch_alive(keys.ALIVE_ALL):
            service = keys.service_of_alive(event.key)
            async with self.changed:
                (self.alive.add if event.alive else self.alive.discard)(service)
                self.changed.notify_all()

    async def wait_for(self, services: list[str], timeout: float) -> None:
        async with asyncio.timeout(timeout), self.changed:
            await self.changed.wait_for(lambda: all(s in self.alive for s in services))


async def launch(
    scenario: Scenario, opts: LaunchOptions, say: Callable[[str, str], None]
) -> RunSummary:
    """Run `scenario` to its end and return the summary; never leaves a child behind."""
    summary = RunSummary(scenario=scenario.name)
    port = opts.port or free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    secrets = None
    if opts.secure:
        agents = [(a.name, AGENT_KINDS[a.kind]) for a in scenario.agents]
        root = Path(opts.run_dir) if opts.run_dir else run_dir(port)
        secrets = create_secrets(root, grants(agents, agent_groups(scenario)))
        say("launcher", f"security=on credentials={root / 'credentials'}")
    try:
        return await _launch(scenario, opts, say, summary, endpoint, secrets)
    finally:
        if secrets is not None:
            secrets.remove()


async def _launch(
    scenario: Scenario,
    opts: LaunchOptions,
    say: Callable[[str, str], None],
    summary: RunSummary,
    endpoint: str,
    secrets: RunSecrets | None,
) -> RunSummary:
    state_dir, procs = _processes(scenario, opts, say, endpoint, secrets)
    planning = [a.name for a in scenario.agents if "planner" in AGENT_KINDS[a.kind]]
    planners = tally.PlannerTally(planning)
    counts = RunCounts(planners)
    memory = MemoryPeaks()
    started = time.monotonic()
    bus: Bus | None = None
    try:
        async with asyncio.TaskGroup() as tg:
            tg.create_task(watch_memory(procs, memory))
            launched = RunLaunched(
                scenario=scenario.name,
                services={
                    p.service: list(p.args) for p in plan_services(scenario, endpoint, opts.record)
                },
            )
            login = _login(secrets)
            bus, ends = await _start_all(
                procs, endpoint, opts, tg, summary, counts, launched, login
            )
            await _await_end(bus, ends, procs, scenario, opts, tg, summary, counts)
            raise _Done
    except* _Done:
        pass
    except* (TimeoutError, CbdiError) as group:
        summary.result = "failed"
        summary.reason = "; ".join(str(e) or type(e).__name__ for e in group.exceptions)
    finally:
        for proc in procs:  # from now on an exit (the world's linger ends) is no failure
            proc.stopping = True
        if bus is not None:
            await collect_stats(bus, summary)
        for proc in reversed(procs):
            await proc.stop()
        if bus is not None:
            await bus.close()
        shutil.rmtree(state_dir, ignore_errors=True)
    summary.wall_time = round(time.monotonic() - started, 3)
    counts.fold(summary)
    summary.planner = planners.summary()
    summary.memory = memory.summary()
    _fold_processes(procs, summary)
    return summary


def _processes(
    scenario: Scenario,
    opts: LaunchOptions,
    say: Callable[[str, str], None],
    endpoint: str,
    secrets: RunSecrets | None,
) -> tuple[str, list[ManagedProcess]]:
    """Make the run's private folder (0700: the world's state file, each process's stall
    evidence for the watchdog) and its processes, not started; return both."""
    state_dir = tempfile.mkdtemp(prefix="cbdi-run-")  # private (0700): the world's state
    try:
        state = f"{state_dir}/world.state"
        specs = run_specs(
            scenario,
            endpoint,
            opts.record,
            opts.heartbeat,
            opts.agent_process,
            state,
            secrets,
            opts.faults,
        )
    except BaseException:
        shutil.rmtree(state_dir, ignore_errors=True)
        raise
    stalls = f"{state_dir}/stall"  # each process's stall evidence, for the watchdog
    os.makedirs(stalls, exist_ok=True)
    procs = [
        ManagedProcess(_niced(spec, opts.agent_nice), opts.restart, say, f"{stalls}/{k}.heartbeat")
        for k, spec in enumerate(specs)
    ]
    return state_dir, procs


def _fold_processes(procs: list[ManagedProcess], summary: RunSummary) -> None:
    """Put each process's restarts, freezes, starvation and exit codes in the summary."""
    for proc in procs:
        summary.restarts[proc.spec.service] = proc.restarts
        summary.freezes[proc.spec.service] = proc.freezes
        summary.freeze_kills[proc.spec.service] = proc.freeze_kills
        summary.starved[proc.spec.service] = proc.starved
        summary.exit_codes[proc.spec.service] = proc.exit_codes


def _login(secrets: RunSecrets | None) -> tuple[str, str]:
    """The launcher's own user and password ('' without security)."""
    if secrets is None:
        return "", ""
    found = read_credentials(secrets.credentials(LAUNCHER))
    return found.user, found.password


class _Done(Exception):
    """End the launcher's TaskGroup once the run is over."""


async def _start_all(
    procs: list[ManagedProcess],
    endpoint: str,
    opts: LaunchOptions,
    tg: asyncio.TaskGroup,
    summary: RunSummary,
    counts: RunCounts,
    launched: RunLaunched,
    login: tuple[str, str],
) -> tuple[Bus, asyncio.Queue[RunFinished]]:
    summary.result = "starting"
    router, rest = procs[0], procs[1:]
    await router.start()
    tg.create_task(router.supervise())
    await _router_is_ours(router, endpoint, opts)  # before logging in: it may be another's
    user, password = login
    cfg = BusConfig(
        connect=(endpoint,), connect_timeout=opts.startup_timeout, user=user, password=password
    )
    bus = await open_bus(cfg)
    live = _Liveliness()
    tg.create_task(live.follow(bus))
    # The world's last word, heard from before it starts: a short run (`--until 1`) may
    # end before every agent service is seen alive. A task reads it from now on (a
    # subscription nobody iterates is never closed, and keeps the interpreter alive).
    ends: asyncio.Queue[RunFinished] = asyncio.Queue()
    events = messages(bus, keys.world_stream("events"), RunFinished, LogSink())
    tg.create_task(_forward(events, ends))
    # Subscribed before any agent starts, so the tally misses none of their messages.
    tg.create_task(counts.listen(sequenced_inputs(bus, tally.KEYS, tally.MESSAGES, LogSink())))
    acts = [keys.CLOCK, ACTS, keys.executor_status("*")]
    actions = sequenced_inputs(bus, acts, (Tick, ActionRequest, ActionStatus), LogSink())
    tg.create_task(counts.listen(actions))
    if opts.view == "text":  # subscribed now too: it shows what agents intend from the start
        from cbdi.view import text_view

        tg.create_task(text_view(bus, sys.stdout))
    if opts.heartbeat > 0:
        kill_after = max(opts.freeze_kill, opts.freeze_limit)
        dog = Watchdog(opts.freeze_limit, TICK, opts.startup_timeout, kill_after)
        tg.create_task(watch_heartbeats(bus, dog))
        tg.create_task(watch_processes(bus, dog, procs))
    await _wait_alive(live, [router], opts)
    router.sink("launcher", f"router endpoint={endpoint}")  # for `cbdi ctl --connect`
    # One at a time: the monitor (so it misses nothing), the world; then all agent services.
    singles = 2 if opts.record else 1
    for i, group in enumerate([*([p] for p in rest[:singles]), rest[singles:]]):
        if i == singles - 1:  # the monitor (if any) is up, the world not yet: say what runs
            await publish(bus, keys.launcher_stream("run"), launched, block=True)
        late = sorted((_delay(opts, p.spec), i) for i, p in enumerate(group))
        waited = 0.0
        for delay, i in late:
            if delay > waited:
                await asyncio.sleep(delay - waited)
                waited = delay
            await group[i].start()
            tg.create_task(group[i].supervise())
        await _wait_alive(live, group, opts)
    summary.result = "running"
    return bus, ends


def _delay(opts: LaunchOptions, spec: ProcessSpec) -> float:
    """Return how late to start a process: the longest delay asked of what it runs."""
    return max(opts.delays.get(s, 0.0) for s in (spec.service, *spec.members))


async def _forward(
    stream: AsyncIterator[tuple[str, RunFinished]], to: asyncio.Queue[RunFinished]
) -> None:
    async for _, msg in stream:
        to.put_nowait(msg)


async def _router_is_ours(router: ManagedProcess, endpoint: str, opts: LaunchOptions) -> None:
    """Make sure our own router listens: the token `cbdi/alive/router` may be another
    run's whose router took the port first (ours then cannot listen and exits), and our
    services would join that run."""
    clock = WallClock()
    deadline = clock.now() + opts.startup_timeout
    while not any("event=routing" in line for line in router.tail):
        if router.failed.is_set() or clock.now() > deadline:
            tail = " | ".join(router.tail) or "no output"
            raise CbdiError(f"{ROUTER_NOT_LISTENING} {endpoint} (port taken?): {tail}")
        await clock.sleep(0.05)


async def _wait_alive(live: _Liveliness, group: list[ManagedProcess], opts: LaunchOptions) -> None:
    """Wait until every process of `group` is alive; fail early if one gives up."""
    names = [member for p in group for member in p.spec.members]
    alive = asyncio.ensure_future(live.wait_for(names, opts.startup_timeout))
    failures = [asyncio.ensure_future(p.failed.wait()) for p in group]
    try:
        await asyncio.wait([alive, *failures], return_when=asyncio.FIRST_COMPLETED)
    finally:
        for f in failures:
            f.cancel()
    dead = [p for p in group if p.failed.is_set()]
    if dead:
        alive.cancel()
        tail = " | ".join(dead[0].tail) if dead[0].tail else "no output"
        raise CbdiError(
            f"{dead[0].spec.service} exited {dead[0].exit_codes[-1]} while starting: {tail}"
        )
    try:
        alive.result()
    except TimeoutError:
        missing = [n for n in names if n not in live.alive]
        raise CbdiError(
            f"not alive after {opts.startup_timeout:.0f} s: {', '.join(missing)}"
        ) from None


async def _await_end(
    bus: Bus,
    ends: asyncio.Queue[RunFinished],
    procs: list[ManagedProcess],
    scenario: Scenario,
    opts: LaunchOptions,
    tg: asyncio.TaskGroup,
    summary: RunSummary,
    counts: RunCounts,
) -> None:
    ended: asyncio.Future[str] = asyncio.get_running_loop().create_future()
    counted = counted_keys([a.name for a in scenario.agents])

    def end(reason: str) -> None:
        if not ended.done():
            ended.set_result(reason)

    async def finished() -> None:
        while True:
            msg = await ends.get()
            summary.epochs, summary.sim_time = msg.epoch, msg.time
            summary.stalls = dict(sorted(msg.stalls.items()))
            summary.requests, summary.trace_digest = msg.requests, msg.trace_digest
            late = msg.lateness
            summary.lateness = (
                {f: getattr(late, f) for f in late.__struct_fields__} if late else None
            )
            missing = await counts.cover(msg.sent, counted, COVER_TIMEOUT)
            if missing:
                procs[0].sink("launcher", f"counted short at the end: {missing}")
            end(msg.reason)

    async def failure(proc: ManagedProcess) -> None:
        await proc.failed.wait()
        end(f"failed: {proc.spec.service} exited {proc.exit_codes[-1]} and was not restarted")

    watchers = [tg.create_task(finished())] + [tg.create_task(failure(p)) for p in procs]
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, end, "interrupted")
    try:
        async with asyncio.timeout(opts.wall_timeout or None):
            reason = await ended
    except TimeoutError:
        reason = f"failed: wall-clock limit of {opts.wall_timeout:.0f} s reached"
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        for w in watchers:
            w.cancel()
    settle(summary, reason, scenario)
