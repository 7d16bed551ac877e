"""Domain plug-ins found by name in an entry-point group.

A domain's package registers what the generic services load (`cbdi.knowledge` for the
scheduler, `cbdi.bindings` for the world, ...); a configuration names one, and a name
that is not installed is a `ConfigError` saying which are.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Protocol

from cbdi.errors import ConfigError
from cbdi.wire.world import ActionRequest

__all__ = ["BINDINGS", "ActionBinding", "installed", "load_binding", "load_plugin"]

BINDINGS = "cbdi.bindings"


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


class ActionBinding(Protocol):
    """How a world performs a domain's PDDL actions."""

    actions: tuple[str, ...]  # the PDDL actions it performs

    def primitive(self, req: ActionRequest) -> ActionRequest:
        """The world's own request for the grounded PDDL action `req`; raise CbdiError
        (the reason the world rejects it) for an action or arguments it cannot perform."""
        ...


def load_binding(name: str, source: str = "world") -> ActionBinding:
    """Return a new binding `name` (entry-point group `cbdi.bindings`)."""
    factory = load_plugin(BINDINGS, name, source, "binding", "action binding")
    binding: ActionBinding = factory()  # type: ignore[operator]
    return binding
