"""The router's refusals, as structured log events.

Zenoh reports an access-control decision only as a `trace` event of its target
`zenoh::net::routing::interceptor::access_control` ("<zid> on ...+Username(u)+... is
unauthorized to Put (ingress) on KEY", or "Using cached result: <zid> is unauthorized
..."), and a failed login as a `debug` event of
`zenoh_transport::unicast::establishment::accept` ("UsrPwd extension - Recv OpenSyn.
Invalid password."). Zenoh writes its log on stdout. So the router sends its stdout
into a pipe (`capture`), a thread reads it, and each refusal becomes an event of the
router's own log: `acl_denied user=robot2.executor action=query flow=ingress
key=cbdi/world/rpc/act/robot1 count=1`, `auth_refused reason=...`. Decisions that
allow are dropped. A flood costs log lines in log2 of its size: a refusal of one user,
action and key is logged the 1st, 2nd, 4th, 8th... time, with its count.
"""

from __future__ import annotations

import os
import re
import sys
import threading
from collections import Counter
from dataclasses import dataclass

import zenoh

from cbdi.runtime.log import Log

__all__ = ["LOG_FILTER", "Denial", "DenialLog", "capture", "parse"]

LOG_FILTER = (
    "off,zenoh::net::routing::interceptor::access_control=trace,"
    "zenoh_transport::unicast::establishment::accept=debug"
)
_MAX_KINDS = 10_000  # distinct (user, action, flow, key) counted at most
_DENIED = re.compile(
    r"(?:Using cached result: )?(?P<zid>[0-9a-f]+)(?: on (?P<subject>\S+))? is unauthorized"
    r" to (?P<action>.+?) \((?P<flow>ingress|egress)\) on (?P<key>\S+)"
)
_USER = re.compile(r"Username\(([^)]*)\)")
_AUTH = re.compile(r"UsrPwd extension - (?P<reason>Recv \w+\. [^.]+)\.")
_NO_SUBJECT = re.compile(r"(?P<zid>[0-9a-f]+) did not match any configured ACL subject")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
# How Zenoh words the actions when it works out a cache (a real declaration is worded
# `Declare Subscriber`, `Liveliness Token`...).
_EVALUATED = frozenset(
    (
        "Query",
        "Reply",
        "Put",
        "Delete",
        "Declare/Undeclare Subscriber",
        "Declare/Undeclare Queryable",
        "Declare/Undeclare Liveliness Token",
        "Liveliness Query",
        "Declare Liveliness Subscriber",
    )
)
_MARKS = (b"unauthorized", b"caching permissions", b"UsrPwd", b"did not match")
_THREAD = re.compile(r"ThreadId\((\d+)\)")
_CACHING = re.compile(r"ACL \((ingress|egress)\): caching permissions for `([^`]*)`")


@dataclass(frozen=True)
class Denial:
    """One refusal: who (`user`, or the session id when unknown), what, which way, where."""

    user: str
    action: str
    flow: str
    key: str


def _action(text: str) -> str:
    """`Declare/Undeclare Subscriber` -> `declare_subscriber`, `Put` -> `put`."""
    return text.replace("Declare/Undeclare", "Declare").lower().replace(" ", "_")


class DenialLog:
    """Turn Zenoh's log lines into events of `log`; remember which session is which user."""

    def __init__(self, log: Log) -> None:
        self.log = log
        self.users: dict[str, str] = {}
        self.counts: Counter[Denial] = Counter()
        self.auth_refused = 0
        # thread -> (flow, key, user) of the permissions it is caching now
        self._caching: dict[str, tuple[str, str, str]] = {}

    def line(self, text: str) -> None:
        """Take one line of Zenoh's log (refusals, caching, logins; not what is allowed).

        When a client declares a key expression, Zenoh works out (and caches) every
        permission on it at once, for one session and one way: a "ACL (ingress): caching
        permissions for `K`" line, then a line per kind of message, allowed or not, on
        that thread. Those are not refusals; what is refused later on `K` shows as
        "Using cached result: ...".
        """
        thread = _THREAD.search(text)
        where = thread.group(1) if thread else ""
        caching = _CACHING.search(text)
        if caching:
            self._caching[where] = (caching.group(1), caching.group(2), "")
            return
        if "unauthorized" in text:
            parsed = parse(text, self.users)
            if parsed is None:
                return
            found, wording = parsed
            cached = "Using cached result" in text
            if not cached and wording in _EVALUATED and self._working_out(where, found):
                return
            self.denied(found)
        elif "UsrPwd extension - Recv" in text:
            match = _AUTH.search(text)
            self.auth_refused += 1
            reason = match.group("reason") if match else "refused"
            self.log.warning("auth_refused", reason=reason, count=self.auth_refused)
        elif "did not match any configured ACL subject" in text:
            match = _NO_SUBJECT.search(text)
            self.log.warning("acl_no_subject", zid=match.group("zid") if match else "?")

    def _working_out(self, thread: str, d: Denial) -> bool:
        """Whether `d` is a line of the cache being worked out on `thread`."""
        state = self._caching.get(thread)
        if state is None or (state[0], state[1]) != (d.flow, d.key):
            self._caching.pop(thread, None)
            return False
        if state[2] and state[2] != d.user:
            return False
        self._caching[thread] = (d.flow, d.key, d.user)
        return True

    def denied(self, d: Denial) -> None:
        if d not in self.counts and len(self.counts) >= _MAX_KINDS:
            d = Denial("(many)", "(many)", d.flow, "(many)")
        self.counts[d] += 1
        n = self.counts[d]
        if n & (n - 1) == 0:  # a power of two
            self.log.warning(
                "acl_denied", user=d.user, action=d.action, flow=d.flow, key=d.key, count=n
            )


def parse(text: str, users: dict[str, str]) -> tuple[Denial, str] | None:
    """Read a refusal from one log line, learning session ids' users in `users`; return
    it with Zenoh's wording of the action (`Declare/Undeclare Subscriber`)."""
    match = _DENIED.search(_ANSI.sub("", text))
    if match is None:
        return None
    zid, subject = match.group("zid"), match.group("subject") or ""
    named = _USER.search(subject)
    if named:
        users[zid] = named.group(1)
    user = users.get(zid, zid)
    wording = match.group("action")
    return Denial(user, _action(wording), match.group("flow"), match.group("key")), wording


def _pump(fd: int, denials: DenialLog) -> None:
    """Read Zenoh's log from `fd` until it closes; pass on what is not Zenoh's."""
    rest = b""
    with os.fdopen(fd, "rb", buffering=0) as pipe:
        while chunk := pipe.read(65536):
            lines = (rest + chunk).split(b"\n")
            rest = lines.pop()
            for raw in lines:
                if b"zenoh" not in raw:  # someone else's print: keep it
                    sys.stderr.write(raw.decode("utf-8", "replace") + "\n")
                elif any(mark in raw for mark in _MARKS):
                    denials.line(raw.decode("utf-8", "replace"))


def capture(log: Log) -> DenialLog:
    """Send this process's stdout (Zenoh's log) into a reader of refusals, and turn on
    Zenoh's log of access-control decisions (`RUST_LOG` overrides `LOG_FILTER`).

    Call once, before the first Zenoh session opens.
    """
    denials = DenialLog(log)
    read, write = os.pipe()
    sys.stdout.flush()
    os.dup2(write, 1)
    os.close(write)
    thread = threading.Thread(target=_pump, args=(read, denials), name="acl-log", daemon=True)
    thread.start()
    zenoh.init_log_from_env_or(LOG_FILTER)
    return denials
