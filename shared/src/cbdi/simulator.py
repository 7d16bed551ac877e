"""A domain's simulator, hosted by the world service (`cbdi-world --simulator NAME`).

The host gives a simulator what every simulated run needs: the epoch clock and its pace,
lockstep with the agents, the start barrier, the request trace, the end of the run, and
publication of what it produces (ticks, outcomes, percepts, snapshots, statistics), so
recording, replay, `cbdi inspect` and the views work for it unchanged. The simulator
itself is pure and deterministic: the same map, agents and seed give the same run.

A domain's package registers its simulator class under the entry-point group
`cbdi.simulators`; a scenario names it (`[run] simulator = "courier"`):

    class CourierSimulator:
        actions = ("drive", "grab", "drop", "charge")   # the PDDL actions it performs

        def __init__(self, config: SimulatorConfig) -> None: ...
        def info(self) -> WorldInfo: ...          # static: map, agents, initial beliefs
        def request(self, req: ActionRequest) -> ActionReply: ...  # start one now
        def initial(self) -> EpochResult: ...     # epoch 0
        def step(self) -> EpochResult: ...        # advance one epoch
        def stats(self, agent: str = "") -> WorldStats: ...

A simulator with settings of its own declares them as a frozen dataclass `Options` (each
field with its default and `metadata={"help": ...}`, and a method `problems()` returning
`(field, reason)` for values out of range); a scenario sets them in its `[world]` table,
`cbdi up --option KEY=VALUE` and `cbdi-world --option KEY=VALUE` on the command line, and
`read_options` checks them by that declaration before anything starts.

A simulator that needs no map file (the world service's `clock`) says so with a class
attribute `needs_map = False`; a scenario for it has no `map`.

A killed world goes on from its state file (`cbdi_world.recovery`): the host saves the
simulator object pickled, so it must pickle (plain Python, `random.Random` and pymunk
bodies do) and stay deterministic; one that does not pickle defines `save_state() ->
bytes` and `restore_state(data: bytes) -> None` (called on one built from the same
config).

`request` gets grounded PDDL actions (`req.action`, `req.args`) for agents of `info()`
only (the host answers `unknown_agent` for any other); it rejects what it cannot do with
an `ActionReply(accepted=False, reason=...)`, and raises for nothing a client sends.
Percepts are `Sensed` belief changes (read by the generic knowledge, `cbdi.literals`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, cast

from cbdi.errors import ConfigError
from cbdi.plugins import load_plugin
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    Percept,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)

__all__ = [
    "SIMULATORS",
    "EpochResult",
    "OptionValue",
    "Simulator",
    "SimulatorClass",
    "SimulatorConfig",
    "load_simulator",
    "option_defaults",
    "parse_option_pairs",
    "performed_actions",
    "read_options",
]

SIMULATORS = "cbdi.simulators"


OptionValue = bool | int | float | str


@dataclass(frozen=True)
class SimulatorConfig:
    """What a simulator is made from: its map file, the agents to place, the seed, the
    sensing depth of agents given one (`--agent NAME:DEPTH`) and its own options (checked
    by `read_options`: only those set, typed as its `Options` declares)."""

    map: str
    agents: tuple[str, ...]
    seed: int = 0
    detection_depth: Mapping[str, int] = field(default_factory=dict)
    options: Mapping[str, OptionValue] = field(default_factory=dict)


@dataclass(frozen=True)
class EpochResult:
    """What one epoch produced, for the host to publish."""

    epoch: int
    time: float
    outcomes: Sequence[ActionOutcome]
    percepts: Sequence[Percept]
    snapshot: WorldSnapshot
    spawned: Sequence[str] = field(default_factory=list)


class Simulator(Protocol):
    """A world the host steps epoch by epoch."""

    @property
    def epoch(self) -> int: ...

    @property
    def time(self) -> float: ...

    @property
    def done(self) -> bool:
        """True when the run's goals are all met (the run ends, `done`)."""
        ...

    def info(self) -> WorldInfo: ...

    def request(self, req: ActionRequest) -> ActionReply: ...

    def initial(self) -> EpochResult: ...

    def step(self) -> EpochResult: ...

    def stats(self, agent: str = "") -> WorldStats: ...


