"""A service restarted by its container's policy learns its restart count from a file in
the container's own volume (`CBDI_LIFE_FILE`, `cbdi compose`); a clean exit resets it."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.runtime import load_config
from cbdi.runtime.life import LIFE_ENV, RESTART_ENV, count_start, end_cleanly
from cbdi_world.settings import WorldSettings


def test_starts_are_counted_until_a_clean_exit(tmp_path: Path) -> None:
    life = tmp_path / "state" / "life"
    seen = []
    for _ in range(3):  # a first start, then two after failures
        env = {LIFE_ENV: str(life)}
        count_start(env)
        count_start(env)  # once per process
        seen.append(env[RESTART_ENV])
    assert seen == ["0", "1", "2"]
    end_cleanly({LIFE_ENV: str(life)})
    env = {LIFE_ENV: str(life)}
    count_start(env)
    assert env[RESTART_ENV] == "0"  # the container started again for a new run


def test_a_supervisors_count_wins_and_garbage_is_a_first_start(tmp_path: Path) -> None:
    life = tmp_path / "life"
    env = {LIFE_ENV: str(life), RESTART_ENV: "4"}  # `cbdi up` said so
    count_start(env)
    assert env[RESTART_ENV] == "4" and not life.exists()
    life.write_bytes(b"\xff\xfe nonsense")
    env = {LIFE_ENV: str(life)}
    count_start(env)
    assert env[RESTART_ENV] == "0" and life.read_text() == "1\n"


def test_a_service_reads_its_restart_count_from_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    life = tmp_path / "life"
    life.write_text("2\n")
    monkeypatch.setenv(LIFE_ENV, str(life))
    monkeypatch.setenv(RESTART_ENV, "")  # so that what count_start sets is undone too
    monkeypatch.delenv(RESTART_ENV)
    settings = load_config(WorldSettings, [], prog="cbdi-world", section="world")
    assert settings.restart == 2 and life.read_text() == "3\n"
