"""`cbdi agent`: run several components of an agent in one process over Zenoh.

    cbdi agent planner --agent robot1 --agent-file F -- scheduler --agent robot1 \\
        --agent-file F -- executor --agent robot1

Each section is a component name and the arguments its own command takes (`cbdi-planner
serve`, `cbdi-scheduler`, `cbdi-executor`). The components are found by name in the
`cbdi.shells` entry-point group (this library imports no service) and run as they would
alone: each its own asyncio service with its own Zenoh session, liveliness token and
heartbeat, on one event loop (`cbdi.runtime.service.run_services`). What they share is
one interpreter and its libraries, about half of a robot's memory. The process is their
unit of restart: when one ends, the others are stopped.

`cbdi up --agent-process` runs every BDI agent this way.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points

from cbdi.errors import CbdiError
from cbdi.runtime.service import Hosted, run_services

__all__ = ["SHELLS", "build", "main", "sections"]

SHELLS = "cbdi.shells"  # entry-point group: component name -> build(argv) -> Hosted
PROG = "cbdi agent"
SEPARATOR = "--"
USAGE = f"usage: {PROG} COMPONENT [ARGS...] [{SEPARATOR} COMPONENT [ARGS...]]..."


def sections(argv: Sequence[str]) -> list[tuple[str, list[str]]]:
    """Split `argv` at each `--` into (component, its arguments); raise CbdiError on an
    empty section or a component named twice."""
    out: list[tuple[str, list[str]]] = []
    part: list[str] = []
    for arg in [*argv, SEPARATOR]:
        if arg != SEPARATOR:
            part.append(arg)
            continue
        if not part or part[0].startswith("-"):
            raise CbdiError(f"each section needs a component name first ({USAGE})")
        if part[0] in (c for c, _ in out):
            raise CbdiError(f"component {part[0]!r} given twice")
        out.append((part[0], part[1:]))
        part = []
    return out


def build(argv: Sequence[str]) -> list[Hosted]:
    """Build every section's service; raise CbdiError naming an unknown component (and
    the installed ones), or the shell's own error on bad arguments."""
    found: dict[str, Callable[[list[str]], Hosted]] = {
        ep.name: ep.load() for ep in entry_points(group=SHELLS)
    }
    built = []
    for component, args in sections(argv):
        if component not in found:
            known = ", ".join(sorted(found)) or "none"
            raise CbdiError(f"no installed package builds a {component!r} (installed: {known})")
        built.append(found[component](args))
    return built


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM/SIGINT or until a component ends; exit 2 on bad arguments."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(f"{USAGE}\n\n{__doc__}")
        return 0 if args else 2
    try:
        services = build(args)
    except (CbdiError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    return run_services(services)


if __name__ == "__main__":
    sys.exit(main())
