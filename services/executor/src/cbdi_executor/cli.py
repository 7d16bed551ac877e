"""`cbdi-executor`: run the executor of one agent."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi import keys
from cbdi.errors import ConfigError
from cbdi.runtime import load_config, run_service
from cbdi_executor.service import ExecutorSettings, executor_main

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT."""
    try:
        settings = load_config(
            ExecutorSettings,
            argv,
            prog="cbdi-executor",
            section="executor",
            description="Dispatch an agent's plans to the world.",
        )
        keys.validate_name(settings.agent)
    except (ConfigError, ValueError) as exc:
        print(f"cbdi-executor: {exc}", file=sys.stderr)
        return 2
    return run_service(
        settings, keys.service_id("executor", settings.agent), executor_main(settings)
    )


if __name__ == "__main__":
    sys.exit(main())
