"""Check a run before anything of it starts: every service is built as it will run.

The scenario file was read already (`load_scenario`: its map exists, its simulator and
options, each BDI agent's agent file and who performs its actions); what only a service
reads is its own: the world its map and domain (the simulator refuses a bad map), the
planner the agent file's PDDL domain, the scheduler the rest of the agent file (beliefs,
desires, rules, knowledge). Each is built by its own shell (`cbdi.shells`, the code the
service runs; this library imports no service) from the arguments it will be given, and
the first refusal is returned to `cbdi up` (exit 2) before a router or any process runs.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.metadata import entry_points

from cbdi.errors import CbdiError, ConfigError
from cbdi.launcher.scenario import Scenario
from cbdi.launcher.services import plan_services
from cbdi.runtime.host import SHELLS

__all__ = ["check_services"]

# An address nothing listens on: building a shell opens no bus.
_NOWHERE = "tcp/127.0.0.1:0"


def check_services(scenario: Scenario) -> None:
    """Build every service of `scenario` that has a shell; raise ConfigError naming the
    service and, from its own loader, the file and the field it refuses."""
    # A plan runs a module (`cbdi_world.cli`); the shell of that module builds it. A
    # plan run by another command (the router, a scripted agent: `cbdi.cli`) has none.
    found = {ep.module: ep for ep in entry_points(group=SHELLS)}
    for plan in plan_services(scenario, _NOWHERE):
        shell = found.get(plan.module)
        if shell is None:
            continue
        build: Callable[[list[str]], object] = shell.load()
        try:
            build(list(plan.args))
        except (CbdiError, ValueError) as exc:
            raise ConfigError(plan.service, "refused", str(exc)) from None
