"""`cbdi router`: a Zenoh router in Python, so no separate zenohd binary is needed.

With `--users` (Zenoh's user-password dictionary, `user:password` lines) a client must
log in as one of them; with `--acl` (a JSON `access_control` configuration, as `cbdi up`
writes it, docs/security.md) the router lets through only what the rules allow, and
logs every refusal (`acl_denied`, `auth_refused`: `cbdi.security.denials`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cbdi.bus.zenoh_bus import DEFAULT_ENDPOINT, BusConfig, zenoh_config
from cbdi.errors import CbdiError, ConfigError
from cbdi.launcher.scenario import AGENT_KINDS
from cbdi.runtime import Log, ServiceContext, ServiceSettings, load_config, run_service
from cbdi.security.secrets import ensure_secrets

__all__ = ["RouterSettings", "main", "make_secrets"]


@dataclass(frozen=True)
class RouterSettings(ServiceSettings):
    """A router listens; it connects to nothing unless told to (to join other routers)."""

    mode: str = field(default="router", metadata={"help": "Zenoh mode (router)"})
    listen: tuple[str, ...] = field(
        default=(DEFAULT_ENDPOINT,), metadata={"help": "endpoints to listen on"}
    )
    connect: tuple[str, ...] = field(default=(), metadata={"help": "other routers to join"})
    users: str = field(
        default="", metadata={"help": "file of user:password lines: clients must log in"}
    )
    acl: str = field(default="", metadata={"help": "JSON access-control rules (deny by default)"})
    secrets_dir: str = field(
        default="",
        metadata={
            "help": "make the run's secrets in this directory first when it lacks them "
            "(a compose run on a fresh clone; kept when there: docs/security.md)"
        },
    )
    secrets_agents: tuple[str, ...] = field(
        default=(),
        metadata={"help": "the run's agents, NAME:KIND[:GROUP], for --secrets-dir"},
    )

    def bus_config(self) -> BusConfig:
        """The router's session: listening, with authentication and access control."""
        cfg = super().bus_config()
        extra: dict[str, Any] = dict(cfg.extra)
        if self.users:
            if not Path(self.users).is_file():
                raise ConfigError(self.users, "users", "file not found")
            extra["transport/auth/usrpwd/dictionary_file"] = str(Path(self.users).resolve())
        if self.acl:
            extra["access_control"] = _read_acl(self.acl)
        return BusConfig(
            mode=cfg.mode,
            connect=cfg.connect,
            listen=cfg.listen,
            connect_timeout=cfg.connect_timeout,
            extra=extra,
            user=cfg.user,
            password=cfg.password,
        )


def _read_acl(path: str) -> dict[str, Any]:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(path, "acl", "file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(path, "acl", f"not a JSON access-control file: {exc}") from None
    if not isinstance(data, dict) or data.get("enabled") is not True:
        raise ConfigError(path, "acl", "expected a JSON object with enabled: true")
    return data


async def _router(ctx: ServiceContext) -> None:
    secured = "acl" if ctx.settings.acl else "users" if ctx.settings.users else "none"
    ctx.log.info("routing", listen=",".join(ctx.settings.listen), security=secured)


def make_secrets(settings: RouterSettings) -> bool:
    """Make the run's secrets in `secrets_dir` unless it holds them; return whether it
    wrote them. ConfigError: a bad NAME:KIND[:GROUP] (GROUP: the agent file's, under
    which its scheduler may ask the others)."""
    from cbdi.launcher.compose import compose_grants  # the run's identities

    agents, groups = [], {}
    for entry in settings.secrets_agents:
        name, _, rest = entry.partition(":")
        kind, _, group = rest.partition(":")
        if kind not in AGENT_KINDS or not name:
            known = ", ".join(AGENT_KINDS)
            why = f"expected NAME:KIND[:GROUP], KIND one of {known}"
            raise ConfigError("--secrets-agents", entry, why)
        agents.append((name, kind))
        if group:
            groups[name] = group
    return ensure_secrets(Path(settings.secrets_dir), compose_grants(agents, groups))


def main(argv: Sequence[str] | None = None) -> int:
    """Run a Zenoh router until SIGTERM/SIGINT."""
    settings = load_config(
        RouterSettings,
        argv,
        prog="cbdi router",
        section="router",
        description="Run the Zenoh router every cbdi service connects to.",
    )
    if settings.secrets_dir:
        try:
            if make_secrets(settings):
                print(f"cbdi router: made the run's secrets in {settings.secrets_dir}")
        except (CbdiError, OSError) as exc:
            print(f"cbdi router: {exc}")
            return 2
    if settings.acl or settings.users:
        from cbdi.security.denials import capture

        try:
            zenoh_config(settings.bus_config())  # bad files: said now, before the capture
        except CbdiError as exc:
            print(f"cbdi router: {exc}")
            return 2
        capture(Log("router", level=settings.log_level, fmt=settings.log_format))
    return run_service(settings, "router", _router)
