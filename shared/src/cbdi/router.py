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
from cbdi.runtime import Log, ServiceContext, ServiceSettings, load_config, run_service

__all__ = ["RouterSettings", "main"]


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


def main(argv: Sequence[str] | None = None) -> int:
    """Run a Zenoh router until SIGTERM/SIGINT."""
    settings = load_config(
        RouterSettings,
        argv,
        prog="cbdi router",
        section="router",
        description="Run the Zenoh router every cbdi service connects to.",
    )
    if settings.acl or settings.users:
        from cbdi.security.denials import capture

        try:
            zenoh_config(settings.bus_config())  # bad files: said now, before the capture
        except CbdiError as exc:
            print(f"cbdi router: {exc}")
            return 2
        capture(Log("router", level=settings.log_level, fmt=settings.log_format))
    return run_service(settings, "router", _router)
