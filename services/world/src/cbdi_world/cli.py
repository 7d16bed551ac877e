"""`cbdi-world` (also `cbdi world`): run the shared world service, hosting a simulator.

`shell` builds the world from its arguments without running it (the `cbdi.shells`
entry-point group): `cbdi up` builds it so before anything starts, to refuse a bad map,
domain or option with the world's own loaders.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from cbdi.errors import CbdiError
from cbdi.runtime import load_config, run_service
from cbdi.runtime.service import Hosted
from cbdi_world.service import WorldSettings, build_world, world_main

__all__ = ["main", "shell"]


def shell(argv: Sequence[str] | None = None) -> Hosted:
    """Build the world that `cbdi-world ARGV` runs; raise CbdiError on a bad setting, or
    a map or option the simulator refuses."""
    settings = load_config(
        WorldSettings,
        argv,
        prog="cbdi-world",
        section="world",
        description="The shared world: hosts a domain's simulator (--simulator NAME, entry "
        "point cbdi.simulators) for every robot: clock, lockstep, percepts, snapshots.",
    )
    return Hosted("world", settings, world_main(build_world(settings)))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the world until SIGTERM/SIGINT; exit 2 on a bad map or settings."""
    try:
        built = shell(argv)
    except CbdiError as exc:  # a bad setting, or a map or option the simulator refuses
        print(f"cbdi-world: {exc}", file=sys.stderr)
        return 2
    return run_service(built.settings, built.service, built.main)


if __name__ == "__main__":
    sys.exit(main())
