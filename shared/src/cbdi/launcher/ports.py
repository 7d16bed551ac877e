"""Free ports for a run's router (`cbdi up` without `--port`, and the tests)."""

from __future__ import annotations

import contextlib
import os
import random
import socket
from collections.abc import Mapping

from cbdi.errors import ConfigError

__all__ = ["PORTS_ENV", "free_port"]

PORTS_ENV = "CBDI_PORTS"  # LOW-HIGH: where `free_port` looks (default: the kernel's pick)


def free_port(environ: Mapping[str, str] = os.environ) -> int:
    """Return a TCP port on loopback that was free a moment ago.

    With `CBDI_PORTS=LOW-HIGH` it is one of those (drawn at random, checked free): a
    range below the kernel's ephemeral ports cannot be taken meanwhile by some outgoing
    connection's source port, and runs given disjoint ranges (parallel test workers)
    cannot pick the same one. ConfigError for a malformed range or one with no free port.
    """
    span = environ.get(PORTS_ENV, "").strip()
    if not span:
        return _bound_port(0)
    low, _, high = span.partition("-")
    if not (low.isdigit() and high.isdigit() and 1024 <= int(low) <= int(high) <= 65535):
        raise ConfigError(PORTS_ENV, span, "expected LOW-HIGH, ports 1024 to 65535")
    candidates = list(range(int(low), int(high) + 1))
    random.SystemRandom().shuffle(candidates)
    for port in candidates[:200]:
        with contextlib.suppress(OSError):
            return _bound_port(port)
    raise ConfigError(PORTS_ENV, span, "no free port found in the range")


def _bound_port(port: int) -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))
        return int(s.getsockname()[1])
