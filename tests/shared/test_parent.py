"""A supervised process dies with its supervisor, even one killed by SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

from tests_support import wait_for

CHILD = textwrap.dedent(
    """
    import time
    from cbdi.runtime.parent import guard_parent
    guard = guard_parent()
    print("guarded", guard.parent, flush=True)
    time.sleep(60)
    """
)

SUPERVISOR = textwrap.dedent(
    f"""
    import os, subprocess, sys, time
    from cbdi.runtime.parent import child_env
    subprocess.Popen([sys.executable, "-c", {CHILD!r}], env={{**os.environ, **child_env()}})
    time.sleep(60)
    """
)


def gone(pid: int) -> bool:
    """True once `pid` is no process, or a zombie nobody reaped yet."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def test_the_child_gets_sigterm_when_its_supervisor_is_killed() -> None:
    sup = subprocess.Popen([sys.executable, "-c", SUPERVISOR], stdout=subprocess.PIPE, text=True)
    try:
        assert sup.stdout is not None
        line = sup.stdout.readline().split()
        assert line[:2] == ["guarded", str(sup.pid)]
        child = [int(p) for p in os.listdir("/proc") if p.isdigit() and _parent(int(p)) == sup.pid]
        assert len(child) == 1
        sup.send_signal(signal.SIGKILL)
        wait_for(lambda: gone(child[0]), timeout=10, what="the child to die with its parent")
    finally:
        sup.kill()
        sup.wait()


def test_a_child_whose_supervisor_is_already_gone_knows_it() -> None:
    code = (
        "from cbdi.runtime.parent import guard_parent; import os;"
        "g = guard_parent({'CBDI_PARENT_PID': str(os.getppid() + 100000)});"
        "print(g.orphaned, 'CBDI_PARENT_PID' in os.environ)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "False"]


def test_without_a_named_supervisor_nothing_is_guarded() -> None:
    code = "from cbdi.runtime.parent import guard_parent; print(guard_parent({}).parent)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "0"


def _parent(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except (FileNotFoundError, ProcessLookupError):
        return -1
