"""`cbdi-world` (also `cbdi world`): run the shared world service, hosting a simulator."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi_world.service import WorldSettings, build_world, world_main

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the world until SIGTERM/SIGINT; exit 2 on a bad map or settings."""
    try:
        settings = load_config(
            WorldSettings,
            argv,
            prog="cbdi-world",
            section="world",
            description="The shared world: hosts a domain's simulator (--simulator NAME, entry "
            "point cbdi.simulators) for every robot: clock, lockstep, percepts, snapshots.",
        )
        world = build_world(settings)
    except CbdiError as exc:  # a bad setting, or a map or option the simulator refuses
        print(f"cbdi-world: {exc}", file=sys.stderr)
        return 2
    return run_service(settings, "world", world_main(world))


if __name__ == "__main__":
    sys.exit(main())
