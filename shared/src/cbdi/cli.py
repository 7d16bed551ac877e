"""`cbdi`: the umbrella command. Built-in subcommands plus those services register.

Services add subcommands through the `cbdi.commands` entry-point group (the world adds
`cbdi world`, the planner `cbdi plan`), so this library never imports a service.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points

__all__ = ["main"]

Command = Callable[[Sequence[str] | None], int]

_BUILTIN = {
    "agent": ("cbdi.runtime.host", "run components of an agent in one process"),
    "ctl": ("cbdi.ctl", "see and change a running agent's beliefs, desires, intentions"),
    "compose": ("cbdi.launcher.compose", "write a compose file running a scenario in containers"),
    "router": ("cbdi.router", "run a Zenoh router"),
    "up": ("cbdi.launcher.cli", "run a scenario: router, world and agents as processes"),
    "wait": ("cbdi.launcher.wait", "wait for the run's end; exit with its result"),
    "view": ("cbdi.view", "show the world as text, one frame per epoch"),
}


def _plugins() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group="cbdi.commands")}


def _usage(plugins: dict[str, object]) -> str:
    lines = ["usage: cbdi COMMAND [ARGS...]", "", "commands:"]
    for name, (_, text) in sorted(_BUILTIN.items()):
        lines.append(f"  {name:<10} {text}")
    for name, ep in sorted(plugins.items()):
        if name in _BUILTIN:
            continue
        lines.append(f"  {name:<10} (from {getattr(ep, 'value', '?').split(':')[0]})")
    lines.append("")
    lines.append("Run `cbdi COMMAND --help` for a command's options.")
    return "\n".join(lines)


def _resolve(name: str, plugins: dict[str, object]) -> Command | None:
    # A service's command wins over a built-in of the same name (the monitor's `view`
    # extends the built-in text view with rerun).
    if name in _BUILTIN and name not in plugins:
        module = __import__(_BUILTIN[name][0], fromlist=["main"])
        command: Command = module.main
        return command
    ep = plugins.get(name)
    if ep is None:
        return None
    loaded: Command = ep.load()  # type: ignore[attr-defined]
    return loaded


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch `cbdi COMMAND ...` to the command's own `main(argv)`."""
    args = list(sys.argv[1:] if argv is None else argv)
    plugins = _plugins()
    if not args or args[0] in ("-h", "--help", "help"):
        print(_usage(plugins))
        return 0 if args else 2
    command = _resolve(args[0], plugins)
    if command is None:
        print(f"cbdi: unknown command {args[0]!r}\n\n{_usage(plugins)}", file=sys.stderr)
        return 2
    return command(args[1:])


if __name__ == "__main__":
    sys.exit(main())
