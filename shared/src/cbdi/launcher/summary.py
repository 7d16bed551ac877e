"""What `cbdi up` reports of a run (`RunSummary`), and the listeners that fill it in:
each agent's action requests, the world's statistics, the run's end."""

from __future__ import annotations

import asyncio
import bisect
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

from cbdi import keys, tally
from cbdi.bus import request
from cbdi.bus.base import Bus
from cbdi.bus.typed import Stamped
from cbdi.errors import CbdiError
from cbdi.launcher.scenario import Scenario
from cbdi.wire.agent import ActionStatus
from cbdi.wire.world import ActionRequest, StatsRequest, Tick, WorldStats

__all__ = ["ACTS", "RunCounts", "RunSummary", "collect_stats", "counted_keys", "settle"]


@dataclass
class RunSummary:
    """What `cbdi up --json` prints."""

    scenario: str
    result: str = "not_started"
    reason: str = ""
    epochs: int = 0
    sim_time: float = 0.0
    wall_time: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)
    restarts: dict[str, int] = field(default_factory=dict)
    # times a process was judged frozen (silent past --freeze-limit, not starved): reported
    freezes: dict[str, int] = field(default_factory=dict)
    freeze_kills: dict[str, int] = field(default_factory=dict)  # of those, killed (--freeze-kill)
    # times a process's loop stood for want of CPU: reported, not killed (slow, not frozen)
    starved: dict[str, int] = field(default_factory=dict)
    exit_codes: dict[str, list[int]] = field(default_factory=dict)
    planner: dict[str, Any] = field(default_factory=dict)  # PlannerTally.summary()
    # Per agent: `actions` it asked the world for and the simulated time of the first.
    actions: dict[str, dict[str, Any]] = field(default_factory=dict)
    # Per agent: the plan steps its executor started, by action name, whoever performed
    # them (the world or a performer process).
    performed: dict[str, dict[str, int]] = field(default_factory=dict)
    # The world's request trace (cbdi_world.trace): its length and digest. Equal
    # digests, equal runs.
    requests: int = 0
    trace_digest: str = ""
    # Lockstep members that missed an ack timeout (member -> epochs stalled).
    stalls: dict[str, int] = field(default_factory=dict)
    # Paced runs: how late the world had its epochs out, in wall seconds (`EpochLateness`:
    # epochs, median, p95, max, and `over` the `bound` of a tenth of an epoch).
    lateness: dict[str, float | int] | None = None
    # The processes' resident sets, sampled while the run ran (`cbdi.launcher.memory`):
    # the peak of their sum, each service's peak (MB), the number of samples.
    memory: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.result in ("done", "time_limit")


ACTS = keys.trace_request(keys.world_rpc("act"))  # the world mirrors what it serves


def counted_keys(agents: list[str]) -> frozenset[str]:
    """Return the keys `RunCounts` counts for `agents`."""
    per_agent = (
        keys.planner_requests,
        keys.planner_plans,
        keys.planner_rounds,
        keys.planner_forecasts,
        keys.executor_status,
    )
    return frozenset([keys.CLOCK, ACTS, *(key(a) for a in agents for key in per_agent)])


