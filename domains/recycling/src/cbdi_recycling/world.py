"""The authoritative recycling world: pure, deterministic, stepped one epoch at a time.

`request` answers an action request at once (accepted with its end time, or rejected with
the reason); `step` advances one epoch: due actions complete (in order of end time, then
agent name), people advance along their loops, litter may appear, bodies glide, and every
agent senses the square around it. Same map, agents, seed, `Chance` and requests: the
same run (what the seed samples is in `cbdi_recycling.chance`).
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from cbdi.simulator import EpochResult
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    AgentStats,
    AgentView,
    Cell,
    ItemView,
    OutcomeStatus,
    PersonView,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)
from cbdi_recycling.chance import Chance, countdown, epochs_of, fails, start_index, stream
from cbdi_recycling.errors import GridError, UnknownAgentError
from cbdi_recycling.maps import WorldMap
from cbdi_recycling.physics import Physics
from cbdi_recycling.rules import Action, check_request, complete, fail
from cbdi_recycling.wire import AgentSeen, BinView, GridMap, Percepts, with_map

__all__ = ["AgentSpec", "EpochResult", "World"]

_EPS = 1e-9
# The counters every world keeps (fields of AgentStats), and this world's own.
_GENERIC_COUNTS = ("failed", "rejected")
_OWN_COUNTS = ("moves", "blocked", "contacts", "pickups", "recycled")  # the paper's metric first


@dataclass(frozen=True)
class AgentSpec:
    """An agent placed in the world: its name, start cell and detection depth."""

    name: str
    start: Cell
    detection_depth: int = 1


@dataclass
class AgentState:
    spec: AgentSpec
    cell: Cell
    holding: list[str] = field(default_factory=list)
    action: Action | None = None
    stats: dict[str, int] = field(default_factory=dict)
    busy: float = 0.0  # seconds spent in actions that ended (succeeded or failed)

    def count(self, what: str) -> None:
        self.stats[what] = self.stats.get(what, 0) + 1


@dataclass
class PersonState:
    name: str
    path: tuple[Cell, ...]
    move_step: int
    index: int = 0
    countdown: int = 0
    patience: int = 0  # epochs blocked before turning round (0: never)
    waited: int = 0  # epochs blocked so far

    def turn_round(self) -> None:
        """Walk the loop the other way from here."""
        self.path = self.path[::-1]
        self.index = len(self.path) - 1 - self.index
        self.waited = 0

    @property
    def cell(self) -> Cell:
        return self.path[self.index]


class World:
    """The recycling world of the paper, for any number of agents."""

    def __init__(
        self,
        world_map: WorldMap,
        agents: Sequence[AgentSpec],
        *,
        seed: int = 0,
        chance: Chance | None = None,
        physics_substeps: int = 4,
    ) -> None:
        self.map = world_map
        self.epoch = 0
        self.time = 0.0
        self.seed = seed
        self.chance = chance or Chance()
        self.rng = random.Random(seed)  # litter only: a seed spawns what it always did
        self._streams: dict[str, random.Random] = {}
        self.agents: dict[str, AgentState] = {}
        self.blocked_static = world_map.walls | set(world_map.bins.values())
        self.people = self._start_people({*world_map.agent_starts, *(a.start for a in agents)})
        self.occupant: dict[Cell, str] = {p.cell: p.name for p in self.people}
        self.litter: dict[str, Cell] = {n: c for n, (c, _) in world_map.litter.items()}
        self.known = {n for n, (_, k) in world_map.litter.items() if k}
        self.in_hand: set[str] = set()
        self.recycled: list[str] = []
        self.spawned = 0
        for spec in agents:
            self._place(spec)
        self.physics = Physics(physics_substeps, self._contact)
        for a in self.agents.values():
            self.physics.add(a.spec.name, a.cell, robot=True)
        for p in self.people:
            self.physics.add(p.name, p.cell, robot=False)

    def _stream(self, purpose: str) -> random.Random:
        """Return the seeded generator of `purpose`, created on first use."""
        if purpose not in self._streams:
            self._streams[purpose] = stream(self.seed, purpose)
        return self._streams[purpose]

    def _start_people(self, agent_starts: set[Cell]) -> list[PersonState]:
        """Put each person on its loop: `path[0]`, or a seeded free cell with `people_phase`.

        A phased person avoids agents' start cells, the cells of people placed before it
        and those of people who stand still (they have no other cell); the map guarantees
        that for `path[0]`, and walls and bins are never on a path.
        """
        people: list[PersonState] = []
        taken = set(agent_starts) | {p.path[0] for p in self.map.people if len(p.path) < 2}
        for p in self.map.people:
            index = 0
            if self.chance.people_phase and len(p.path) > 1:
                index = start_index(p.path, taken, self._stream(f"people-phase:{p.name}"))
                taken.add(p.path[index])
            wait = countdown(p.move_step, self.chance.people_jitter, self._jitter(p.name))
            people.append(PersonState(p.name, p.path, p.move_step, index, wait, p.patience))
        return people

    def _jitter(self, person: str) -> random.Random:
        return self._stream(f"people-jitter:{person}")

    def _place(self, spec: AgentSpec) -> None:
        if spec.name in self.agents:
            raise GridError(f"agent {spec.name!r} given twice")
        if not self.map.inside(spec.start) or spec.start in self.blocked_static:
            raise GridError(f"agent {spec.name!r} cannot start on {list(spec.start)}")
        if spec.start in self.occupant:
            raise GridError(f"agent {spec.name!r} would start on {self.occupant[spec.start]}")
        self.agents[spec.name] = AgentState(spec, spec.start)
        self.occupant[spec.start] = spec.name

    def _contact(self, robot: str, person: str) -> None:
        self.agents[robot].count("contacts")

    def agent(self, name: str) -> AgentState:
        try:
            return self.agents[name]
        except KeyError:
            raise UnknownAgentError(name) from None

    @property
    def done(self) -> bool:
        """True when no litter lies on the ground, in a hand, or on the way to a bin."""
        return not self.litter and not self.in_hand

    def request(self, req: ActionRequest) -> ActionReply:
        """Accept or reject an action at once; an accepted one starts now."""
        agent = self.agent(req.agent)
        reason, action = check_request(self, agent, req)
        if action is None:
            agent.count("rejected")
            return ActionReply(request_id=req.request_id, accepted=False, reason=reason)
        if self.chance.duration_noise > 0:
            action = self._stretched(req.agent, action)
        agent.action = action
        if action.name == "pickup":  # at start: the item leaves the cell (domain semantics)
            del self.litter[action.item or ""]
            self.in_hand.add(action.item or "")
        elif action.name == "recycle":  # at start: the item leaves the hand
            agent.holding.remove(action.item or "")
        return ActionReply(
            request_id=req.request_id,
            accepted=True,
            starts_at=action.starts_at,
            ends_at=action.ends_at,
        )

    def _stretched(self, agent: str, action: Action) -> Action:
        """Return `action` lasting its noisy duration, ending on an epoch boundary.

        The end is computed as `step` computes epoch times, so it matches one exactly.
        """
        e = self.map.epoch_duration
        rng = self._stream(f"durations:{agent}")
        k = epochs_of(self.map.durations[action.name], e, self.chance.duration_noise, rng)
        return replace(action, ends_at=(self.epoch + k) * e)

    def step(self) -> EpochResult:
        """Advance one epoch and return what happened."""
        self.epoch += 1
        self.time = self.epoch * self.map.epoch_duration
        outcomes = self._complete_actions()
        self._move_people()
        spawned = self._spawn_litter()
        targets = {a.spec.name: a.cell for a in self.agents.values()}
        targets.update((p.name, p.cell) for p in self.people)
        self.physics.glide(targets, self.map.epoch_duration)
        return self._result(outcomes, spawned)

    def initial(self) -> EpochResult:
        """Return epoch 0 as an `EpochResult` (nothing happened yet)."""
        return self._result([], [])

    def _result(self, outcomes: list[ActionOutcome], spawned: list[str]) -> EpochResult:
        return EpochResult(
            epoch=self.epoch,
            time=self.time,
            outcomes=outcomes,
            percepts=[self.percepts(n) for n in self.agents],
            snapshot=self.snapshot(),
            spawned=spawned,
        )

    def _complete_actions(self) -> list[ActionOutcome]:
        due = [
            a
            for a in self.agents.values()
            if a.action is not None and a.action.ends_at <= self.time + _EPS
        ]
        due.sort(key=lambda a: (a.action.ends_at if a.action else 0.0, a.spec.name))
        outcomes = []
        for agent in due:
            action = agent.action
            assert action is not None
            agent.action = None
            agent.busy += max(0.0, action.ends_at - action.starts_at)
            status, reason = self._end(agent, action)
            outcomes.append(
                ActionOutcome(
                    agent=agent.spec.name,
                    request_id=action.request_id,
                    action=action.name,
                    status=status,
                    reason=reason,
                    epoch=self.epoch,
                    time=self.time,
                    target=action.target,
                    item=action.item,
                )
            )
        return outcomes

    def _end(self, agent: AgentState, action: Action) -> tuple[OutcomeStatus, str]:
        """Complete `action`, unless the seeded failure draw (one per action) fails it."""
        p = self.chance.failure_probability
        if fails(p, self._stream(f"failures:{agent.spec.name}")):
            return fail(self, agent, action, f"random failure (p={p:g})")
        return complete(self, agent, action)

    def _move_people(self) -> None:
        for p in self.people:
            if len(p.path) < 2:
                continue
            p.countdown -= 1
            if p.countdown > 0:
                continue
            nxt = (p.index + 1) % len(p.path)
            if p.path[nxt] in self.occupant:
                p.waited += 1  # blocked: try again next epoch, or turn round
                if p.patience and p.waited >= p.patience:
                    p.turn_round()
                continue
            del self.occupant[p.cell]
            p.index, p.waited = nxt, 0
            self.occupant[p.cell] = p.name
            p.countdown = countdown(p.move_step, self.chance.people_jitter, self._jitter(p.name))

    def _spawn_litter(self) -> list[str]:
        if self.map.spawn_probability <= 0 or self.rng.random() >= self.map.spawn_probability:
            return []
        taken = self.blocked_static | set(self.occupant) | set(self.litter.values())
        free = [
            (x, y)
            for y in range(self.map.height)
            for x in range(self.map.width)
            if (x, y) not in taken
        ]
        if not free:
            return []
        self.spawned += 1
        name = f"litter_{self.spawned}"
        self.litter[name] = self.rng.choice(free)
        return [name]

    def percepts(self, name: str) -> Percepts:
        """What agent `name` senses now: the clipped (2d+1)x(2d+1) square around it."""
        agent = self.agent(name)
        d = agent.spec.detection_depth
        (ax, ay), m = agent.cell, self.map
        free: list[Cell] = []
        blocked: list[Cell] = []
        for y in range(max(0, ay - d), min(m.height, ay + d + 1)):
            for x in range(max(0, ax - d), min(m.width, ax + d + 1)):
                cell = (x, y)
                if cell == agent.cell:
                    continue
                if cell in self.blocked_static or cell in self.occupant:
                    blocked.append(cell)
                else:
                    free.append(cell)
        seen = [
            ItemView(name=n, cell=c, known=n in self.known)
            for n, c in self.litter.items()
            if abs(c[0] - ax) <= d and abs(c[1] - ay) <= d
        ]
        others = [
            AgentSeen(name=n, cell=a.cell)
            for n, a in sorted(self.agents.items())
            if n != name and abs(a.cell[0] - ax) <= d and abs(a.cell[1] - ay) <= d
        ]
        return Percepts(
            agent=name,
            epoch=self.epoch,
            time=self.time,
            position=agent.cell,
            depth=d,
            free=free,
            blocked=blocked,
            items=seen,
            holding=list(agent.holding),
            others=others,
        )

    def snapshot(self) -> WorldSnapshot:
        """Everything that moves, with the bodies' poses."""
        pose = self.physics.pose
        agents = [
            AgentView(
                name=n,
                cell=a.cell,
                pose=pose(n),
                load=list(a.holding),
                action=a.action.name if a.action else "",
            )
            for n, a in self.agents.items()
        ]
        people = [PersonView(name=p.name, cell=p.cell, pose=pose(p.name)) for p in self.people]
        litter = [ItemView(name=n, cell=c, known=n in self.known) for n, c in self.litter.items()]
        return WorldSnapshot(
            epoch=self.epoch,
            time=self.time,
            agents=agents,
            people=people,
            items=litter,
            completed=list(self.recycled),
        )

    def stats(self, agent: str = "") -> WorldStats:
        """Per-agent counters (one agent, or all when `agent` is empty) and litter totals."""
        names = [self.agent(agent).spec.name] if agent else list(self.agents)
        rows = [self._agent_stats(n) for n in names]
        return WorldStats(
            epoch=self.epoch,
            time=self.time,
            agents=rows,
            done=self.done,
            totals={
                "litter_on_ground": len(self.litter),
                "litter_held": len(self.in_hand),
                "litter_recycled": len(self.recycled),
                "litter_spawned": self.spawned,
            },
        )

    def _agent_stats(self, name: str) -> AgentStats:
        """One agent's row: the generic counters as fields, the grid's own in `counts`
        (zero when nothing happened)."""
        a = self.agents[name]
        generic = {k: v for k, v in a.stats.items() if k in _GENERIC_COUNTS}
        counts = {k: a.stats.get(k, 0) for k in _OWN_COUNTS}
        return AgentStats(agent=name, busy=round(a.busy, 9), counts=counts, **generic)

    def info(self) -> WorldInfo:
        """The static part of the world."""
        m = self.map
        grid = GridMap(
            width=m.width,
            height=m.height,
            walls=sorted(m.walls),
            bins=[BinView(name=n, cell=c) for n, c in m.bins.items()],
            capacity=m.capacity,
            detection_depth={n: a.spec.detection_depth for n, a in self.agents.items()},
        )
        info = WorldInfo(
            map_name=m.name,
            agents=list(self.agents),
            epoch_duration=m.epoch_duration,
            durations=dict(m.durations),
            known_items=[
                ItemView(name=n, cell=c, known=True) for n, (c, known) in m.litter.items() if known
            ],
        )
        return with_map(info, grid)
