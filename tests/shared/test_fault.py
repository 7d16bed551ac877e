"""Faults injected at a chosen epoch (`cbdi.runtime.fault`): parsing, the first life
only, `cbdi up --fault` and `cbdi compose --fault` checking what they are given."""

from __future__ import annotations

import asyncio
import io
import os
import shutil
import signal
import subprocess
import sys

import pytest

from cbdi import keys
from cbdi.bus import MemoryBus
from cbdi.errors import ConfigError
from cbdi.launcher.cli import check_faults
from cbdi.launcher.compose import ComposeOptions, compose_file
from cbdi.launcher.scenario import find_scenario, load_scenario
from cbdi.runtime.fault import Fault, parse_faults, planned_fault
from cbdi.runtime.log import Log
from cbdi.runtime.service import ServiceContext, fault_at_epoch
from cbdi.wire.base import encode
from cbdi.wire.world import Tick


def test_faults_parse_from_several_texts_and_comma_lists() -> None:
    faults = parse_faults(["world:kill@12,robot1/planner:stop@8", " monitor:kill@0 "])
    assert faults == (
        Fault("world", "kill", 12),
        Fault("robot1/planner", "stop", 8),
        Fault("monitor", "kill", 0),
    )
    assert ",".join(map(str, faults)) == "world:kill@12,robot1/planner:stop@8,monitor:kill@0"
    assert parse_faults([]) == () and parse_faults([""]) == ()


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("world", "expected SERVICE:KIND@EPOCH"),
        ("world:kill", "expected SERVICE:KIND@EPOCH"),
        ("world:kill@-1", "expected SERVICE:KIND@EPOCH"),
        ("world:kill@x", "expected SERVICE:KIND@EPOCH"),
        ("world:explode@3", "unknown kind 'explode'"),
        ("world:kill@99999999999", "expected SERVICE:KIND@EPOCH"),
        ("world:kill@9999999999", "is past"),
        ("/world:kill@3", "no service id"),
        ("robot1//planner:kill@3", "no service id"),
        ("world:kill@3,world:stop@4", "has a fault already"),
        ("wo rld:kill@3", "expected SERVICE:KIND@EPOCH"),
    ],
)
def test_a_malformed_fault_is_refused_naming_it(text: str, says: str) -> None:
    with pytest.raises(ValueError, match=says) as caught:
        parse_faults([text])
    assert "fault " in str(caught.value)


def test_a_fault_strikes_in_the_first_life_only() -> None:
    faults = parse_faults(["world:kill@12,robot1/planner:kill@3"])
    assert planned_fault("world", faults, {}) == Fault("world", "kill", 12)
    assert planned_fault("world", faults, {"CBDI_RESTART": "0"}) == Fault("world", "kill", 12)
    assert planned_fault("world", faults, {"CBDI_RESTART": "1"}) is None
    assert planned_fault("robot1/executor", faults, {}) is None


