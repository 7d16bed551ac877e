"""The clock world: the world service's simulator with no domain (robots that act through
performers still need the world's clock)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.errors import ConfigError
from cbdi.launcher.scenario import load_scenario
from cbdi.launcher.services import world_args
from cbdi.runtime import load_config
from cbdi.wire.world import ActionRequest, Sensed
from cbdi_world.errors import WorldError
from cbdi_world.service import WorldSettings, build_world


def test_the_clock_counts_epochs_and_performs_nothing() -> None:
    argv = ["--simulator", "clock", "--agent", "robot1", "--option", "epoch_duration=0.5"]
    world = build_world(load_config(WorldSettings, argv, prog="w", section="world", env={}))
    assert world.info().epoch_duration == 0.5 and world.info().agents == ["robot1"]
    first = world.initial()
    assert [p.agent for p in first.percepts] == ["robot1"]
    for _ in range(4):
        result = world.step()
    assert (result.epoch, result.time, world.done) == (4, 2.0, False)
    assert all(isinstance(p, Sensed) and not p.add for p in result.percepts)
    reply = world.request(ActionRequest(agent="robot1", action="carry", request_id="r1"))
    assert not reply.accepted and "needs a performer" in reply.reason
    assert [a.agent for a in world.stats().agents] == ["robot1"]


def test_a_bad_clock_option_and_a_map_asked_of_the_grid_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"--option: epoch_duration: expected seconds"):
        argv = ["--simulator", "clock", "--option", "epoch_duration=0"]
        build_world(load_config(WorldSettings, argv, prog="w", section="world", env={}))
    with pytest.raises(WorldError, match="the 'recycling' simulator needs one"):
        argv = ["--simulator", "recycling"]
        build_world(load_config(WorldSettings, argv, prog="w", section="world", env={}))


def test_a_clock_scenario_needs_no_map(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\n[run]\nsimulator = "clock"\n[[agents]]\nname = "robot1"\n')
    scenario = load_scenario(path)
    assert scenario.map_path is None and "--map" not in world_args(scenario)
    path.write_text('name = "s"\n[run]\nsimulator = "recycling"\n[[agents]]\nname = "robot1"\n')
    with pytest.raises(ConfigError, match="map: missing: the 'recycling' simulator needs a map"):
        load_scenario(path)
