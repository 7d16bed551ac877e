"""The `cbdi.shells` entry points: a component's service built from its command line.

`cbdi replay --check` finds the planner and scheduler through them (the monitor imports
no service), with the arguments the launcher recorded.
"""

from __future__ import annotations

import re
from importlib.metadata import entry_points

import pytest

from cbdi.agentfile import AgentFileError
from cbdi.errors import CbdiError
from cbdi.runtime import host
from tests_support import REPO

AGENT_FILE = str(REPO / "domains/recycling/agents/recycler.toml")


def shells() -> dict[str, object]:
    return {ep.name: ep.load() for ep in entry_points(group="cbdi.shells")}


def test_the_planner_and_scheduler_build_their_shells_from_their_arguments() -> None:
    found = shells()
    assert {"planner", "scheduler"} <= set(found)
    args = ["--agent", "robot2", "--agent-file", AGENT_FILE]
    planner = found["planner"]([*args, "--planning-speed", "1000"])  # type: ignore[operator]
    assert planner.service == "robot2/planner"
    assert planner.settings.planning_speed == 1000.0
    scheduler = found["scheduler"](args)  # type: ignore[operator]
    assert scheduler.service == "robot2/scheduler"
    assert scheduler.settings.agent_file == AGENT_FILE


def test_a_shell_refuses_a_missing_agent_file_by_name(tmp_path: object) -> None:
    missing = f"{tmp_path}/nowhere.toml"
    for name, build in shells().items():
        if name in ("executor", "world"):  # the ones without an agent file
            continue
        with pytest.raises(AgentFileError, match=r"nowhere\.toml"):
            build(["--agent", "robot1", "--agent-file", missing])  # type: ignore[operator]


def test_cbdi_agent_builds_one_agents_components_from_their_sections() -> None:
    args = ["--agent", "robot2", "--agent-file", AGENT_FILE]
    built = host.build(
        ["planner", *args, "--", "scheduler", *args, "--", "executor", "--agent", "robot2"]
    )
    assert [b.service for b in built] == ["robot2/planner", "robot2/scheduler", "robot2/executor"]
    assert built[2].settings.agent == "robot2"


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (
            ["mover", "--agent", "r"],
            "no installed package builds a 'mover' (installed: executor, planner",
        ),
        (["--agent", "r"], "each section needs a component name first"),
        (["executor", "--agent", "r", "--"], "each section needs a component name first"),
        (["executor", "--agent", "r", "--", "executor", "--agent", "r"], "'executor' given twice"),
    ],
)
def test_cbdi_agent_refuses_bad_sections_by_name(argv: list[str], says: str) -> None:
    with pytest.raises(CbdiError, match=re.escape(says)):
        host.build(argv)
    assert host.main(argv) == 2


def test_cbdi_agent_refuses_a_bad_component_argument_before_starting() -> None:
    assert host.main(["executor", "--agent", "robot 1"]) == 2
