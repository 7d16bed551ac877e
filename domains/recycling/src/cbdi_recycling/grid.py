"""The recycling grid world as a simulator the world service hosts (`cbdi.simulators`).

`GridWorld` is the pure `World` built from a `SimulatorConfig`: the map file, the agents
on the map's start cells in order, the seed, and the options below (a scenario's
`[world]` table, `--option KEY=VALUE`). It performs the domain's PDDL actions through
its binding (`cbdi.bindings`, `recycling` by default) and its own primitive actions
(`move` with a `target` cell, `pickup` and `recycle` with an `item`), which a scripted
robot sends.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.simulator import OptionValue, SimulatorConfig
from cbdi.wire.world import ActionReply, ActionRequest, Cell
from cbdi_recycling.binding import ACTIONS, ActionBinding, load_binding
from cbdi_recycling.chance import Chance
from cbdi_recycling.errors import GridError
from cbdi_recycling.limits import chance_problems
from cbdi_recycling.maps import load_map, with_situation
from cbdi_recycling.world import AgentSpec, World

__all__ = ["GridOptions", "GridWorld", "agent_specs"]


@dataclass(frozen=True)
class GridOptions:
    """The grid world's own settings: the paper's situations and seeded variations."""

    move_step: int = field(default=0, metadata={"help": "people step every N epochs (0: map's)"})
    det_area: int = field(
        default=-1, metadata={"help": "every agent's detection depth (-1: the map's or its own)"}
    )
    known_litter: int = field(
        default=-1, metadata={"help": "litter items known at start, first in reading order"}
    )
    spawn: float = field(
        default=-1.0, metadata={"help": "probability of new litter per epoch (-1: map's)"}
    )
    people_phase: bool = field(
        default=False, metadata={"help": "people start at a seeded cell of their loop"}
    )
    people_jitter: int = field(
        default=0, metadata={"help": "people step up to N epochs early or late (seeded)"}
    )
    duration_noise: float = field(
        default=0.0,
        metadata={"help": "stretch actions by a seeded 0..F of their duration (whole epochs)"},
    )
    failure_probability: float = field(
        default=0.0, metadata={"help": "chance that an accepted action fails at its end"}
    )
    binding: str = field(
        default="recycling",
        metadata={"help": "how PDDL actions map to the grid's (entry point cbdi.bindings)"},
    )

    def problems(self) -> list[tuple[str, str]]:
        """Return `(option, reason)` for each value out of its range."""
        found = chance_problems(self.people_jitter, self.duration_noise, self.failure_probability)
        for name, low in (("move_step", 0), ("det_area", -1), ("known_litter", -1)):
            value = getattr(self, name)
            if value < low:
                found.append((name, f"expected an integer >= {low}, got {value!r}"))
        if not (self.spawn == -1 or 0 <= self.spawn <= 1):
            found.append(("spawn", f"expected a probability in [0, 1] (or -1), got {self.spawn!r}"))
        if not self.binding:
            found.append(("binding", "expected the name of an action binding"))
        return found


def agent_specs(
    names: Sequence[str], depths: Mapping[str, int], starts: Sequence[Cell], depth: int
) -> list[AgentSpec]:
    """Place agents on the map's start cells, in order, each with its own detection depth
    (`depths`) or the map's."""
    if len(names) > len(starts):
        raise GridError(f"{len(names)} agents but the map has only {len(starts)} start cells")
    specs: list[AgentSpec] = []
    for name, start in zip(names, starts, strict=False):
        try:
            keys.validate_name(name)
        except ValueError as exc:
            raise GridError(f"agent {name!r}: {exc}") from None
        specs.append(AgentSpec(name=name, start=start, detection_depth=depths.get(name, depth)))
    if len({s.name for s in specs}) != len(specs):
        raise GridError("agent names must be unique")
    return specs


class GridWorld(World):
    """The recycling grid world, built from a `SimulatorConfig`."""

    actions: tuple[str, ...] = ACTIONS
    Options = GridOptions

    def __init__(self, config: SimulatorConfig) -> None:
        options = GridOptions(**config.options)  # type: ignore[arg-type]
        problems = options.problems()
        if problems:
            raise GridError("; ".join(f"{name}: {reason}" for name, reason in problems))
        self.binding: ActionBinding = load_binding(options.binding, "world option binding")
        self.actions = self.binding.actions
        world_map = with_situation(
            load_map(config.map),
            move_step=options.move_step,
            detection_depth=options.det_area,
            known_litter=options.known_litter,
            spawn_probability=options.spawn,
        )
        own = {} if options.det_area >= 0 else config.detection_depth
        agents = config.agents or ("robot1",)
        specs = agent_specs(agents, own, world_map.agent_starts, world_map.detection_depth)
        chance = Chance(
            people_phase=options.people_phase,
            people_jitter=options.people_jitter,
            duration_noise=options.duration_noise,
            failure_probability=options.failure_probability,
        )
        super().__init__(world_map, specs, seed=config.seed, chance=chance)

    @classmethod
    def performs(cls, options: Mapping[str, OptionValue]) -> tuple[str, ...]:
        """The PDDL actions performed with `options` (its binding's)."""
        name = options.get("binding", "recycling")
        return load_binding(str(name), "world option binding").actions

    def request(self, req: ActionRequest) -> ActionReply:
        """Accept or reject an action: a PDDL action (`args`) through the binding, which
        raises a CbdiError (the reason) for one it does not perform; a primitive as is."""
        return super().request(self.binding.primitive(req) if req.args else req)