class RunCounts:
    """Count what the agents did: the planners' plans, replans, repairs and rounds
    (`cbdi.tally`), each agent's action requests to the world and the simulated time of
    its first, and the steps its executor started (`running`), by action name, whoever
    performs them.

    The messages are kept as they come and counted at the end (`fold`), in lockstep up to
    what the world says was sent before its last epoch (`RunFinished.sent`): what the
    members do on the last tick, while the run ends, is not the run's, and only a cut by
    sequence numbers, not by arrival, makes the counts repeat. A sender whose numbers on
    a key go back has restarted (as `cbdi.lockstep` tells): the cut is of its last life,
    what its earlier lives sent all counts.
    """

    def __init__(self, planners: tally.PlannerTally) -> None:
        self.planners = planners
        self.samples: list[tuple[int, Stamped]] = []  # (its sender's life, the message)
        self.heard: dict[str, int] = {}  # the last sequence number heard, per key
        self.lives: dict[str, int] = {}  # the life of the key's sender (0: the first)
        self.upto: dict[str, int] = {}  # the cut: RunFinished.sent (empty: none)
        self._news = asyncio.Event()

    async def listen(self, stream: AsyncIterator[Stamped]) -> None:
        """Keep every message of `stream` until cancelled."""
        async for sample in stream:
            key = sample.key
            if sample.seq and sample.seq <= self.heard.get(key, 0):
                self.lives[key] = self.lives.get(key, 0) + 1  # numbered afresh: restarted
            self.heard[key] = sample.seq
            self.samples.append((self.lives.get(key, 0), sample))
            self._news.set()

    def missing(self, sent: dict[str, int], counted: frozenset[str]) -> dict[str, int]:
        """Return, of the `counted` keys in `sent`, those with fewer messages heard."""
        return {k: n for k, n in sent.items() if k in counted and self.heard.get(k, 0) < n}

    async def cover(
        self, sent: dict[str, int], counted: frozenset[str], timeout: float
    ) -> dict[str, int]:
        """Cut the counts at `sent` and wait (`timeout` wall seconds at most) until every
        counted key of it is heard in full: its messages travel on other keys than the
        world's last word and may come after it. Return what is still missing."""
        self.upto = dict(sent)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):
                while self.missing(sent, counted):
                    self._news.clear()
                    await self._news.wait()
        return self.missing(sent, counted)

    def fold(self, summary: RunSummary) -> None:
        """Count the messages kept (up to the cut, if any) into `summary` and the tally."""
        ticks = _TickTimes()
        first: dict[str, tuple[int, float]] = {}  # agent -> (order, arrival time) of its first
        started: set[tuple[str, str]] = set()  # (agent, step id) seen running
        for life, (key, seq, order, msg) in self.samples:
            if self.upto and life == self.lives.get(key, 0) and seq > self.upto.get(key, 0):
                continue  # sent on the last tick, or after
            if isinstance(msg, Tick):
                ticks.tick(order, msg.time)
            elif isinstance(msg, ActionStatus):
                if msg.status == "running" and (msg.agent, msg.step_id) not in started:
                    started.add((msg.agent, msg.step_id))
                    by_name = summary.performed.setdefault(msg.agent, {})
                    by_name[msg.action] = by_name.get(msg.action, 0) + 1
            elif isinstance(msg, ActionRequest):
                agent = summary.actions.setdefault(msg.agent, {"actions": 0, "first_action": None})
                agent["actions"] += 1
                if msg.agent not in first or 0 < order < first[msg.agent][0]:
                    first[msg.agent] = (order, ticks.now)
            else:
                self.planners.observe(key, msg)
        for name, (o, arrived) in first.items():
            summary.actions[name]["first_action"] = ticks.at(o) if o else arrived


class _TickTimes:
    """The simulated time of the world's ticks by the world's publication number
    (`Stamped.order`): the time at which the world served a request it mirrored, whichever
    of the tick and the request arrived first (they travel on two keys)."""

    def __init__(self) -> None:
        self.orders: list[int] = []
        self.times: list[float] = []
        self.now = 0.0  # by arrival, for samples with no publication number

    def tick(self, order: int, time: float) -> None:
        self.now = time
        k = bisect.bisect(self.orders, order)
        self.orders.insert(k, order)
        self.times.insert(k, time)

    def at(self, order: int) -> float:
        """Return the time of the last tick published before `order`."""
        k = bisect.bisect(self.orders, order)
        return self.times[k - 1] if order and k else self.now


def settle(summary: RunSummary, reason: str, scenario: Scenario) -> None:
    if reason == "done":
        summary.result = "done"
    elif reason == "time_limit":
        until_done = scenario.run.until == "done"
        summary.result = "incomplete" if until_done else "time_limit"
        summary.reason = "time limit reached before the world was done" if until_done else ""
    else:
        summary.result = "failed" if reason.startswith("failed") else reason
        summary.reason = reason


# Wall seconds the world has to answer the final stats request, and how often it is
# asked: a world on a loaded machine (16 robots and a test suite on 2 cores) answered
# after more than 2 s, and the summary of a run that ended `done` had no counters.
STATS_TIMEOUT = 10.0
STATS_ATTEMPTS = 3


async def collect_stats(bus: Bus, summary: RunSummary) -> None:
    for _ in range(STATS_ATTEMPTS):
        try:
            stats = await request(
                bus, keys.world_rpc("stats"), StatsRequest(), WorldStats, timeout=STATS_TIMEOUT
            )
        except (CbdiError, TimeoutError):
            continue
        summary.stats = {
            "epoch": stats.epoch,
            "time": stats.time,
            **stats.totals,  # the simulator's own totals, by name
            "agents": {a.agent: _agent_dict(a) for a in stats.agents},
        }
        summary.epochs = summary.epochs or stats.epoch
        summary.sim_time = summary.sim_time or stats.time
        return


def _agent_dict(a: Any) -> dict[str, int | float]:
    """One agent's counters: the simulator's own (`counts`: the grid's moves first), the
    generic ones, busy time."""
    return {**a.counts, "failed": a.failed, "rejected": a.rejected, "busy": a.busy}
