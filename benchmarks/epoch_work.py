"""What each epoch costs the scheduler and the planner service, on any map.

Runs a map's BDI robots with every service shell in one process (`cbdi.runtime.together`,
the in-memory bus, lockstep, flat out) and times, per epoch and agent:

- the scheduler's cycle: belief revision from the world's percepts, the rules, the
  desires and claims, and the beliefs it publishes (`SchedulerService.on_message` on a
  `Percepts`);
- the planner service's per-epoch work outside its search rounds: the beliefs update
  applied, the forecast of the executing plan and what follows from it
  (`OnlinePlannerService.handle` on a `BeliefsUpdate`), on the event loop; and apart,
  the grounding it does ahead in a worker thread (`ContinualPlanner.warm`), most epochs
  none (the task is reused);

as CPU seconds of the event-loop thread (`time.thread_time`, so a search round running in
its worker thread meanwhile is not counted), and the bytes of the belief updates. It
prints the median, the 95th percentile and the maximum over the epochs, and how often the
planner grounded a task against how often it reused one.

    .venv/bin/python benchmarks/epoch_work.py [--map campus-30x30] [--agents 1]
        [--until 60] [--planning-speed 180] [--seed 3]

Virtual time: the run is the same on any machine; the times are this machine's.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import uvloop
from cbdi_recycling.wire import Percepts

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.clock import ManualClock
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire.agent import BeliefsUpdate
from cbdi.wire.common import RunFinished
from cbdi_executor.service import ExecutorSettings, executor_main
from cbdi_planner.agent import online_service as planner_service
from cbdi_planner.agent.continual import ContinualPlanner
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain
from cbdi_scheduler import service as scheduler_service
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from cbdi_world.service import WorldSettings, build_world, world_main

ROOT = Path(__file__).resolve().parents[1]
AGENT_FILE = str(ROOT / "domains/recycling/agents/recycler.toml")

Times = dict[str, list[float]]


def timed(method: Callable[..., Any], kind: type, times: Times, label: str) -> Callable[..., Any]:
    """Wrap an async handler so its calls on a `kind` message are timed (CPU of the loop)."""

    async def wrapper(self: Any, *args: Any) -> Any:
        msg = args[-1]
        if not isinstance(msg, kind):
            return await method(self, *args)
        started = time.thread_time()
        try:
            return await method(self, *args)
        finally:
            times[f"{self.agent} {label}"].append(time.thread_time() - started)

    return wrapper


def agent_services(name: str, planning_speed: float) -> tuple[list[TogetherService], Any]:
    raw = read_agent_file(AGENT_FILE, name)
    domain = parse_domain(raw.domain.read_text(encoding="utf-8"), str(raw.domain))
    planner = PlannerSettings(agent=name, agent_file=AGENT_FILE, planning_speed=planning_speed)
    scheduler = SchedulerSettings(agent=name, agent_file=AGENT_FILE)
    executor = ExecutorSettings(agent=name)
    mind = Mind(load_agent(AGENT_FILE, name))
    return [
        TogetherService(f"{name}/planner", planner, planner_main(planner, domain, raw)),
        TogetherService(f"{name}/scheduler", scheduler, scheduler_main(mind, scheduler)),
        TogetherService(f"{name}/executor", executor, executor_main(executor)),
    ], raw


async def run(args: argparse.Namespace, times: Times, sizes: list[int]) -> RunFinished:
    agents = [f"robot{k + 1}" for k in range(args.agents)]
    members = tuple(f"{a}/{c}" for a in agents for c in ("planner", "scheduler", "executor"))
    settings = WorldSettings(
        simulator="recycling",
        map=str(ROOT / "domains/recycling/maps" / f"{args.map}.toml"),
        agent=tuple(agents),
        speed=0.0,
        lockstep=True,
        seed=args.seed,
        max_time=args.until,
        member=members,
        option=("spawn=0.0",),
    )
    world = TogetherService("world", settings, world_main(build_world(settings), ManualClock()))
    services = [world]
    for a in agents:
        services += agent_services(a, args.planning_speed)[0]
    network = MemoryNetwork()
    together = Together(services, network)
    ended = messages(network.bus(), keys.world_stream("events"), RunFinished, LogSink())
    beliefs = network.bus().subscribe(keys.scheduler_beliefs("*"))

    async def count() -> None:
        async for sample in beliefs:
            sizes.append(len(sample.payload))

    async def watch() -> RunFinished:
        _, finished = await anext(ended)
        together.stop()
        return finished

    counter = asyncio.create_task(count())
    watcher = asyncio.create_task(watch())
    await together.run()
    counter.cancel()
    return await watcher


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--map", default="campus-30x30", help="a map of domains/recycling/maps")
    p.add_argument("--agents", type=int, default=1)
    p.add_argument("--until", type=float, default=60.0, help="simulated seconds to run")
    p.add_argument("--planning-speed", type=float, default=180.0, help="expansions per sim s")
    p.add_argument("--seed", type=int, default=3)
    args = p.parse_args(argv)
    if args.agents < 1 or args.until <= 0 or args.planning_speed <= 0:
        p.error("--agents, --until and --planning-speed must be positive")

    times: Times = defaultdict(list)
    sizes: list[int] = []
    sched, plan = scheduler_service.SchedulerService, planner_service.OnlinePlannerService
    sched.on_message = timed(sched.on_message, Percepts, times, "scheduler cycle")  # type: ignore[method-assign]
    plan.handle = timed(plan.handle, BeliefsUpdate, times, "planner beliefs")  # type: ignore[method-assign]
    warm = ContinualPlanner.warm

    def warm_timed(self: Any, *a: Any) -> None:
        started = time.thread_time()
        try:
            warm(self, *a)
        finally:
            times[f"{self.agent} planner grounding"].append(time.thread_time() - started)

    ContinualPlanner.warm = warm_timed  # type: ignore[method-assign]
    groundings: list[Any] = []
    init = plan.__init__

    def keep(self: Any, *a: Any, **k: Any) -> None:
        init(self, *a, **k)
        groundings.append(self.core.groundings)

    plan.__init__ = keep  # type: ignore[method-assign]
    started = time.perf_counter()
    finished = uvloop.run(run(args, times, sizes))
    wall = time.perf_counter() - started
    print(
        f"{args.map}, {args.agents} agent(s), {finished.epoch} epochs to {finished.time:g} s"
        f" ({finished.reason}), planning speed {args.planning_speed:g}, {wall:.1f} wall s"
    )
    print(f"{'per epoch (CPU ms)':<28}{'epochs':>7}{'median':>9}{'p95':>9}{'max':>9}")
    for label in sorted(times):
        ms = sorted(1000 * t for t in times[label])
        p95 = ms[min(len(ms) - 1, round(0.95 * (len(ms) - 1)))]
        print(f"{label:<28}{len(ms):>7}{statistics.median(ms):>9.2f}{p95:>9.2f}{ms[-1]:>9.2f}")
    if sizes:
        print(
            f"belief updates: {len(sizes)}, bytes median {statistics.median(sizes):.0f},"
            f" max {max(sizes)}, total {sum(sizes)}"
        )
    for k, g in enumerate(groundings):
        print(f"robot{k + 1} planner: grounded {g.grounded} times, reused {g.reused} times")
    return 0


if __name__ == "__main__":
    sys.exit(main())
