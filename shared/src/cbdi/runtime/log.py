"""Structured logs: one event per line, `key=value` (default) or JSON, on stderr."""

from __future__ import annotations

import json
import sys
import time
from typing import Any, TextIO

__all__ = ["Log"]

_LEVELS = {"debug": 10, "info": 20, "warning": 30, "error": 40}


def _kv(value: Any) -> str:
    text = str(value)
    if text == "" or any(c in text for c in ' "=\n'):
        return json.dumps(text)
    return text


class Log:
    """A structured logger bound to a service id: `log.info("started", key=1)`."""

    def __init__(
        self,
        service: str,
        *,
        level: str = "info",
        fmt: str = "kv",
        stream: TextIO | None = None,
    ) -> None:
        if level not in _LEVELS:
            raise ValueError(f"log level must be one of {sorted(_LEVELS)}, got {level!r}")
        if fmt not in ("kv", "json"):
            raise ValueError(f"log format must be kv or json, got {fmt!r}")
        self.service = service
        self.threshold = _LEVELS[level]
        self.fmt = fmt
        self.stream = stream or sys.stderr
        self.lost = 0  # lines that could not be written

    def event(self, level: str, event: str, **fields: Any) -> None:
        """Write one event line if `level` passes the threshold."""
        if _LEVELS[level] < self.threshold:
            return
        record = {"ts": f"{time.time():.3f}", "level": level, "service": self.service}
        record["event"] = event
        record.update(fields)
        if self.fmt == "json":
            line = json.dumps(record, default=str)
        else:
            line = " ".join(f"{k}={_kv(v)}" for k, v in record.items())
        try:
            self.stream.write(line + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # nobody reads (the supervisor died): lose the line,
            self.lost += 1  # not the service

    def debug(self, event: str, **fields: Any) -> None:
        self.event("debug", event, **fields)

    def info(self, event: str, **fields: Any) -> None:
        self.event("info", event, **fields)

    def warning(self, event: str, **fields: Any) -> None:
        self.event("warning", event, **fields)

    def error(self, event: str, **fields: Any) -> None:
        self.event("error", event, **fields)
