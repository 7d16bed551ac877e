"""The `cbdi.shells` entry points: a component's service built from its command line.

`cbdi replay --check` finds the planner and scheduler through them (the monitor imports
no service), with the arguments the launcher recorded.
"""

from __future__ import annotations

from importlib.metadata import entry_points

import pytest

from cbdi.agentfile import AgentFileError
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
    for build in shells().values():
        with pytest.raises(AgentFileError, match=r"nowhere\.toml"):
            build(["--agent", "robot1", "--agent-file", missing])  # type: ignore[operator]
