"""Turn cbdi messages into rerun entities: the map, bodies, intents, logs and plots.

Entity layout (what a user sees in the viewer):

- `world/map/walls`, `world/map/bins` (static boxes), `world/people`, `world/litter`
- `world/robots` (points labelled with names), `agents/<name>/intent` (the requested move)
- `agents/<name>/log` (text log: requests, outcomes, desires, plans, step statuses, early
  arrests), `world/plans/<name>` (the cells each received plan's moves visit),
  `health` (services up/down)
- `plots/<name>/{moves,recycled,failed,blocked}` (from the world's statistics)

Timelines: `epoch` (sequence) and `sim_time` (simulated seconds).
"""

from __future__ import annotations

from typing import Any

from cbdi.errors import WireError
from cbdi.wire.agent import ActionStatus, ArrestReport, DesireEvent, PartialPlan
from cbdi.wire.base import decode
from cbdi.wire.common import Liveliness, RunFinished
from cbdi.wire.world import (
    ActionOutcome,
    ActionRequest,
    Tick,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)
from cbdi_monitor.reader import RecordedMessage

__all__ = ["RerunLogger"]

ROBOT_COLOURS = [
    (230, 80, 60),
    (60, 120, 230),
    (60, 180, 90),
    (200, 140, 30),
    (150, 80, 200),
    (30, 170, 170),
    (220, 90, 160),
    (120, 120, 120),
]


