"""What `cbdi up` reports of a run (`RunSummary`), and the listeners that fill it in:
each agent's action requests, the world's statistics, the run's end."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

from cbdi import keys, tally
from cbdi.bus import request
from cbdi.bus.base import Bus
from cbdi.errors import CbdiError
from cbdi.launcher.scenario import Scenario
from cbdi.wire.agent import ActionStatus
from cbdi.wire.base import Message
from cbdi.wire.world import ActionRequest, StatsRequest, Tick, WorldStats

__all__ = ["RunSummary", "collect_stats", "count_actions", "count_plans", "settle"]


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


async def count_plans(
    stream: AsyncIterator[tuple[str, Message]], planners: tally.PlannerTally
) -> None:
    """Count the planners' plans, replans, repairs and rounds as they are published."""
    async for key, msg in stream:
        planners.observe(key, msg)


async def count_actions(stream: AsyncIterator[tuple[str, Message]], summary: RunSummary) -> None:
    """Count each agent's action requests to the world and note the simulated time of its
    first; and the steps its executor started (`running`), by action name, whoever
    performs them."""
    now = 0.0
    started: set[tuple[str, str]] = set()  # (agent, step id) seen running
    async for _, msg in stream:
        if isinstance(msg, Tick):
            now = msg.time
        elif isinstance(msg, ActionStatus):
            if msg.status == "running" and (msg.agent, msg.step_id) not in started:
                started.add((msg.agent, msg.step_id))
                by_name = summary.performed.setdefault(msg.agent, {})
                by_name[msg.action] = by_name.get(msg.action, 0) + 1
        elif isinstance(msg, ActionRequest):
            agent = summary.actions.setdefault(msg.agent, {"actions": 0, "first_action": None})
            agent["actions"] += 1
            if agent["first_action"] is None:
                agent["first_action"] = now


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


async def collect_stats(bus: Bus, summary: RunSummary) -> None:
    with contextlib.suppress(CbdiError, TimeoutError):
        stats = await request(bus, keys.world_rpc("stats"), StatsRequest(), WorldStats, timeout=2.0)
        summary.stats = {
            "epoch": stats.epoch,
            "time": stats.time,
            **stats.totals,  # the simulator's own totals, by name
            "agents": {a.agent: _agent_dict(a) for a in stats.agents},
        }
        summary.epochs = summary.epochs or stats.epoch
        summary.sim_time = summary.sim_time or stats.time


def _agent_dict(a: Any) -> dict[str, int | float]:
    """One agent's counters: the generic ones, the simulator's own (`counts`), busy time."""
    generic = ("moves", "blocked", "failed", "rejected", "contacts")
    return {**{k: getattr(a, k) for k in generic}, **a.counts, "busy": a.busy}
