"""`cbdi-executor`: run the executor of one agent.

`shell(args)` builds the same service from the same arguments without running it, for a
caller that runs several shells in one process (`cbdi agent`, through the `cbdi.shells`
entry-point group).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence

from cbdi import keys
from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi.runtime.together import TogetherService
from cbdi_executor.service import ExecutorSettings, condition_waits, executor_main

__all__ = ["main", "shell"]

PROG = "cbdi-executor"


def shell(argv: Sequence[str] | None = None) -> TogetherService:
    """Build the executor that `cbdi-executor ARGV` runs; raise CbdiError or ValueError
    on bad settings."""
    settings = load_config(
        ExecutorSettings,
        argv,
        prog=PROG,
        section="executor",
        description="Dispatch an agent's plans to the world.",
    )
    keys.validate_name(settings.agent)
    for action in settings.performer:
        keys.validate_name(action, "performer action")
    if not (math.isfinite(settings.condition_wait) and settings.condition_wait >= 0):
        raise ValueError(f"condition_wait {settings.condition_wait}: expected seconds >= 0")
    for action in condition_waits(settings.condition_wait_for):
        keys.validate_name(action, "condition_wait_for action")
    service = keys.service_id("executor", settings.agent)
    return TogetherService(service, settings, executor_main(settings))


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT; exit 2 on bad settings."""
    try:
        built = shell(argv)
    except (CbdiError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    return run_service(built.settings, built.service, built.main)


if __name__ == "__main__":
    sys.exit(main())
