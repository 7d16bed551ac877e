"""Settings: flags over environment over TOML file over defaults, with named errors."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest

from cbdi.errors import ConfigError
from cbdi.runtime import ServiceSettings, load_config


@dataclass(frozen=True)
class DemoSettings(ServiceSettings):
    speed: float = 1.0
    agent: tuple[str, ...] = ()
    lockstep: bool = False
    name: str = field(default="w")


def load(argv: list[str], env: dict[str, str] | None = None) -> DemoSettings:
    return load_config(DemoSettings, argv, prog="t", section="demo", env=env or {})


def test_defaults() -> None:
    s = load([])
    assert s.speed == 1.0 and s.connect == ("tcp/127.0.0.1:7447",) and s.mode == "client"


def test_precedence_flag_env_file(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text('[demo]\nspeed = 3.0\nname = "file"\nlockstep = true\n')
    s = load(["--config", str(cfg)], {"CBDI_SPEED": "5"})
    assert (s.speed, s.name, s.lockstep) == (5.0, "file", True)
    s = load(["--config", str(cfg), "--speed", "7", "--no-lockstep"], {"CBDI_SPEED": "5"})
    assert (s.speed, s.lockstep) == (7.0, False)


def test_repeatable_and_comma_lists() -> None:
    assert load(["--agent", "a", "--agent", "b"]).agent == ("a", "b")
    assert load([], {"CBDI_AGENT": "a,b,c"}).agent == ("a", "b", "c")
    assert load([], {"CBDI_CONNECT": "tcp/127.0.0.1:1"}).connect == ("tcp/127.0.0.1:1",)


def test_bad_value_names_source_and_field(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        load([], {"CBDI_SPEED": "fast"})
    assert err.value.source == "environment" and err.value.field == "speed"
    cfg = tmp_path / "c.toml"
    cfg.write_text("speed = 'x'\n")
    with pytest.raises(ConfigError, match=r"config file .*c\.toml: speed"):
        load(["--config", str(cfg)])


def test_unknown_setting_in_file_is_refused(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("sped = 2\n")
    with pytest.raises(ConfigError, match="sped: unknown setting"):
        load(["--config", str(cfg)])


def test_broken_toml_and_missing_file(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("speed = = 2\n")
    with pytest.raises(ConfigError, match="toml"):
        load(["--config", str(cfg)])
    with pytest.raises(ConfigError, match="not found"):
        load(["--config", str(tmp_path / "none.toml")])
