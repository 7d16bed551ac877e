"""Domain plug-ins found by name in an entry-point group.

A domain's package registers what the generic services load (`cbdi.knowledge` for the
scheduler, `cbdi.simulators` for the world, ...); a configuration names one, and a name
that is not installed is a `ConfigError` saying which are.
"""

from __future__ import annotations

from functools import cache
from importlib.metadata import entry_points

from cbdi.errors import ConfigError
from cbdi.wire.world import Percept, Sensed

__all__ = [
    "COUNTERS",
    "PERCEPTS",
    "domain_counters",
    "installed",
    "load_plugin",
    "percept_types",
]


def installed(group: str) -> list[str]:
    """The names installed under entry-point group `group`."""
    return sorted({ep.name for ep in entry_points(group=group)})


def load_plugin(group: str, name: str, source: str, field: str, what: str) -> object:
    """Load entry point `name` of `group`; ConfigError (`source`, `field`) naming what is
    installed if there is none, or if it does not load."""
    found = [ep for ep in entry_points(group=group) if ep.name == name]
    if not found:
        known = ", ".join(installed(group)) or "none"
        raise ConfigError(source, field, f"no {what} {name!r} (installed: {known})")
    try:
        return found[0].load()
    except Exception as exc:  # a broken plug-in: say which, never a traceback
        raise ConfigError(source, field, f"{what} {name!r} does not load: {exc}") from None


# A domain's summary counters, under its simulator's name: a mapping of counter name to
# the action whose successes it counts (recycling: `{"moves": "move", "recycled":
# "recycle"}`), for reports such as `cbdi inspect`.
COUNTERS = "cbdi.counters"


def domain_counters(simulator: str) -> dict[str, str]:
    """Return the summary counters registered for `simulator` (entry-point group
    `cbdi.counters`): counter name -> action name. None when nothing is registered
    under that name here (a domain not installed); a ConfigError if it does not load or
    is not a mapping of names to names."""
    if simulator not in installed(COUNTERS):
        return {}
    found = load_plugin(COUNTERS, simulator, "world info", "simulator", "summary counters")
    if not isinstance(found, dict) or not all(
        isinstance(k, str) and k and isinstance(v, str) and v for k, v in found.items()
    ):
        raise ConfigError(
            "world info", "simulator", f"counters of {simulator!r}: not a mapping of names"
        )
    return dict(found)


# A domain's own percept messages (a `cbdi.wire.world.Percept` subclass each, e.g. the
# grid's `cbdi_recycling.wire:Percepts`), beside the generic `Sensed`.
PERCEPTS = "cbdi.percepts"


@cache
def percept_types() -> tuple[type[Percept], ...]:
    """Return every percept message a world may publish: `Sensed`, then the installed
    domains' own (entry-point group `cbdi.percepts`), by name; a ConfigError for one
    that does not load or is no `Percept`."""
    found: list[type[Percept]] = [Sensed]
    for name in installed(PERCEPTS):
        cls = load_plugin(PERCEPTS, name, "installed domains", name, "percept type")
        if not (isinstance(cls, type) and issubclass(cls, Percept)):
            raise ConfigError("installed domains", name, "percept type: not a Percept message")
        found.append(cls)
    return tuple(found)
