"""The courier world, a simulator the world service hosts (`--simulator courier`).

Pure and deterministic: the same floor, agents and seed give the same run. Each epoch,
in this order: open doors nobody stands in may close (seeded, one stream for doors),
which breaks a drive into that door (its `over all (open ?to)`); due actions end (in
order of end time, then agent name); parcels due back wait at their start again (a
parcel of several `rounds`); carts roll one cell along their route every `step` epochs
(they wait for a cell a robot holds); every robot senses the square around it, and is
told where a parcel of several rounds waits.

Actions follow `pddl/domain.pddl`: a robot does one at a time; `drive` takes its target
cell at start and uses one unit of battery, `grab` and `drop` move a parcel, `charge`
at a dock fills the battery, `open_door` opens a closed door next to the robot.
"""

from __future__ import annotations

import random

from cbdi.errors import ConfigError
from cbdi.simulator import EpochResult, SimulatorConfig
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    AgentStats,
    AgentView,
    ItemView,
    OutcomeStatus,
    PersonView,
    Sensed,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)
from cbdi_courier.floor import Cell, Floor, cell_name, load_floor
from cbdi_courier.state import CartState, RobotState, RunningAction

__all__ = ["ACTIONS", "DURATIONS", "CourierSimulator"]

# The PDDL actions and their durations (simulated seconds), as in pddl/domain.pddl.
DURATIONS = {"drive": 2.0, "open_door": 1.0, "grab": 1.0, "drop": 1.0, "charge": 4.0}
ACTIONS = tuple(DURATIONS)
_ARITY = {"drive": 3, "open_door": 3, "grab": 3, "drop": 3, "charge": 2}
_EPS = 1e-9


