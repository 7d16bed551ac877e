"""The world service's settings, and the simulator they build (`build_world`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from cbdi import keys
from cbdi.errors import CbdiError
from cbdi.runtime import ServiceSettings
from cbdi.simulator import (
    Simulator,
    SimulatorConfig,
    load_simulator,
    parse_option_pairs,
    read_options,
)
from cbdi_world.acks import members_of
from cbdi_world.errors import WorldError

__all__ = ["RESUME_IF_FOUND", "RESUME_ON_RESTART", "WorldSettings", "agent_entries", "build_world"]

RESUME_ON_RESTART, RESUME_IF_FOUND = "on-restart", "if-found"
RESUMES = (RESUME_ON_RESTART, RESUME_IF_FOUND)


@dataclass(frozen=True)
class WorldSettings(ServiceSettings):
    """Settings of `cbdi-world` (flags, `CBDI_*` environment or the `[world]` TOML table)."""

    map: str = field(default="", metadata={"help": "map file (TOML)"})
    agent: tuple[str, ...] = field(
        default=(), metadata={"help": "agent NAME or NAME:DEPTH, placed on the map's start cells"}
    )
    speed: float = field(default=1.0, metadata={"help": "simulated s per wall s; 0 = flat out"})
    seed: int = field(default=0, metadata={"help": "seed of the simulator's random generators"})
    max_time: float = field(default=0.0, metadata={"help": "end the run at this simulated time"})
    stop_when_done: bool = field(
        default=True, metadata={"help": "end when the simulator's goals are all met"}
    )
    linger: float = field(
        default=0.0,
        metadata={
            "help": "after the run ends, answer this many wall s, then exit (0: till stopped)"
        },
    )
    lockstep: bool = field(
        default=False, metadata={"help": "virtual time: each epoch waits for every member's ack"}
    )
    member: tuple[str, ...] = field(
        default=(),
        metadata={"help": "lockstep member AGENT/COMPONENT (default: each agent's executor)"},
    )
    wait_agents: float = field(
        default=30.0, metadata={"help": "seconds to wait for every member before epoch 0 (0: none)"}
    )
    ack_timeout: float = field(
        default=120.0, metadata={"help": "lockstep: seconds to wait for a member's ack"}
    )
    stats_every: int = field(default=10, metadata={"help": "publish statistics every N epochs"})
    simulator: str = field(
        default="",
        metadata={"help": "the domain's simulator to host (entry point cbdi.simulators)"},
    )
    option: tuple[str, ...] = field(
        default=(),
        metadata={"help": "a simulator option KEY=VALUE (what it declares: its Options)"},
    )
    state: str = field(
        default="",
        metadata={"help": "keep the world's state in FILE, for a restart ('': none)"},
    )
    state_every: int = field(
        default=20,
        metadata={"help": "save the whole state every N epochs (in between: what changed it)"},
    )
    restart: int = field(
        default=0,
        metadata={
            "help": "restarts so far (cbdi up sets CBDI_RESTART): above 0 the run goes on "
            "from --state"
        },
    )
    resume: str = field(
        default=RESUME_ON_RESTART,
        metadata={
            "help": f"when the run goes on from --state: {RESUME_ON_RESTART} (--restart above"
            f" 0) or {RESUME_IF_FOUND} (whenever the file is there: a container's own volume)"
        },
    )

    def resumes(self) -> bool:
        """Whether this world goes on from its state file (if it has a usable one)."""
        if not self.state:
            return False
        if self.resume == RESUME_IF_FOUND:
            return Path(self.state).exists()
        return self.restart > 0


def build_world(settings: WorldSettings) -> Simulator:
    """Build the `--simulator` from its map, agents, seed and options; raise a
    CbdiError/WorldError naming what is wrong (a map it refuses names the simulator)."""
    if not (math.isfinite(settings.linger) and settings.linger >= 0):
        raise WorldError(f"--linger must be a finite number of seconds >= 0, not {settings.linger}")
    if settings.state_every < 1:
        raise WorldError(f"--state-every must be an epoch count >= 1, not {settings.state_every}")
    if settings.resume not in RESUMES:
        raise WorldError(f"--resume must be one of {', '.join(RESUMES)}, not {settings.resume!r}")
    simulator = load_simulator(settings.simulator, "--simulator")
    if not settings.map and getattr(simulator, "needs_map", True):
        raise WorldError(
            f"no map given (--map FILE): the {settings.simulator!r} simulator needs one"
        )
    options = read_options(simulator, parse_option_pairs(settings.option, "--option"), "--option")
    agents, depths = agent_entries(settings.agent or ("robot1",))
    members_of(settings.member, list(agents))  # every member names an agent
    config = SimulatorConfig(
        map=settings.map, agents=agents, seed=settings.seed, detection_depth=depths, options=options
    )
    try:
        return simulator(config)
    except CbdiError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise WorldError(f"simulator {settings.simulator!r}, map {settings.map}: {exc}") from None


def agent_entries(entries: Sequence[str]) -> tuple[tuple[str, ...], dict[str, int]]:
    """Read `--agent NAME[:DEPTH]` entries: the names in order, and the depths given."""
    names: list[str] = []
    depths: dict[str, int] = {}
    for entry in entries:
        name, _, depth = entry.partition(":")
        try:
            keys.validate_name(name)
            if depth:
                depths[name] = int(depth)
                if depths[name] < 0:
                    raise ValueError(f"a detection depth is >= 0, not {depth}")
        except ValueError as exc:
            raise WorldError(f"--agent {entry!r}: {exc}") from None
        names.append(name)
    if len(set(names)) != len(names):
        raise WorldError("agent names must be unique")
    return tuple(names), depths
