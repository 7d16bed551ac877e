"""Die with the parent: a supervised service never outlives the supervisor that started it.

A supervisor (`cbdi up`) puts its pid in the child's environment (`child_env`); the
child, first thing at start-up, asks Linux for a signal when its parent dies
(`prctl(PR_SET_PDEATHSIG)`) and then checks that the parent is still the one named:
if it died between the fork and the `prctl`, no signal would ever come, so the child
ends at once. This holds even when the supervisor is killed with SIGKILL, which no
handler of its own can see. A child that is told to stop this way and does not manage
to within a grace period (a loop blocked, a worker thread that does not return) is
ended hard.

On systems without `prctl` (not Linux) the guard does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass

__all__ = [
    "NICE_ENV",
    "PARENT_ENV",
    "ParentGuard",
    "child_env",
    "die_with_parent",
    "guard_parent",
    "take_niceness",
]

PARENT_ENV = "CBDI_PARENT_PID"
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _load_prctl() -> Callable[..., int] | None:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        prctl: Callable[..., int] = libc.prctl
    except (OSError, AttributeError):
        return None
    return prctl


# Resolved once, before any fork: `die_with_parent` may run between fork and exec.
_prctl = _load_prctl()


def die_with_parent(sig: int = signal.SIGTERM) -> bool:
    """Ask for `sig` when the parent (thread) of this process ends; False if unsupported.

    Safe as a `preexec_fn`: one foreign call, resolved before the fork.
    """
    if _prctl is None:
        return False
    return _prctl(_PR_SET_PDEATHSIG, ctypes.c_ulong(sig), 0, 0, 0) == 0


def child_env() -> dict[str, str]:
    """Return the environment entry telling a child service who its supervisor is."""
    return {PARENT_ENV: str(os.getpid())}


@dataclass(frozen=True)
class ParentGuard:
    """A service's supervisor (pid 0: none), and what to do once it is gone."""

    parent: int = 0
    grace: float = 5.0

    @property
    def orphaned(self) -> bool:
        """True when a supervisor was named and this process is no longer its child."""
        return self.parent > 0 and os.getppid() != self.parent

    def stop_hard_later(self) -> None:
        """End the process after `grace` seconds if it is still there (orphans only).

        A thread, not a task: a blocked event loop would never run a task.
        """
        if not self.orphaned:
            return
        timer = threading.Timer(self.grace, os._exit, args=(1,))
        timer.daemon = True
        timer.start()


def guard_parent(env: Mapping[str, str] | None = None) -> ParentGuard:
    """Set the parent-death signal if a supervisor is named in `env` (default: ours).

    The name is removed from this process's environment, so that a program the service
    starts in turn is not taken for a child of our supervisor.
    """
    value = (os.environ if env is None else env).get(PARENT_ENV, "")
    os.environ.pop(PARENT_ENV, None)
    try:
        parent = int(value)
    except ValueError:
        return ParentGuard()
    if parent <= 0 or not die_with_parent():
        return ParentGuard()
    return ParentGuard(parent)


NICE_ENV = "CBDI_NICE"  # the niceness the launcher asks an agent's process to run at


def take_niceness(env: Mapping[str, str] | None = None) -> int:
    """Run at the niceness the launcher asked for (`CBDI_NICE`, 1 to 19: an agent's
    process yields the CPU to the router and the world); return it (0: none asked, or
    not a niceness). Call before any thread starts: threads inherit it."""
    value = (os.environ if env is None else env).get(NICE_ENV, "")
    try:
        nice = int(value)
    except ValueError:
        return 0
    if not 1 <= nice <= 19:
        return 0
    try:
        os.setpriority(os.PRIO_PROCESS, 0, max(os.getpriority(os.PRIO_PROCESS, 0), nice))
    except OSError:
        return 0
    return nice