def test_strike_kills_or_stops_the_process_it_runs_in() -> None:
    code = (
        "import sys; from cbdi.runtime.fault import Fault, strike\n"
        "strike(Fault('x', sys.argv[1], 0)); print('survived')"
    )
    killed = subprocess.run([sys.executable, "-c", code, "kill"], capture_output=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL and b"survived" not in killed.stdout
    stopped = subprocess.Popen([sys.executable, "-c", code, "stop"], stdout=subprocess.PIPE)
    try:
        # A stopped child is reported by waitpid with WUNTRACED; poll() would not see it.
        _, status = os.waitpid(stopped.pid, os.WUNTRACED)
        assert os.WIFSTOPPED(status)
        stopped.send_signal(signal.SIGCONT)
        out, _ = stopped.communicate(timeout=60)
        assert out.strip() == b"survived"
    finally:
        stopped.kill()


def test_strike_kills_a_containers_init_process_too() -> None:
    """As pid 1 of its own pid namespace (a container's main process) a process cannot
    signal itself to death: the kill is then an exit with nothing flushed (137)."""
    unshare = shutil.which("unshare")
    assert unshare, "unshare (util-linux) is missing"
    code = (
        "import os; from cbdi.runtime.fault import Fault, strike\n"
        "print(os.getpid(), flush=True); strike(Fault('x', 'kill', 0)); print('survived')"
    )
    done = subprocess.run(
        [unshare, "--pid", "--fork", sys.executable, "-c", code], capture_output=True, timeout=60
    )
    assert done.stdout.split() == [b"1"], done.stdout + done.stderr
    assert done.returncode == 128 + signal.SIGKILL


def _paper(agents: int = 2):  # type: ignore[no-untyped-def]
    return load_scenario(find_scenario("paper-7x7")).with_agents(agents)


def test_cbdi_up_checks_faults_against_the_runs_services() -> None:
    scenario = _paper()
    assert check_faults(["world:kill@12", "robot2/executor:stop@3"], scenario) == (
        "world:kill@12,robot2/executor:stop@3"
    )
    assert check_faults([], scenario) == ""
    assert check_faults(["monitor:kill@4"], scenario, record="run.mcap") == "monitor:kill@4"
    with pytest.raises(ConfigError, match="no such service in this run"):
        check_faults(["monitor:kill@4"], scenario)  # nothing recorded: no monitor
    with pytest.raises(ConfigError, match="robot1/planner"):
        check_faults(["robot3/planner:kill@4"], scenario)  # the known ones listed
    with pytest.raises(ConfigError, match="--fault"):
        check_faults(["world:kill"], scenario)


def test_cbdi_up_refuses_a_bad_fault_before_anything_starts() -> None:
    from tests_support import cbdi_up

    done = cbdi_up("paper-7x7", "--fault", "robot9/planner:kill@3", timeout=60)
    assert done.returncode == 2, done.stderr
    assert "--fault" in done.stderr and "robot9/planner" in done.stderr
    assert "started service" not in done.stderr


def test_compose_gives_each_fault_to_its_service_only() -> None:
    opts = ComposeOptions(faults=("world:kill@12", "robot1/planner:kill@15"))
    blocks: dict[str, str] = {}
    service = ""
    for line in compose_file(_paper(), opts).splitlines():  # a service: two spaces, a colon
        if line.startswith("  ") and not line.startswith("   ") and line.endswith(":"):
            service = line.strip()[:-1]
        elif service:
            blocks[service] = blocks.get(service, "") + line.strip() + "\n"
    assert "CBDI_FAULT: world:kill@12" in blocks["world"]
    assert "CBDI_FAULT: robot1/planner:kill@15" in blocks["robot1-planner"]
    faulted = [name for name, block in blocks.items() if "CBDI_FAULT" in block]
    assert sorted(faulted) == ["robot1-planner", "world"]
    with pytest.raises(ConfigError, match="not a service a container run can fault"):
        compose_file(_paper(), ComposeOptions(faults=("router:kill@3",)))
    with pytest.raises(ConfigError, match="--fault"):
        compose_file(_paper(), ComposeOptions(faults=("world:boom@3",)))


async def test_the_watcher_strikes_at_the_first_tick_of_its_epoch_or_after() -> None:
    bus, out = MemoryBus(), io.StringIO()
    ctx = ServiceContext("robot1/planner", bus, Log("robot1/planner", stream=out))
    struck: list[Fault] = []
    fault = Fault("robot1/planner", "kill", 5)
    watcher = asyncio.create_task(fault_at_epoch(ctx, fault, struck.append))
    await asyncio.sleep(0)
    for epoch in (3, 4, 6, 7):  # epoch 5 went by unseen: the next one strikes
        tick = Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=1.0, lockstep=True)
        await bus.publish(keys.world_stream("clock"), encode(tick))
        await asyncio.sleep(0)
        assert struck == ([] if epoch < 5 else [fault]), epoch
        if struck:
            break
    await asyncio.wait_for(watcher, 5)
    assert struck == [fault]
    assert "event=fault_injected fault=robot1/planner:kill@5 epoch=6" in out.getvalue()
