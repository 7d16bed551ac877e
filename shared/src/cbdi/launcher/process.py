"""One supervised OS process of a run: started, log-prefixed, restarted by policy.

Every child is told the launcher's pid (`cbdi.runtime.parent`): it asks Linux for
SIGTERM when the launcher dies, even by SIGKILL, so a run leaves no orphan behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from cbdi.runtime.parent import child_env

__all__ = ["ManagedProcess", "ProcessSpec", "RestartPolicy"]

# glibc's malloc gives every thread that allocates an arena of its own; a service's
# worker and Zenoh threads so hold memory they freed (4 robots on campus-30x30: 10 MB
# each). Two arenas, unless the environment says otherwise.
MALLOC = {"MALLOC_ARENA_MAX": "2"}

RESTART_POLICIES = ("never", "on-failure", "always")
EXIT_BAD_CONFIG = 2  # what every cbdi service exits with on bad settings or input files
RESTART_ENV = "CBDI_RESTART"
STALL_FILE_ENV = "CBDI_STALL_FILE"  # where a child's stall watcher leaves its evidence


@dataclass(frozen=True)
class RestartPolicy:
    """When to restart a process that exited on its own, and how often at most."""

    mode: str = "on-failure"
    max_restarts: int = 3
    backoff: float = 0.5

    def __post_init__(self) -> None:
        if self.mode not in RESTART_POLICIES:
            raise ValueError(f"restart policy must be one of {RESTART_POLICIES}, got {self.mode!r}")

    def should_restart(self, returncode: int, restarts: int) -> bool:
        """Decide on a restart after an exit with `returncode` (negative: killed by signal)."""
        if restarts >= self.max_restarts or self.mode == "never":
            return False
        if returncode == EXIT_BAD_CONFIG:  # a bad map or setting will not mend itself
            return False
        return self.mode == "always" or returncode != 0


@dataclass(frozen=True)
class ProcessSpec:
    """What to run: a service id (`world`, `robot1/executor`), its argv and environment.

    `args` are the arguments after the program (the end of `argv`): what the service was
    told, as the launcher records it for a recording to say how to build it again.
    """

    service: str
    argv: tuple[str, ...]
    env: dict[str, str] = field(default_factory=dict)
    args: tuple[str, ...] = ()
    # The services the process runs when it runs several (`cbdi agent`), else empty.
    hosts: tuple[str, ...] = ()

    @classmethod
    def of(
        cls,
        service: str,
        program: Sequence[str],
        args: Sequence[str],
        env: dict[str, str],
        hosts: Sequence[str] = (),
    ) -> ProcessSpec:
        """Return the spec running `program` (an argv prefix) with `args`."""
        return cls(service, argv_of(program, args), env, tuple(args), tuple(hosts))

    @property
    def members(self) -> tuple[str, ...]:
        """The service ids this process runs: their liveliness and heartbeats are its."""
        return self.hosts or (self.service,)


LineSink = Callable[[str, str], None]


class ManagedProcess:
    """A child process whose output lines go to `sink(service, line)`."""

    def __init__(
        self, spec: ProcessSpec, policy: RestartPolicy, sink: LineSink, stall_file: str = ""
    ) -> None:
        self.spec = spec
        self.policy = policy
        self.sink = sink
        # The file its stall watcher writes its evidence to (`cbdi.runtime.stall`), read
        # by the watchdog when the network drops the heartbeats that carry it.
        self.stall_file = stall_file
        self.proc: asyncio.subprocess.Process | None = None
        self.restarts = 0
        self.freezes = 0  # times one of its processes was judged frozen (reported)
        self.freeze_kills = 0  # times one was killed for it
        self._frozen: set[int] = set()  # the pids judged frozen
        self.starved = 0  # times its loop stood for want of CPU (reported, not killed)
        self.exit_codes: list[int] = []
        self.tail: deque[str] = deque(maxlen=20)
        self.stopping = False
        self.failed = asyncio.Event()
        self._pumps: list[asyncio.Task[None]] = []

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    @property
    def running(self) -> bool:
        """True while the current process runs and is not being stopped."""
        return self.proc is not None and self.proc.returncode is None and not self.stopping

    async def start(self) -> None:
        """Start the process (again)."""
        # CBDI_RESTART: how many times it was restarted (0 at first), so a service can
        # tell a restart within the run from a new run (a recorder continues its file).
        restart = {RESTART_ENV: str(self.restarts)}
        if self.stall_file:
            restart[STALL_FILE_ENV] = self.stall_file
        env = {**MALLOC, **os.environ, **self.spec.env, **child_env(), **restart}
        self.proc = await asyncio.create_subprocess_exec(
            *self.spec.argv,
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
            env=env,
            start_new_session=True,  # Ctrl-C reaches the launcher only; it stops children in order
        )
        assert self.proc.stdout is not None and self.proc.stderr is not None
        self._pumps = [
            asyncio.create_task(self._pump(self.proc.stdout)),
            asyncio.create_task(self._pump(self.proc.stderr)),
        ]
        self.sink("launcher", f"started service={self.spec.service} pid={self.proc.pid}")

    async def _pump(self, stream: asyncio.StreamReader) -> None:
        while line := await stream.readline():
            text = line.decode(errors="replace").rstrip("\n")
            self.tail.append(text)
            self.sink(self.spec.service, text)

    def frozen(self, pid: int) -> None:
        """Count process `pid` judged frozen (once per process, reported or killed)."""
        if pid not in self._frozen:
            self._frozen.add(pid)
            self.freezes += 1

    def kill_frozen(self, pid: int) -> bool:
        """Kill process `pid` if it is still the current one (SIGKILL: a stopped process
        cannot handle SIGTERM); `supervise` then restarts it by policy."""
        proc = self.proc
        if proc is None or proc.pid != pid or proc.returncode is not None or self.stopping:
            return False
        self.frozen(pid)
        self.freeze_kills += 1
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        return True

    async def supervise(self) -> None:
        """Wait for exits and restart by policy until stopped or given up (sets `failed`)."""
        while True:
            assert self.proc is not None
            code = await self.proc.wait()
            await asyncio.gather(*self._pumps)
            self.exit_codes.append(code)
            if self.stopping:
                return
            if not self.policy.should_restart(code, self.restarts):
                self.sink("launcher", f"gave_up service={self.spec.service} exit_code={code}")
                self.failed.set()
                return
            self.restarts += 1
            self.sink(
                "launcher",
                f"restarting service={self.spec.service} exit_code={code} restart={self.restarts}",
            )
            await asyncio.sleep(self.policy.backoff)
            await self.start()

    async def stop(self, grace: float = 5.0) -> None:
        """Ask the process to stop (SIGTERM), then kill it after `grace` seconds."""
        self.stopping = True
        proc = self.proc
        if proc is None or proc.returncode is not None:
            return
        try:
            await self._terminate(proc, grace)
        finally:
            if proc.returncode is not None:
                self.exit_codes.append(proc.returncode)

    async def _terminate(self, proc: asyncio.subprocess.Process, grace: float) -> None:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGTERM)
        try:
            async with asyncio.timeout(grace):
                await proc.wait()
        except TimeoutError:
            self.sink("launcher", f"killing service={self.spec.service} after {grace:.0f} s")
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()


def console_script(name: str, module: str) -> tuple[str, ...]:
    """Return the argv prefix running console script `name` (next to this Python, or -m)."""
    import shutil
    import sys
    from pathlib import Path

    beside = Path(sys.executable).parent / name
    if beside.exists():
        return (str(beside),)
    found = shutil.which(name)
    return (found,) if found else (sys.executable, "-m", module)


def argv_of(*parts: str | Sequence[str]) -> tuple[str, ...]:
    """Flatten strings and sequences of strings into one argv tuple."""
    out: list[str] = []
    for part in parts:
        out.extend([part] if isinstance(part, str) else part)
    return tuple(out)
