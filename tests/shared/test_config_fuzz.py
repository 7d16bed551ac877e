"""Config-file fuzz: mutated scenario, agent, map and floor files give a `CbdiError`
naming what is wrong, never another exception (a traceback for the user).

The shipped files are copied (with their folders, so relative paths resolve) and each is
mutated a few times over: bytes changed or cut, and fragments that break TOML or types
(`nan`, `1e400`, `-1`, brackets, quotes) put in.
"""

from __future__ import annotations

import random
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from cbdi_courier.floor import load_floor
from cbdi_recycling.maps import load_map

from cbdi.errors import CbdiError
from cbdi.launcher.scenario import load_scenario
from cbdi_scheduler.agentfile import load_agent
from tests_support import REPO

FRAGMENTS = [b"-1", b"nan", b"1e400", b'"', b"[", b"]", b"=", b"\n", b"true", b"{", b"x", b"\xff"]
LOADERS: dict[str, tuple[str, Callable[[Path], object]]] = {
    "scenario": ("*/scenarios/*.toml", load_scenario),
    "agent": ("*/agents/*.toml", lambda p: load_agent(p, "robot1")),
    "map": ("recycling/maps/*.toml", load_map),
    "floor": ("courier/maps/*.toml", load_floor),
}


def mutated(data: bytes, rng: random.Random) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        at = rng.randrange(max(1, len(out)))
        how = rng.random()
        if how < 0.4 and out:
            out[at] = rng.randrange(256)
        elif how < 0.7:
            del out[at : at + rng.randint(1, 20)]
        else:
            out[at:at] = rng.choice(FRAGMENTS)
    return bytes(out)


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_mutated_config_files_give_a_cbdi_error_or_load(kind: str, tmp_path: Path) -> None:
    domains = tmp_path / "domains"
    shutil.copytree(REPO / "domains", domains, ignore=shutil.ignore_patterns("src", "*.egg-info"))
    pattern, load = LOADERS[kind]
    sources = sorted(domains.glob(pattern))
    assert sources, pattern
    rng = random.Random(f"config-fuzz:{kind}")
    refused = 0
    for i in range(150):
        source = rng.choice(sources)
        path = source.with_name(f"fuzz-{i}.toml")
        path.write_bytes(mutated(source.read_bytes(), rng))
        try:
            load(path)
        except CbdiError as exc:
            refused += 1
            assert str(path) in str(exc) or "fuzz-" in str(exc), exc  # says which file
        path.unlink()
    assert refused > 30  # most mutations break the file, and are said to
