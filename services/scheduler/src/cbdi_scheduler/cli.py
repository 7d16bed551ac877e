"""`cbdi-scheduler`: run the BDI scheduler of one agent."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi import keys
from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT; exit 2 on a bad agent file or settings."""
    try:
        settings = load_config(
            SchedulerSettings,
            argv,
            prog="cbdi-scheduler",
            section="scheduler",
            description="The BDI scheduler of an agent.",
        )
        keys.validate_name(settings.agent)
        if not settings.agent_file:
            raise CbdiError("no agent file given (--agent-file FILE)")
        mind = Mind(load_agent(settings.agent_file, settings.agent))
    except (CbdiError, ValueError) as exc:
        print(f"cbdi-scheduler: {exc}", file=sys.stderr)
        return 2
    return run_service(
        settings, keys.service_id("scheduler", settings.agent), scheduler_main(mind, settings)
    )


if __name__ == "__main__":
    sys.exit(main())