class SimulatorClass(Protocol):
    """What `cbdi.simulators` entry points name: a class with its actions."""

    actions: ClassVar[tuple[str, ...]]

    def __call__(self, config: SimulatorConfig) -> Simulator: ...


def load_simulator(name: str, source: str = "world") -> SimulatorClass:
    """Return the simulator class `name` (entry-point group `cbdi.simulators`);
    ConfigError naming what is installed if there is none."""
    if not name:
        raise ConfigError(source, "simulator", "no simulator named (entry point cbdi.simulators)")
    found = load_plugin(SIMULATORS, name, source, "simulator", "simulator")
    if not callable(found) or not isinstance(getattr(found, "actions", None), tuple):
        raise ConfigError(source, "simulator", f"{name!r} is not a simulator class with actions")
    return cast(SimulatorClass, cast(Callable[..., object], found))


def performed_actions(
    simulator: SimulatorClass, options: Mapping[str, OptionValue]
) -> tuple[str, ...]:
    """The PDDL actions `simulator` performs with `options` (its `performs(options)` when it
    has one, as when an option picks what it performs, else its class's `actions`)."""
    performs = getattr(simulator, "performs", None)
    if callable(performs):
        return tuple(performs(options))
    return simulator.actions


def option_defaults(simulator: object) -> dict[str, OptionValue]:
    """The options `simulator` (class) declares in its `Options` dataclass, with defaults."""
    declared = getattr(simulator, "Options", None)
    if declared is None or not dataclasses.is_dataclass(declared):
        return {}
    return {f.name: f.default for f in dataclasses.fields(declared)}  # type: ignore[misc]


def parse_option_pairs(pairs: Sequence[str], source: str) -> dict[str, str]:
    """Split command-line `KEY=VALUE` entries; ConfigError for one without `=`."""
    raw: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ConfigError(source, pair, "expected KEY=VALUE")
        raw[key.strip().replace("-", "_")] = value.strip()
    return raw


def read_options(
    simulator: object, raw: Mapping[str, object], source: str, prefix: str = ""
) -> dict[str, OptionValue]:
    """Check `raw` against the options `simulator` declares and return them typed.

    Text (from a command line) is read as the option's type; a TOML integer is taken for
    a float option; NaN and infinities are refused; then the `Options` dataclass's own
    `problems()` check ranges. Errors name `source` and the option (`prefix` + name)."""
    defaults = option_defaults(simulator)
    name = getattr(simulator, "__name__", "the simulator")
    values: dict[str, OptionValue] = {}
    for key, value in raw.items():
        if key not in defaults:
            known = ", ".join(sorted(defaults)) or "none"
            raise ConfigError(
                source, f"{prefix}{key}", f"unknown option of {name} (it has: {known})"
            )
        values[key] = _typed(value, defaults[key], source, f"{prefix}{key}")
    if defaults:
        declared: Any = getattr(simulator, "Options", None)
        problems = getattr(declared(**values), "problems", None)
        for field_name, reason in problems() if callable(problems) else []:
            raise ConfigError(source, f"{prefix}{field_name}", reason)
    return values


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def _typed(value: object, default: OptionValue, source: str, where: str) -> OptionValue:
    kind = type(default)
    if isinstance(value, str) and kind is not str:
        text = value.strip().lower()
        try:
            if kind is bool:
                if text not in _TRUE + _FALSE:
                    raise ValueError(value)
                value = text in _TRUE
            else:
                value = kind(text)
        except ValueError:
            raise ConfigError(source, where, f"expected {kind.__name__}, got {value!r}") from None
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if type(value) is not kind:
        got = type(value).__name__
        raise ConfigError(source, where, f"expected {kind.__name__}, got {got}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(source, where, f"expected a finite number, got {value!r}")
    return value
