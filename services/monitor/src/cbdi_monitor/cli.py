"""`cbdi-monitor` (also `cbdi monitor`): record a running system to MCAP."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi.errors import ConfigError
from cbdi.runtime import load_config, run_service
from cbdi_monitor.service import MonitorSettings, monitor_main

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Record until SIGTERM/SIGINT, then finish the file."""
    try:
        settings = load_config(
            MonitorSettings,
            argv,
            prog="cbdi-monitor",
            section="monitor",
            description="Record every cbdi message to an MCAP file.",
        )
    except ConfigError as exc:
        print(f"cbdi-monitor: {exc}", file=sys.stderr)
        return 2
    return run_service(settings, "monitor", monitor_main(settings))


if __name__ == "__main__":
    sys.exit(main())
