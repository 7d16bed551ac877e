"""Errors of the cbdi common library.

Each failure a caller may want to handle differently has its own class; all derive from
`CbdiError` so a service can log and count any of them without a bare `except`.
"""

from __future__ import annotations

__all__ = [
    "BusClosedError",
    "CbdiError",
    "ConfigError",
    "RejectedInputError",
    "RequestFailedError",
    "RequestTimeoutError",
    "WireError",
]


class CbdiError(Exception):
    """Base class of every error raised by cbdi code."""


class WireError(CbdiError):
    """Reject a payload that is not a valid message of the expected schema.

    `schema` names what was expected, `reason` says what was wrong (garbage bytes, a field
    of the wrong type, a missing field, another schema), `key` where it arrived, if known.
    """

    def __init__(self, schema: str, reason: str, key: str | None = None, sender: str = "") -> None:
        self.schema = schema
        self.reason = reason
        self.key = key
        self.sender = sender
        where = f" on {key}" if key else ""
        source = f" from {sender}" if sender else ""
        super().__init__(f"bad {schema} message{source}{where}: {reason}")


class RejectedInputError(CbdiError):
    """Report a valid message whose handling failed with a domain error (and was dropped).

    `schema` is the message's, `sender` who sent it (its `agent` field, if any), `key`
    where it arrived, `reason` the domain error, `code` the domain error's own code
    (`bad_request`, `unknown_plan`, ...) or `rejected`.
    """

    def __init__(
        self, schema: str, reason: str, key: str, sender: str = "", code: str = "rejected"
    ) -> None:
        self.code = code
        self.schema = schema
        self.reason = reason
        self.key = key
        self.sender = sender
        source = f" from {sender}" if sender else ""
        super().__init__(f"rejected {schema} message{source} on {key}: {reason}")


class ConfigError(CbdiError):
    """Reject a configuration value, naming the source (flag, env, file) and the field."""

    def __init__(self, source: str, field: str, reason: str) -> None:
        self.source = source
        self.field = field
        self.reason = reason
        super().__init__(f"{source}: {field}: {reason}")


class BusClosedError(CbdiError):
    """Raise when a bus operation is attempted after the bus was closed."""


class RequestTimeoutError(CbdiError):
    """Raise when a request got no reply in time (nobody serves the key, or it is slow)."""

    def __init__(self, key: str, timeout: float) -> None:
        self.key = key
        self.timeout = timeout
        super().__init__(f"no reply on {key} within {timeout:.3f} s")


class RequestFailedError(CbdiError):
    """Raise when the server answered a request with an error reply."""

    def __init__(self, key: str, code: str, message: str) -> None:
        self.key = key
        self.code = code
        self.message = message
        super().__init__(f"request on {key} failed: {code}: {message}")
