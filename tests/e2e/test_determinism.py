"""Virtual time makes a run a function of its inputs (issue 12): the same scenario, flags
and seed give the same world request trace, epoch by epoch, however loaded the machine,
whatever the start order; another seed gives another run. And the same `--json`
summary, every count of it, but for its wall-clock and host figures (issue 32).

Every run here is real processes over real Zenoh (`cbdi up`), flat out (`--speed 0`: an
epoch starts as soon as every member acknowledged the one before), while two processes
burn both cores.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from tests_support import REPO, cbdi_up, cpu_load

pytestmark = pytest.mark.e2e

# The summary's wall-clock and host figures, named by docs/architecture.md ("The summary
# too"): every other figure of a lockstep run is a function of its inputs.
WALL_CLOCK = (
    "wall_time",
    "lateness",
    "memory",
    "freezes",
    "freeze_kills",
    "starved",
    "search_seconds",
)


def run(*args: str, timeout: float = 400) -> dict[str, Any]:
    result = cbdi_up(*args, "--speed", "0", "--json", "--quiet", timeout=timeout)
    assert result.returncode in (0, 3), result.stderr[-3000:]
    summary: dict[str, Any] = json.loads(result.stdout)
    assert summary["trace_digest"] and summary["requests"] > 0 and not summary["stalls"]
    return summary


def comparable(figures: Any) -> Any:
    """Return the summary without its wall-clock and host figures, at any depth."""
    if isinstance(figures, dict):
        return {k: comparable(v) for k, v in figures.items() if k not in WALL_CLOCK}
    return figures


def differences(a: Any, b: Any, path: str = "") -> list[str]:
    """Name every figure that differs between two summaries (for the failure message)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [
            d
            for k in sorted(a.keys() | b.keys())
            for d in differences(a.get(k), b.get(k), f"{path}.{k}")
        ]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def fingerprint(summary: dict[str, Any]) -> tuple[object, ...]:
    moves = {a: s["moves"] for a, s in summary["stats"]["agents"].items()}
    return summary["trace_digest"], summary["requests"], summary["sim_time"], moves


def test_the_paper_run_repeats_exactly_under_load_and_a_seed_changes_it() -> None:
    with cpu_load():
        first = run("paper-7x7", "--mode", "online", "--seed", "1")
        again = run("paper-7x7", "--mode", "online", "--seed", "1")
        other = run("paper-7x7", "--mode", "online", "--seed", "3")
    assert first["result"] == "done"
    assert comparable(first) == comparable(again), differences(comparable(first), comparable(again))
    assert other["trace_digest"] != first["trace_digest"]


@pytest.mark.timeout(600)  # two 3-robot runs whose planners search each epoch, loaded
def test_three_robots_repeat_exactly_under_load() -> None:
    """The whole summary repeats, the planners' and executors' counts with the trace,
    but for its wall-clock and host figures."""
    with cpu_load():
        runs = [run("warehouse-15x15-bdi", "--until", "done") for _ in range(2)]
    first, again = (comparable(r) for r in runs)
    assert first == again, differences(first, again)
    assert first["result"] == "done" and first["planner"]["total"]["replans"] > 0
    # Counted up to the last tick: every action asked is in the world's trace.
    assert sum(a["actions"] for a in first["actions"].values()) == first["requests"]
    assert sum(1 for a in first["actions"].values() if a["actions"] > 0) == 3


def test_the_summary_names_what_it_does_not_repeat() -> None:
    """The figures left out of the comparison are the ones the docs call wall-clock."""
    doc = (REPO / "docs" / "architecture.md").read_text()
    said = doc.split("**The summary too.**")[1].split("\n\n")[0]
    assert all(f"`{name}`" in said for name in WALL_CLOCK)


def test_late_schedulers_and_planners_change_nothing() -> None:
    """Any start order gives the same run: epoch 0 waits for every member's `ready`; and so
    does running each agent's services in one process."""
    args = ("paper-7x7", "--agents", "3", "--seed", "2")
    on_time = run(*args)
    late = run(
        *args,
        "--delay",
        "robot1/scheduler=3",
        "--delay",
        "robot2/scheduler=2",
        "--delay",
        "robot3/planner=4",
    )
    assert late["result"] == on_time["result"] == "done"
    assert comparable(late) == comparable(on_time), differences(
        comparable(late), comparable(on_time)
    )
    assert all(a["actions"] > 0 for a in late["actions"].values())  # every robot took part
    # One process per agent (its three services on one event loop): the same run again.
    hosted = run(*args, "--agent-process")
    assert fingerprint(hosted) == fingerprint(on_time)
    assert set(hosted["restarts"]) == {
        "router",
        "world",
        "robot1/agent",
        "robot2/agent",
        "robot3/agent",
    }
