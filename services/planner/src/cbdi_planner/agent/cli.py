"""`cbdi-planner serve`: run the planner service of one agent.

`shell(args)` builds the same service from the same arguments without running it, for a
caller that runs several shells in one process (`cbdi replay --check`, through the
`cbdi.shells` entry-point group).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi.runtime.together import TogetherService
from cbdi_planner.agent.backends import BACKENDS
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.core import compiled
from cbdi_planner.errors import PlannerError
from cbdi_planner.pddl import parse_domain

__all__ = ["main", "shell"]

PROG = "cbdi-planner serve"


def shell(argv: Sequence[str] | None = None) -> TogetherService:
    """Build the planner that `cbdi-planner serve ARGV` runs; raise CbdiError or
    ValueError on bad settings, a bad agent file or a bad domain (what callers outside
    the planner know: the `cbdi.shells` contract)."""
    settings = load_config(
        PlannerSettings,
        argv,
        prog=PROG,
        section="planner",
        description="The planner of one agent.",
    )
    keys.validate_name(settings.agent)
    if not settings.agent_file:
        raise CbdiError("no agent file given (--agent-file FILE)")
    raw = read_agent_file(settings.agent_file, settings.agent)
    backend = settings.backend or raw.planning.backend
    if backend not in BACKENDS:
        raise CbdiError(f"unknown backend {backend!r} (known: {', '.join(BACKENDS)})")
    compiled()  # CBDI_SEARCH_CORE names a core that runs here (CoreError says what not)
    try:
        domain = parse_domain(raw.domain.read_text(encoding="utf-8"), str(raw.domain))
    except PlannerError as exc:
        raise CbdiError(str(exc)) from exc
    service = keys.service_id("planner", settings.agent)
    return TogetherService(service, settings, planner_main(settings, domain, raw))


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT; exit 2 on a bad agent file, domain or settings."""
    try:
        built = shell(argv)
    except (CbdiError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    return run_service(built.settings, built.service, built.main)


if __name__ == "__main__":
    sys.exit(main())
