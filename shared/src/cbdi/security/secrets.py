"""A run's secrets on disk: one password per identity, the router's user list and ACL.

`create_secrets` writes, under a run directory (mode 0700):

- `credentials/<user>.json` (mode 0600), one per identity: `{"identity", "user",
  "password", "groups"}`, read by the service given it (`--credentials`, or
  `CBDI_CREDENTIALS`);
- `router/users.txt` (0600), `user:password` lines, Zenoh's `usrpwd` dictionary;
- `router/acl.json` (0600), the router's `access_control` (`cbdi.security.policy`).

Passwords are random (`secrets.token_urlsafe`), new for every run. A run's directory
is found again from its router's port (`run_dir`), so that `cbdi ctl --connect` finds
the operator's credentials of the run it talks to.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import secrets
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cbdi.errors import ConfigError
from cbdi.security.policy import Grant, acl_config, user_of

__all__ = [
    "CREDENTIALS_ENV",
    "Credentials",
    "RunSecrets",
    "create_secrets",
    "discover",
    "ensure_secrets",
    "read_credentials",
    "read_zenoh_settings",
    "run_dir",
]

CREDENTIALS_ENV = "CBDI_CREDENTIALS"
RUNS_ENV = "CBDI_RUNS_DIR"  # where `cbdi up` keeps its runs' secrets (default below)
_PORT = re.compile(r":(\d+)$")
MAKE_SECRETS = (
    "a run's secrets are made by `cbdi up`, by `cbdi compose` (beside the compose file) "
    "or, in a compose run, by its router (docs/security.md)"
)


@dataclass(frozen=True)
class Credentials:
    """One identity's Zenoh user and password, and the groups it may ask under."""

    identity: str
    user: str
    password: str
    groups: tuple[str, ...] = ()

    def __repr__(self) -> str:  # never print a password
        return f"Credentials(identity={self.identity!r}, user={self.user!r})"


@dataclass(frozen=True)
class RunSecrets:
    """Where a run's secrets are (see the module's docstring)."""

    root: Path

    def credentials(self, identity: str) -> Path:
        return self.root / "credentials" / f"{user_of(identity)}.json"

    @property
    def users(self) -> Path:
        return self.root / "router" / "users.txt"

    @property
    def acl(self) -> Path:
        return self.root / "router" / "acl.json"

    @property
    def hub(self) -> Path:
        """The hub router's Zenoh settings: its id (`{"id": ...}`, `--zenoh-config`)."""
        return self.root / "router" / "hub.json"

    def remove(self) -> None:
        """Delete the secrets (they are worth nothing once the router is gone)."""
        shutil.rmtree(self.root / "credentials", ignore_errors=True)
        shutil.rmtree(self.root / "router", ignore_errors=True)
        with contextlib.suppress(OSError):  # not empty: someone else's files too
            self.root.rmdir()


def _write_private(path: Path, text: str) -> None:
    """Write `text` to `path`, readable by its owner only, from its first byte on."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    path.parent.chmod(0o700)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        os.fchmod(f.fileno(), 0o600)  # an older file of looser mode keeps its mode otherwise
        f.write(text)


def create_secrets(root: Path, all_grants: Sequence[Grant]) -> RunSecrets:
    """Write a fresh password for every grant's identity, the user list and the ACL."""
    root.mkdir(parents=True, exist_ok=True, mode=0o700)
    root.chmod(0o700)
    out = RunSecrets(root)
    lines = []
    for g in all_grants:
        password = secrets.token_urlsafe(24)
        record = {"identity": g.identity, "user": g.user, "password": password}
        _write_private(out.credentials(g.identity), json.dumps({**record, "groups": g.groups}))
        lines.append(f"{g.user}:{password}")
    _write_private(out.users, "\n".join(lines) + "\n")
    hub = _zenoh_id()
    _write_private(out.hub, json.dumps({"id": hub}))
    _write_private(out.acl, json.dumps(acl_config(all_grants, hub), indent=1))
    return out


def ensure_secrets(root: Path, all_grants: Sequence[Grant]) -> bool:
    """Write the run's secrets in `root` unless it holds every grant's already; return
    whether it wrote them. Under a lock: the routers of a run's compose projects, and
    `cbdi compose`, may make them at once (the first writes, the others keep them)."""
    root.mkdir(parents=True, exist_ok=True, mode=0o700)
    with open(root / ".lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        have = RunSecrets(root)
        files = [
            have.acl,
            have.hub,
            have.users,
            *(have.credentials(g.identity) for g in all_grants),
        ]
        if all(f.is_file() for f in files):
            return False
        create_secrets(root, all_grants)
        return True


def _zenoh_id() -> str:
    """A random Zenoh id (16 bytes in hex; no zero at either end, which Zenoh would not
    print back the same)."""
    while True:
        zid = secrets.token_hex(16)
        if zid[0] != "0" and zid[-1] != "0":
            return zid


def read_credentials(path: str | Path) -> Credentials:
    """Read a credentials file; raise ConfigError naming the file and what is wrong."""
    where = str(path)
    try:
        data: Any = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(where, "credentials", f"file not found; {MAKE_SECRETS}") from None
    except OSError as exc:
        raise ConfigError(where, "credentials", exc.strerror or str(exc)) from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(where, "credentials", f"not a JSON credentials file: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(where, "credentials", "expected a JSON object")
    for name in ("user", "password"):
        if not isinstance(data.get(name), str) or not data[name] or ":" in data[name]:
            raise ConfigError(where, name, "missing, empty, not a string or with a ':'")
    groups = data.get("groups", [])
    if not isinstance(groups, list) or not all(isinstance(g, str) for g in groups):
        raise ConfigError(where, "groups", "expected a list of group names")
    identity = data.get("identity", data["user"])
    return Credentials(str(identity), data["user"], data["password"], tuple(groups))


def read_zenoh_settings(path: str | Path) -> dict[str, Any]:
    """Read a JSON object of Zenoh settings by path (`{"transport/link/tls/root_ca_certificate":
    "ca.pem"}`); raise ConfigError naming the file and what is wrong."""
    where = str(path)
    try:
        data: Any = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(where, "zenoh_config", "file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(where, "zenoh_config", f"not a JSON file: {exc}") from None
    if not isinstance(data, dict) or not all(isinstance(k, str) and k for k in data):
        raise ConfigError(where, "zenoh_config", 'expected {"path/of/key": value, ...}')
    return data


def _runs_root() -> Path:
    base = os.environ.get(RUNS_ENV) or os.environ.get("XDG_RUNTIME_DIR")
    return Path(base) / "cbdi" if base else Path.home() / ".cache" / "cbdi" / "runs"


def run_dir(port: int) -> Path:
    """Return the directory of the run whose router listens on `port` on this host."""
    return _runs_root() / f"run-{port}"


def discover(endpoints: Sequence[str], identity: str) -> Path | None:
    """Return the credentials of `identity` in the local run of the first endpoint
    (`tcp/127.0.0.1:PORT`) that has them, or None."""
    for endpoint in endpoints:
        match = _PORT.search(endpoint)
        if match:
            found = RunSecrets(run_dir(int(match.group(1)))).credentials(identity)
            if found.is_file():
                return found
    return None
