"""A burst of fuzzed messages over real Zenoh into a running `cbdi up` run.

The same Hypothesis-built messages as `tests/test_fuzz_services.py` (every wire type,
valid-shaped or mangled), 400 of them, published by a client of the run's router on
every key the agent's services and the world read, a quarter of them also sent to every
request endpoint, while the run goes on. The run's result may be anything (a fuzzed
`RunFinished` or `Tick` is a message like any other to a client the bus lets publish);
what must hold is that no service dies or crashes
in a handler: none is restarted, and each exits 0 at the end.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import subprocess
from pathlib import Path

import pytest
from test_fuzz_services import ENDPOINTS, STREAMS, fuzzed

from cbdi.bus import BusConfig, open_bus
from cbdi.errors import CbdiError
from tests_support import CBDI, REPO, free_port, wait_for

pytestmark = pytest.mark.e2e


@pytest.mark.timeout(300)
async def test_a_fuzz_burst_over_zenoh_kills_no_service(tmp_path: Path) -> None:
    port = free_port()
    log = tmp_path / "up.log"
    up = subprocess.Popen(
        # No security: the fuzzing client may publish anywhere (with it, the router
        # refuses it, tests/e2e/test_security.py).
        [CBDI, "up", "paper-7x7", "--json", "--port", str(port), "--speed", "2", "--no-secure"],
        stdout=subprocess.PIPE,
        stderr=log.open("w"),
        text=True,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        await asyncio.to_thread(
            wait_for,
            lambda: "event=act epoch=" in log.read_text(),
            timeout=120,
            what="the run under way",
        )
        bus = await open_bus(BusConfig(connect=(f"tcp/127.0.0.1:{port}",)))
        try:
            for i, payload in enumerate(fuzzed(400)):
                await bus.publish(STREAMS[i % len(STREAMS)], payload)
                if i % 4 == 0:
                    with contextlib.suppress(CbdiError, TimeoutError):
                        await bus.request(ENDPOINTS[i % len(ENDPOINTS)], payload, timeout=1.0)
        finally:
            await bus.close()
        out, _ = await asyncio.to_thread(up.communicate, timeout=240)
    finally:
        up.kill()
    text = log.read_text()
    summary = json.loads(out)
    assert "restarting service=" not in text, text[-3000:]
    assert "handler_crash" not in text and "Traceback" not in text, text[-3000:]
    codes = summary["exit_codes"]
    assert codes and all(c == [0] for c in codes.values()), codes
    refused = text.count("bad_input") + text.count("event=bad")
    print("result", summary["result"], "log lines on bad input", refused)
    assert refused > 0
