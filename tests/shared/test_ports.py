"""Free ports for a run's router (`cbdi.launcher.ports`): the kernel's pick, or one of a
given range (`CBDI_PORTS`), checked free; a bad range is a named error."""

from __future__ import annotations

import socket

import pytest

from cbdi.errors import ConfigError
from cbdi.launcher.ports import PORTS_ENV, free_port


def test_a_port_comes_from_the_range_given_and_is_free() -> None:
    seen = {free_port({PORTS_ENV: "21000-21009"}) for _ in range(40)}
    assert seen <= set(range(21000, 21010)) and len(seen) > 1  # drawn, not the first one
    with socket.socket() as s:
        s.bind(("127.0.0.1", free_port({PORTS_ENV: "21000-21009"})))


def test_a_taken_port_is_passed_over() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        taken.listen()
        with pytest.raises(ConfigError, match="no free port"):
            free_port({PORTS_ENV: f"{port}-{port}"})


@pytest.mark.parametrize("span", ["20000", "a-b", "30000-20000", "80-90", "65000-70000"])
def test_a_bad_range_is_refused_naming_the_variable(span: str) -> None:
    with pytest.raises(ConfigError, match=PORTS_ENV):
        free_port({PORTS_ENV: span})


def test_without_a_range_the_kernel_picks() -> None:
    assert 1024 <= free_port({}) <= 65535