class CourierSimulator:
    """The courier floor with its robots, parcels, doors and carts."""

    actions = ACTIONS

    def __init__(self, config: SimulatorConfig) -> None:
        self.floor: Floor = load_floor(config.map)
        f = self.floor
        if len(config.agents) > len(f.starts):
            raise ConfigError(
                config.map, "layout", f"{len(config.agents)} agents, {len(f.starts)} start cells"
            )
        self.epoch = 0
        self.time = 0.0
        self.doors_rng = random.Random(f"{config.seed}:doors")
        self.robots = {
            name: RobotState(name, start, float(f.battery))
            for name, start in zip(config.agents, f.starts, strict=False)
        }
        self.parcels: dict[str, Cell] = {p.name: p.at for p in f.parcels}  # lying on the floor
        self.goal = {p.name: p.to for p in f.parcels}
        self.rounds = {p.name: p.rounds for p in f.parcels}
        self.delivered: list[str] = []  # every delivery, in order (a parcel per round)
        self.resting: set[str] = set()  # delivered, and not (yet) back
        self.returns: dict[str, float] = {}  # parcel -> when it waits at its start again
        self.open = {d: True for d in sorted(f.doors)}
        self.carts = [CartState(c.name, c.route, c.step) for c in f.carts]
        self.rejected: dict[str, int] = {}

    # -- the host's interface -------------------------------------------------------------
    @property
    def done(self) -> bool:
        return len(self.delivered) == sum(self.rounds.values())

    def info(self) -> WorldInfo:
        f = self.floor
        cells = [(x, y) for y in range(f.height) for x in range(f.width) if f.floor_cell((x, y))]
        instances = {cell_name(c): "cell" for c in cells}
        instances |= {r: "robot" for r in self.robots} | {p: "parcel" for p in self.goal}
        facts: list[list[str]] = []
        taken = {r.cell for r in self.robots.values()} | {c.cell for c in self.carts}
        for c in cells:
            facts += [["link", cell_name(c), cell_name(n)] for n in f.links(c)]
            if c not in taken:
                facts.append(["clear", cell_name(c)])
            if c not in f.doors or self.open[c]:
                facts.append(["open", cell_name(c)])
        facts += [["dock", cell_name(c)] for c in sorted(f.docks)]
        facts += [["destination", p, cell_name(c)] for p, c in self.goal.items()]
        facts += [["parcel_at", p, cell_name(c)] for p, c in self.parcels.items()]
        fluents = [(["capacity", r], float(f.battery)) for r in self.robots]
        return WorldInfo(
            map_name=f.name,
            agents=list(self.robots),
            epoch_duration=f.epoch_duration,
            durations=dict(DURATIONS),
            instances=instances,
            facts=facts,
            fluents=fluents,
            view=f.view(),
        )

    def request(self, req: ActionRequest) -> ActionReply:
        robot = self.robots[req.agent]
        reason, action = self._check(robot, req)
        if action is None:
            robot.count("rejected")
            return ActionReply(request_id=req.request_id, accepted=False, reason=reason)
        robot.action = action
        if action.name == "drive":  # at start: the target is taken, a unit of charge used
            robot.battery -= 1
            robot.charged = False
        elif action.name == "grab":
            del self.parcels[action.args[1]]
        elif action.name == "drop":
            robot.carrying = ""
        return ActionReply(
            request_id=req.request_id,
            accepted=True,
            starts_at=action.starts_at,
            ends_at=action.ends_at,
        )

    def initial(self) -> EpochResult:
        return self._result([])

    def step(self) -> EpochResult:
        self.epoch += 1
        self.time = self.epoch * self.floor.epoch_duration
        outcomes = self._settle_contests()
        self._close_doors()
        outcomes += self._complete()
        self._bring_back()
        self._roll_carts()
        return self._result(outcomes)

    def stats(self, agent: str = "") -> WorldStats:
        names = [agent] if agent else list(self.robots)
        rows = [
            AgentStats(
                agent=n,
                failed=self.robots[n].counts.get("failed", 0),
                rejected=self.robots[n].counts.get("rejected", 0),
                busy=round(self.robots[n].busy, 9),
                counts=dict(sorted(self.robots[n].counts.items())),
            )
            for n in names
        ]
        return WorldStats(
            epoch=self.epoch,
            time=self.time,
            agents=rows,
            done=self.done,
            totals={
                "parcels": len(self.goal),
                "deliveries": sum(self.rounds.values()),
                "delivered": len(self.delivered),
            },
        )

    # -- actions --------------------------------------------------------------------------
    def _occupied(self, cell: Cell, earlier_only: bool = False) -> bool:
        """A robot stands there or drives into it, or a cart stands there; `earlier_only`:
        only drives that began before this epoch count (a request's check: the requests
        of one epoch come in any order, so they must not decide each other)."""
        for r in self.robots.values():
            a = r.action
            if r.cell == cell or (
                a
                and a.name == "drive"
                and a.target == cell
                and not (earlier_only and a.starts_at >= self.time - _EPS)
            ):
                return True
        return any(c.cell == cell for c in self.carts)

    def _settle_contests(self) -> list[ActionOutcome]:
        """Drives of the epoch just ended into one cell: the first robot by name takes
        it, the others fail at once, their charge given back (in lockstep a run must not
        depend on which request came first)."""
        began = self.time - self.floor.epoch_duration
        drives: dict[Cell, list[RobotState]] = {}
        for r in sorted(self.robots.values(), key=lambda r: r.name):
            a = r.action
            if a and a.name == "drive" and a.target is not None and abs(a.starts_at - began) < _EPS:
                drives.setdefault(a.target, []).append(r)
        outcomes = []
        for target, robots in drives.items():
            for robot in robots[1:]:
                action = robot.action
                assert action is not None
                robot.action = None
                robot.battery += 1
                robot.charged = robot.battery >= self.floor.battery
                robot.count("failed")
                why = f"{cell_name(target)} is not clear ({robots[0].name} drives there)"
                outcomes.append(
                    ActionOutcome(
                        agent=robot.name,
                        request_id=action.request_id,
                        action=action.name,
                        status="failed",
                        reason=why,
                        epoch=self.epoch,
                        time=self.time,
                    )
                )
        return outcomes

    def _check(self, robot: RobotState, req: ActionRequest) -> tuple[str, RunningAction | None]:
        name, args = req.action, tuple(req.args)
        if name not in DURATIONS:
            return f"the courier world has no action {name!r} (it has {', '.join(ACTIONS)})", None
        if len(args) != _ARITY[name] or args[0] != robot.name:
            return f"{name} takes {_ARITY[name]} arguments, the first {robot.name}", None
        if robot.action is not None:
            return f"{robot.name} is busy with {robot.action.name}", None
        cells = {cell_name(c): c for c in self._cells()}
        here = cell_name(robot.cell)
        start = self.time
        action = RunningAction(name, args, req.request_id, start, start + DURATIONS[name])
        if name in ("drive", "open_door"):
            src, dst = cells.get(args[1]), cells.get(args[2])
            if src is None or dst is None:
                return f"{args[1]} or {args[2]} is not a floor cell", None
            if src != robot.cell:
                return f"{robot.name} is at {here}, not {args[1]}", None
            if dst not in self.floor.links(src):
                return f"{args[2]} is not next to {args[1]}", None
            action.target = dst
            if name == "open_door":
                if dst not in self.open or self.open[dst]:
                    return f"{args[2]} is no closed door", None
            elif not self.open.get(dst, True):
                return f"the door at {args[2]} is closed", None
            elif self._occupied(dst, earlier_only=True):
                return f"{args[2]} is not clear", None
            elif robot.battery < 1:
                return f"{robot.name}'s battery is empty", None
        elif name == "grab":
            if args[2] != here or self.parcels.get(args[1]) != robot.cell:
                return f"no parcel {args[1]} at {here}", None
            if robot.carrying:
                return f"{robot.name} already carries {robot.carrying}", None
        elif name == "drop":
            if robot.carrying != args[1]:
                return f"{robot.name} does not carry {args[1]}", None
            if args[2] != here or self.goal.get(args[1]) != robot.cell:
                return f"{here} is not where {args[1]} goes", None
        elif name == "charge" and (args[1] != here or robot.cell not in self.floor.docks):
            return f"no dock at {here}", None
        return "", action

    def _cells(self) -> list[Cell]:
        f = self.floor
        return [(x, y) for y in range(f.height) for x in range(f.width) if f.floor_cell((x, y))]

    def _close_doors(self) -> None:
        p = self.floor.door_close_probability
        for door, is_open in self.open.items():
            if not is_open or any(r.cell == door for r in self.robots.values()):
                continue
            if any(c.cell == door for c in self.carts):
                continue
            if self.doors_rng.random() < p:
                self.open[door] = False
                for r in self.robots.values():
                    a = r.action
                    if a and a.name == "drive" and a.target == door and not a.broken:
                        a.broken = f"the door at {cell_name(door)} closed during the drive"

    def _complete(self) -> list[ActionOutcome]:
        due = sorted(
            (r for r in self.robots.values() if r.action and r.action.ends_at <= self.time + _EPS),
            key=lambda r: (r.action.ends_at if r.action else 0.0, r.name),
        )
        outcomes = []
        for robot in due:
            action = robot.action
            assert action is not None
            robot.action = None
            robot.busy += action.ends_at - action.starts_at
            reason = action.broken
            status: OutcomeStatus = "failed" if reason else "succeeded"
            if reason:
                robot.count("failed")
            else:
                robot.count(action.name)
                self._effect(robot, action)
            outcomes.append(
                ActionOutcome(
                    agent=robot.name,
                    request_id=action.request_id,
                    action=action.name,
                    status=status,
                    reason=reason,
                    epoch=self.epoch,
                    time=self.time,
                )
            )
        return outcomes

    def _effect(self, robot: RobotState, action: RunningAction) -> None:
        if action.name == "drive" and action.target is not None:
            robot.cell = action.target
        elif action.name == "open_door" and action.target is not None:
            self.open[action.target] = True
        elif action.name == "grab":
            robot.carrying = action.args[1]
        elif action.name == "drop":
            parcel = action.args[1]
            self.delivered.append(parcel)
            self.resting.add(parcel)
            if self.delivered.count(parcel) < self.rounds[parcel]:
                again = next(p.again_after for p in self.floor.parcels if p.name == parcel)
                self.returns[parcel] = self.time + again
        elif action.name == "charge":
            robot.battery = float(self.floor.battery)
            robot.charged = True

    def _bring_back(self) -> None:
        """Parcels whose time came wait at their start again, undelivered."""
        start = {p.name: p.at for p in self.floor.parcels}
        for parcel, when in sorted(self.returns.items()):
            if when <= self.time + _EPS:
                del self.returns[parcel]
                self.resting.discard(parcel)
                self.parcels[parcel] = start[parcel]

    def _roll_carts(self) -> None:
        for cart in self.carts:
            if self.epoch % cart.step:
                continue
            direction = cart.direction
            nxt = cart.next_index()
            cell = cart.route[nxt]
            if self._occupied(cell) or not self.open.get(cell, True):
                cart.direction = direction  # wait, and keep going the same way
                continue
            cart.index = nxt

    # -- what robots sense ----------------------------------------------------------------
    def _result(self, outcomes: list[ActionOutcome]) -> EpochResult:
        return EpochResult(
            epoch=self.epoch,
            time=self.time,
            outcomes=outcomes,
            percepts=[self._sensed(r) for r in self.robots.values()],
            snapshot=self._snapshot(),
        )

    def _sensed(self, robot: RobotState) -> Sensed:
        """What `robot` senses now, as a robot's own sensors would: mid-drive it is still
        at the cell it left (the one it drives into is taken), busy, its battery already
        used; what its running action will leave is the planner's to work out (the
        committed state, `cbdi_planner.continual.commit`)."""
        d = self.floor.sensing
        (ax, ay) = robot.cell
        delivered = [p for p in dict.fromkeys(self.delivered) if p in self.resting]
        add: list[list[str]] = [["at", robot.name, cell_name(robot.cell)]]
        delete: list[list[str]] = []
        for y in range(ay - d, ay + d + 1):
            for x in range(ax - d, ax + d + 1):
                c = (x, y)
                if not self.floor.floor_cell(c):
                    continue
                n = cell_name(c)
                (delete if self._occupied(c) else add).append(["clear", n])
                if c in self.open:
                    (add if self.open[c] else delete).append(["open", n])
                if c != robot.cell:
                    delete.append(["at", robot.name, n])
                for p in self.goal:
                    (add if self.parcels.get(p) == c else delete).append(["parcel_at", p, n])
        for p in self.goal:
            (add if robot.carrying == p else delete).append(["carrying", robot.name, p])
        add += [["delivered", p] for p in delivered]
        # A parcel that comes back is an order: every robot is told where it waits (out
        # of sight too), and that it is no longer delivered.
        for p, rounds in self.rounds.items():
            if rounds == 1:
                continue
            if p not in delivered:
                delete.append(["delivered", p])
            waits = self.parcels.get(p)
            if waits is not None and max(abs(waits[0] - ax), abs(waits[1] - ay)) > d:
                add.append(["parcel_at", p, cell_name(waits)])
        for pred, holds in (
            ("idle", robot.action is None),
            ("empty", not robot.carrying),
            ("charged", robot.charged),
        ):
            (add if holds else delete).append([pred, robot.name])
        return Sensed(
            agent=robot.name,
            epoch=self.epoch,
            time=self.time,
            add=add,
            delete=delete,
            fluents=[(["battery", robot.name], robot.battery)],
        )

    def _snapshot(self) -> WorldSnapshot:
        agents = [
            AgentView(
                name=r.name,
                cell=r.cell,
                pose=(float(r.cell[0]), float(r.cell[1])),
                load=[r.carrying] if r.carrying else [],
                action=r.action.name if r.action else "",
            )
            for r in self.robots.values()
        ]
        carts = [
            PersonView(name=c.name, cell=c.cell, pose=(float(c.cell[0]), float(c.cell[1])))
            for c in self.carts
        ]
        parcels = [ItemView(name=p, cell=c) for p, c in self.parcels.items()]
        return WorldSnapshot(
            epoch=self.epoch,
            time=self.time,
            agents=agents,
            people=carts,
            items=parcels,
            completed=list(self.delivered),
        )
