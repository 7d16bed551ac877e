"""A greenhouse, a domain whose map is a graph: places with positions, links between
them, plants that dry up again after each watering. The smallest simulator the world
host runs that has no floor of cells (`cbdi.simulator`; map: greenhouse.toml).

PDDL actions: `(go ?r ?from ?to)` along a link, 2 s; `(water ?r ?plant ?place)` where
the robot stands, 1 s. A robot senses where it is, whether it is idle, and which plants
are dry. Done when every plant was watered `rounds` times.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from cbdi.simulator import EpochResult, SimulatorConfig
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    AgentStats,
    AgentView,
    ItemView,
    MapLink,
    MapPlace,
    MapView,
    Sensed,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)

DURATIONS = {"go": 2.0, "water": 1.0}
COUNTERS = {"waterings": "water", "walks": "go"}  # what `cbdi inspect` counts per robot


class Greenhouse:
    """Robots walk between places and water the plants that are dry."""

    actions = tuple(DURATIONS)

    def __init__(self, config: SimulatorConfig) -> None:
        data = tomllib.loads(Path(config.map).read_text(encoding="utf-8"))
        self.name, self.size = str(data["name"]), tuple(data["size"])
        self.places = {n: (float(x), float(y)) for n, (x, y) in data["places"].items()}
        self.links = [(a, b) for a, b in data["links"]]
        self.plants: dict[str, str] = dict(data["plants"])  # plant -> its place
        self.epoch_duration, self.dry_after = data["epoch_duration"], data["dry_after"]
        self.rounds = int(data["rounds"])
        self.epoch, self.time = 0, 0.0
        self.where = {a: str(data["start"]) for a in config.agents}
        self.running: dict[str, tuple[ActionRequest, float]] = {}  # agent -> (what, ends)
        self.dry_at: dict[str, float | None] = {p: 0.0 for p in self.plants}  # None: never
        self.watered = dict.fromkeys(self.plants, 0)
        self.counts: dict[str, dict[str, int]] = {a: {} for a in config.agents}

    @property
    def done(self) -> bool:
        return all(n >= self.rounds for n in self.watered.values())

    def info(self) -> WorldInfo:
        facts = [["link", a, b] for a, b in self.links] + [["link", b, a] for a, b in self.links]
        facts += [["plant_at", p, at] for p, at in self.plants.items()]
        view = MapView(
            width=self.size[0],
            height=self.size[1],
            places=[MapPlace(name=n, at=at) for n, at in self.places.items()],
            links=[MapLink(a=a, b=b) for a, b in self.links],
        )
        instances = {p: "place" for p in self.places} | {p: "plant" for p in self.plants}
        return WorldInfo(
            map_name=self.name,
            agents=list(self.where),
            epoch_duration=self.epoch_duration,
            durations=dict(DURATIONS),
            instances=instances | {a: "robot" for a in self.where},
            facts=facts,
            view=view,
        )

    def request(self, req: ActionRequest) -> ActionReply:
        why = self._refusal(req)
        if why:
            self._count(req.agent, "rejected")
            return ActionReply(request_id=req.request_id, accepted=False, reason=why)
        ends = self.time + DURATIONS[req.action]
        self.running[req.agent] = (req, ends)
        return ActionReply(
            request_id=req.request_id, accepted=True, starts_at=self.time, ends_at=ends
        )

    def initial(self) -> EpochResult:
        return self._result([])

    def step(self) -> EpochResult:
        self.epoch += 1
        self.time = self.epoch * self.epoch_duration
        return self._result(self._complete())

    def stats(self, agent: str = "") -> WorldStats:
        rows = [
            AgentStats(
                agent=a,
                rejected=self.counts[a].get("rejected", 0),
                counts=dict(sorted(self.counts[a].items())),
            )
            for a in ([agent] if agent else self.where)
        ]
        watered = sum(self.watered.values())
        return WorldStats(
            epoch=self.epoch,
            time=self.time,
            agents=rows,
            done=self.done,
            totals={"watered": watered},
        )

    def _refusal(self, req: ActionRequest) -> str:
        here, args = self.where[req.agent], req.args
        if req.action not in DURATIONS or len(args) != 3 or args[0] != req.agent:
            return f"no such action: ({req.action} {' '.join(args)})"
        if req.agent in self.running:
            return "busy"
        if req.action == "go" and (args[1] != here or {args[1], args[2]} not in self._pairs()):
            return f"no link from {here} to {args[2]}"
        if req.action == "water" and (self.plants.get(args[1]) != here or not self._dry(args[1])):
            return f"no dry {args[1]} at {here}"
        return ""

    def _pairs(self) -> list[set[str]]:
        return [{a, b} for a, b in self.links]

    def _dry(self, plant: str) -> bool:
        due = self.dry_at[plant]
        return due is not None and self.time >= due

    def _count(self, agent: str, what: str) -> None:
        self.counts[agent][what] = self.counts[agent].get(what, 0) + 1

    def _complete(self) -> list[ActionOutcome]:
        outcomes = []
        for agent in sorted(self.running):
            req, ends = self.running[agent]
            if ends > self.time + 1e-9:
                continue
            del self.running[agent]
            if req.action == "go":
                self.where[agent] = req.args[2]
            else:
                plant = req.args[1]
                self.watered[plant] += 1
                again = self.watered[plant] < self.rounds
                self.dry_at[plant] = self.time + self.dry_after if again else None
            self._count(agent, req.action)
            outcomes.append(
                ActionOutcome(
                    agent=agent,
                    request_id=req.request_id,
                    action=req.action,
                    status="succeeded",
                    reason="",
                    epoch=self.epoch,
                    time=self.time,
                )
            )
        return outcomes

    def _result(self, outcomes: list[ActionOutcome]) -> EpochResult:
        dry = [p for p in self.plants if self._dry(p)]
        percepts = [
            Sensed(
                agent=a,
                epoch=self.epoch,
                time=self.time,
                add=[["at", a, here]] + [["dry", p] for p in dry]
                + ([] if a in self.running else [["idle", a]]),
                delete=[["at", a, p] for p in self.places if p != here]
                + [["dry", p] for p in self.plants if p not in dry]
                + ([["idle", a]] if a in self.running else []),
            )
            for a, here in self.where.items()
        ]  # fmt: skip
        snapshot = WorldSnapshot(
            epoch=self.epoch,
            time=self.time,
            agents=[self._agent(a) for a in self.where],
            people=[],
            items=[ItemView(name=p, cell=self._cell(self.plants[p])) for p in dry],
            completed=[p for p, n in self.watered.items() if n >= self.rounds],
        )
        return EpochResult(self.epoch, self.time, outcomes, percepts, snapshot)

    def _agent(self, agent: str) -> AgentView:
        here = self.where[agent]
        action = self.running[agent][0].action if agent in self.running else ""
        return AgentView(name=agent, cell=self._cell(here), pose=self.places[here], action=action)

    def _cell(self, place: str) -> tuple[int, int]:
        x, y = self.places[place]
        return int(x), int(y)
