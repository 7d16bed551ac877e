"""`cbdi-scheduler`: run the BDI scheduler of one agent.

`shell(args)` builds the same service from the same arguments without running it, for a
caller that runs several shells in one process (`cbdi replay --check`, through the
`cbdi.shells` entry-point group).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi import keys
from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi.runtime.together import TogetherService
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main

__all__ = ["main", "shell"]

PROG = "cbdi-scheduler"


def shell(argv: Sequence[str] | None = None) -> TogetherService:
    """Build the scheduler that `cbdi-scheduler ARGV` runs; raise CbdiError or ValueError
    on bad settings or a bad agent file."""
    settings = load_config(
        SchedulerSettings,
        argv,
        prog=PROG,
        section="scheduler",
        description="The BDI scheduler of an agent.",
    )
    keys.validate_name(settings.agent)
    if not settings.agent_file:
        raise CbdiError("no agent file given (--agent-file FILE)")
    mind = Mind(load_agent(settings.agent_file, settings.agent))
    service = keys.service_id("scheduler", settings.agent)
    return TogetherService(service, settings, scheduler_main(mind, settings))


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT; exit 2 on a bad agent file or settings."""
    try:
        built = shell(argv)
    except (CbdiError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    return run_service(built.settings, built.service, built.main)


if __name__ == "__main__":
    sys.exit(main())
