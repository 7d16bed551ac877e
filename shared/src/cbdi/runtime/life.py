"""How many times a service was started again after a failure, where no supervisor says
so (`CBDI_LIFE_FILE`): a container restarted by its restart policy.

`cbdi up` tells a restarted service its restart count (`CBDI_RESTART`). A container's
restart policy tells it nothing; but a volume of the container's own outlives its
process. With `CBDI_LIFE_FILE` naming a file there (`cbdi compose` does), a service
counts its starts in it: the first start finds no file (restart 0), each start after a
failure finds one more. A clean exit (code 0) removes the file, so the container
started again for a new run is a first start again.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import MutableMapping
from pathlib import Path

__all__ = ["LIFE_ENV", "RESTART_ENV", "count_start", "end_cleanly"]

LIFE_ENV = "CBDI_LIFE_FILE"
RESTART_ENV = "CBDI_RESTART"


def count_start(environ: MutableMapping[str, str] = os.environ) -> None:
    """With `CBDI_LIFE_FILE` and no `CBDI_RESTART`: set `CBDI_RESTART` to the starts the
    file counted, and count this one (once per process: the variable is then set)."""
    path = environ.get(LIFE_ENV)
    if not path or RESTART_ENV in environ:
        return
    life = Path(path)
    try:
        text = life.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        text = "0"
    except (OSError, UnicodeDecodeError) as exc:
        print(f"{LIFE_ENV} {path}: unreadable ({exc}); taken as a first start", file=sys.stderr)
        text = "0"
    starts = int(text) if text.isdigit() else 0
    try:
        life.parent.mkdir(parents=True, exist_ok=True)
        life.write_text(f"{starts + 1}\n", encoding="ascii")
    except OSError as exc:
        print(f"{LIFE_ENV} {path}: cannot write ({exc}); starts not counted", file=sys.stderr)
    environ[RESTART_ENV] = str(starts)


def end_cleanly(environ: MutableMapping[str, str] = os.environ) -> None:
    """After a clean exit: the next start is a first one again."""
    path = environ.get(LIFE_ENV)
    if path:
        with contextlib.suppress(OSError):
            Path(path).unlink(missing_ok=True)