class RerunLogger:
    """Log decoded cbdi messages to a rerun recording stream."""

    def __init__(self, rr: Any, stream: Any) -> None:
        self.rr, self.stream = rr, stream
        self.epoch, self.time = 0, 0.0
        self.colours: dict[str, tuple[int, int, int]] = {}
        self.cells: dict[str, tuple[int, int]] = {}
        self.skipped = 0

    def colour(self, agent: str) -> tuple[int, int, int]:
        if agent not in self.colours:
            self.colours[agent] = ROBOT_COLOURS[len(self.colours) % len(ROBOT_COLOURS)]
        return self.colours[agent]

    def log(self, path: str, entity: Any, static: bool = False) -> None:
        self.stream.log(path, entity, static=static)

    def clock(self, epoch: int, time: float) -> None:
        self.epoch, self.time = epoch, time
        self.stream.set_time("epoch", sequence=epoch)
        self.stream.set_time("sim_time", duration=time)

    def handle(self, m: RecordedMessage) -> None:
        """Log one recorded message (unknown or undecodable ones are skipped)."""
        handler = self._handlers.get(m.schema)
        if handler is None:
            return
        try:
            handler(self, m)
        except WireError:
            self.skipped += 1

    def on_tick(self, m: RecordedMessage) -> None:
        tick = decode(m.payload, Tick, m.key)
        self.clock(tick.epoch, tick.time)

    def on_info(self, m: RecordedMessage) -> None:
        rr, info = self.rr, decode(m.payload, WorldInfo, m.key)
        self.log(
            "world/map/floor",
            rr.Boxes2D(mins=[[0, 0]], sizes=[[info.width, info.height]], colors=[(235, 235, 235)]),
            static=True,
        )
        if info.walls:
            self.log(
                "world/map/walls",
                rr.Boxes2D(
                    centers=[(x + 0.5, y + 0.5) for x, y in info.walls],
                    half_sizes=[(0.5, 0.5)] * len(info.walls),
                    colors=[(60, 60, 60)],
                ),
                static=True,
            )
        self.log(
            "world/map/bins",
            rr.Boxes2D(
                centers=[(b.cell[0] + 0.5, b.cell[1] + 0.5) for b in info.bins],
                half_sizes=[(0.4, 0.4)] * len(info.bins),
                colors=[(40, 140, 60)],
                labels=[b.name for b in info.bins],
            ),
            static=True,
        )

    def on_snapshot(self, m: RecordedMessage) -> None:
        rr, snap = self.rr, decode(m.payload, WorldSnapshot, m.key)
        self.clock(snap.epoch, snap.time)
        self.log(
            "world/robots",
            rr.Points2D(
                [a.pose for a in snap.agents],
                radii=0.35,
                colors=[self.colour(a.name) for a in snap.agents],
                labels=[
                    f"{a.name} ({len(a.holding)})" if a.holding else a.name for a in snap.agents
                ],
            ),
        )
        self.cells.update((a.name, a.cell) for a in snap.agents)
        self.log(
            "world/people",
            rr.Points2D(
                [p.pose for p in snap.people],
                radii=0.3,
                colors=[(250, 190, 40)],
                labels=[p.name for p in snap.people],
            ),
        )
        self.log(
            "world/litter",
            rr.Points2D(
                [(i.cell[0] + 0.5, i.cell[1] + 0.5) for i in snap.litter],
                radii=0.15,
                colors=[(120, 70, 20) if i.known else (200, 120, 60) for i in snap.litter],
            ),
        )

    def on_request(self, m: RecordedMessage) -> None:
        if not m.key.endswith("/act/request"):
            return
        rr, req = self.rr, decode(m.payload, ActionRequest, m.key)
        text = f"requests {req.action}" + (f" to {list(req.target)}" if req.target else "")
        self.log(f"agents/{req.agent}/log", rr.TextLog(text, level="INFO"))
        here = self.cells.get(req.agent)
        if req.action == "move" and req.target and here:
            self.log(
                f"agents/{req.agent}/intent",
                rr.Arrows2D(
                    origins=[(here[0] + 0.5, here[1] + 0.5)],
                    vectors=[(req.target[0] - here[0], req.target[1] - here[1])],
                    colors=[self.colour(req.agent)],
                ),
            )

    def on_outcome(self, m: RecordedMessage) -> None:
        rr, o = self.rr, decode(m.payload, ActionOutcome, m.key)
        level = "INFO" if o.status == "succeeded" else "WARN"
        why = f": {o.reason}" if o.reason else ""
        self.log(f"agents/{o.agent}/log", rr.TextLog(f"{o.action} {o.status}{why}", level=level))

    def on_stats(self, m: RecordedMessage) -> None:
        rr, stats = self.rr, decode(m.payload, WorldStats, m.key)
        for a in stats.agents:
            for name in ("moves", "recycled", "failed", "blocked"):
                self.log(f"plots/{a.agent}/{name}", rr.Scalars(getattr(a, name)))

    def on_alive(self, m: RecordedMessage) -> None:
        rr, event = self.rr, decode(m.payload, Liveliness, m.key)
        service = event.key.removeprefix("cbdi/alive/")
        self.log(
            "health",
            rr.TextLog(
                f"{service} {'up' if event.alive else 'down'}",
                level="INFO" if event.alive else "WARN",
            ),
        )

    def on_finished(self, m: RecordedMessage) -> None:
        done = decode(m.payload, RunFinished, m.key)
        self.log("health", self.rr.TextLog(f"run finished: {done.reason}", level="INFO"))

    def on_desire(self, m: RecordedMessage) -> None:
        rr, e = self.rr, decode(m.payload, DesireEvent, m.key)
        goal = " ".join(f"({' '.join(g)})" for g in e.goal)
        why = f": {e.reason}" if e.reason else ""
        level = "WARN" if e.event == "dropped" else "INFO"
        self.log(
            f"agents/{e.agent}/log",
            rr.TextLog(f"desire {e.desire} {e.event}{why} {goal}", level=level),
        )

    def on_plan(self, m: RecordedMessage) -> None:
        """Draw the cells a plan's moves visit, from the robot's cell."""
        rr, plan = self.rr, decode(m.payload, PartialPlan, m.key)
        cells = [_cell(s.args[2]) for s in plan.steps if s.action == "move" and len(s.args) > 2]
        path = [(x + 0.5, y + 0.5) for x, y in cells if x >= 0]
        here = self.cells.get(plan.agent)
        if here is not None:
            path.insert(0, (here[0] + 0.5, here[1] + 0.5))
        self.log(
            f"agents/{plan.agent}/log",
            rr.TextLog(
                f"plan {plan.plan_id} (after {plan.baseline or 'nothing'}): {len(plan.steps)} steps"
            ),
        )
        if len(path) > 1:
            self.log(
                f"world/plans/{plan.agent}",
                rr.LineStrips2D([path], colors=[self.colour(plan.agent)], radii=0.06),
            )

    def on_status(self, m: RecordedMessage) -> None:
        rr, st = self.rr, decode(m.payload, ActionStatus, m.key)
        if st.status == "waiting":
            return
        why = f": {st.reason}" if st.reason else ""
        level = "INFO" if st.status in ("running", "succeeded") else "WARN"
        self.log(
            f"agents/{st.agent}/log",
            rr.TextLog(f"step {st.step_id} {st.action} {st.status}{why}", level=level),
        )

    def on_arrest(self, m: RecordedMessage) -> None:
        rr, a = self.rr, decode(m.payload, ArrestReport, m.key)
        self.log(
            f"agents/{a.agent}/log",
            rr.TextLog(
                f"early arrest of {a.plan_id} after {a.last_step or 'nothing'}; "
                f"cancelled {', '.join(a.cancelled) or 'nothing'}",
                level="WARN",
            ),
        )

    _handlers = {
        "cbdi.world.Tick/1": on_tick,
        "cbdi.world.WorldInfo/1": on_info,
        "cbdi.world.WorldSnapshot/1": on_snapshot,
        "cbdi.world.ActionRequest/1": on_request,
        "cbdi.world.ActionOutcome/1": on_outcome,
        "cbdi.world.WorldStats/1": on_stats,
        "cbdi.Liveliness/1": on_alive,
        "cbdi.RunFinished/1": on_finished,
        "cbdi.agent.DesireEvent/1": on_desire,
        "cbdi.agent.PartialPlan/1": on_plan,
        "cbdi.agent.ActionStatus/1": on_status,
        "cbdi.agent.ArrestReport/1": on_arrest,
    }


def _cell(name: str) -> tuple[int, int]:
    parts = name.split("_")
    try:
        return (int(parts[1]), int(parts[2]))
    except (IndexError, ValueError):
        return (-1, -1)
