"""The monitor end to end: record a `cbdi up` run of the paper scenario, check the file,
compare its counts with what the services say they sent, inspect, export, replay and
re-record, convert to rerun and look at it in the rerun web viewer in headless Chromium.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
from collections import defaultdict
from pathlib import Path

import pytest

from cbdi_monitor.reader import read_messages
from pngcheck import count_pixels
from tests_support import BIN, REPO, Proc, free_port, wait_for

pytestmark = pytest.mark.e2e
ENV = {**os.environ, "RERUN_TELEMETRY_ENABLED": "false"}


def run(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    exe = str(BIN / argv[0]) if (BIN / argv[0]).exists() else argv[0]
    return subprocess.run(
        [exe, *argv[1:]],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        env=ENV,
        stdin=subprocess.DEVNULL,
    )


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, str]:
    out = tmp_path_factory.mktemp("rec") / "paper.mcap"
    # Lockstep: the world waits for the robot every epoch, so what the tests read off the
    # run (its first action at 0, 22 moves) does not depend on how loaded the machine is
    # (in real time a slow first request started it at 4 s).
    result = run(
        "cbdi", "up", "paper-7x7-scripted", "--speed", "40", "--lockstep",
        "--record", str(out), "--json",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    return out, json.loads(result.stdout), result.stderr


def test_recording_passes_rerun_mcap_check(recording: tuple[Path, dict, str]) -> None:
    path, _, _ = recording
    result = run("rerun", "mcap", "check", str(path))
    assert result.returncode == 0, result.stdout + result.stderr


def test_every_message_the_services_sent_is_in_the_file(recording: tuple[Path, dict, str]) -> None:
    path, _, log = recording
    sent: dict[str, int] = defaultdict(int)
    for service, key, count in re.findall(
        r"^(\S+)\s*\| .*event=sent key=(\S+) count=(\d+)", log, re.M
    ):
        if service != "monitor":  # its own last health notes may follow its file's end
            sent[key] += int(count)
    recorded: dict[str, int] = defaultdict(int)
    for m in read_messages(path):
        recorded[m.key] += 1
    assert sent, "the services reported no sent counts"
    assert {k: recorded[k] for k in sent} == dict(sent)
    assert recorded["cbdi/trace/world/rpc/act/request"] > 0  # RPC traffic is in the file
    assert recorded["cbdi/alive/world"] == 2  # the world came up and went down


def test_channels_name_agent_component_and_schema(recording: tuple[Path, dict, str]) -> None:
    from mcap.reader import make_reader

    path, _, _ = recording
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    channels = {c.topic: c for c in summary.channels.values()}
    percepts = channels["cbdi/world/percepts/robot1"]
    assert percepts.message_encoding == "msgpack"
    assert percepts.metadata["agent"] == "robot1"
    assert percepts.metadata["component"] == "world"
    assert percepts.metadata["schema"] == "cbdi.recycling.Percepts/1"
    assert summary.schemas[percepts.schema_id].encoding == "jsonschema"
    seqs = [m.seq for m in read_messages(path, ["cbdi/world/clock"])]
    assert seqs == list(range(1, len(seqs) + 1))  # the sender's sequence, none missing


def test_inspect_reports_the_domains_counters(recording: tuple[Path, dict, str]) -> None:
    path, summary, _ = recording
    result = run("cbdi", "inspect", str(path), "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    robot = report["agents"]["robot1"]
    assert report["simulator"] == "recycling"  # its counters: what the domain registers
    assert robot["counters"]["moves"] == summary["stats"]["agents"]["robot1"]["moves"] == 22
    assert robot["counters"]["recycled"] == 3 and report["result"] == "done"
    assert robot["first_action_time"] == 0.0
    assert robot["replans"] is None and robot["search_rounds"] is None  # no planner
    text = run("cbdi", "inspect", str(path)).stdout
    assert "agent robot1: moves=22" in text


def test_export_to_json_keeps_every_message(
    recording: tuple[Path, dict, str], tmp_path: Path
) -> None:
    path, _, _ = recording
    out = tmp_path / "paper.json.mcap"
    assert run("cbdi", "export", str(path), "--json", str(out)).returncode == 0
    original = list(read_messages(path))
    exported = list(read_messages(out))
    assert len(exported) == len(original)
    assert {m.encoding for m in exported} == {"json"}
    tick = next(m for m in exported if m.key == "cbdi/world/clock")
    assert json.loads(tick.payload)["schema"] == "cbdi.world.Tick/1"


def test_replay_rerecorded_gives_the_same_payloads(
    recording: tuple[Path, dict, str], tmp_path: Path
) -> None:
    path, _, _ = recording
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {"CBDI_CONNECT": endpoint}
    router = Proc([str(BIN / "cbdi"), "router", "--listen", endpoint], tmp_path / "r.log")
    again = tmp_path / "again.mcap"
    monitor = Proc([str(BIN / "cbdi-monitor"), "--output", str(again)], tmp_path / "m.log", env)
    try:
        wait_for(lambda: "event=ready" in monitor.output(), what="monitor ready")
        result = run("cbdi", "replay", str(path), "--speed", "4", "--connect", endpoint)
        assert result.returncode == 0, result.stderr
        time.sleep(0.5)
    finally:
        monitor.stop()
        router.stop()

    def payloads(p: Path) -> dict[str, list[bytes]]:
        out: dict[str, list[bytes]] = defaultdict(list)
        for m in read_messages(p):
            if m.schema not in ("cbdi.Liveliness/1", "cbdi.ServiceHealth/1"):
                out[m.key].append(m.payload)
        return dict(out)

    assert payloads(again) == payloads(path)


@pytest.mark.timeout(400)
def test_rrd_conversion_verifies_and_the_web_viewer_shows_the_run(
    recording: tuple[Path, dict, str], tmp_path: Path
) -> None:
    path, _, _ = recording
    rrd = tmp_path / "paper.rrd"
    result = run("cbdi", "view", str(path), "--rrd", str(rrd))
    assert result.returncode == 0, result.stderr
    verify = run("rerun", "rrd", "verify", str(rrd))
    assert verify.returncode == 0, verify.stdout + verify.stderr
    shot = tmp_path / "viewer.png"
    _screenshot(rrd, shot, tmp_path)
    assert drawn(shot), drawn_pixels(shot)  # the robot and the people drawn


def drawn_pixels(shot: Path) -> tuple[int, int]:
    """The robot's pixels (red) and the people's (amber) in a screenshot of the run."""
    robot = count_pixels(shot, lambda r, g, b: r > 190 and g < 120 and b < 100)
    person = count_pixels(shot, lambda r, g, b: r > 220 and 150 < g < 215 and b < 90)
    return robot, person


def drawn(shot: Path) -> bool:
    return all(n > 150 for n in drawn_pixels(shot))


def _screenshot(rrd: Path, shot: Path, tmp: Path) -> None:
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium")
    assert chromium, "chromium is missing: `make test` installs it (Debian package)"
    web, grpc = free_port(), free_port()
    viewer = Proc(
        [
            str(BIN / "rerun"),
            str(rrd),
            "--web-viewer",
            "--bind",
            "127.0.0.1",
            "--web-viewer-port",
            str(web),
            "--port",
            str(grpc),
        ],
        tmp / "rerun.log",
        {"RERUN_TELEMETRY_ENABLED": "false"},
    )
    try:
        wait_for(lambda: "Hosting a web-viewer" in viewer.output(), what="rerun web viewer")
        url = f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
        with sync_playwright() as p:
            browser = p.chromium.launch(
                executable_path=chromium,
                args=[
                    "--no-sandbox",
                    "--disable-gpu",
                    "--disable-quic",
                    "--no-first-run",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                    "--enable-unsafe-swiftshader",
                    "--use-angle=swiftshader",
                ],
            )
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(url)
            # The wasm app loads, then draws the run: wait for the drawing (what the test
            # asserts) however long a loaded machine's software rendering takes, up to a
            # bound no correct run reaches.
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline:
                page.wait_for_timeout(1000)
                page.screenshot(path=str(shot))
                if drawn(shot):
                    break
            browser.close()
    finally:
        viewer.stop()


def test_live_view_follows_a_running_system(tmp_path: Path) -> None:
    port = free_port()
    # 600 simulated s at speed 4: the run outlasts both views however slowly they start
    # (a view of a run that ended cannot connect); it is stopped once they are done.
    launcher = Proc(
        [str(BIN / "cbdi"), "up", "paper-7x7-scripted", "--speed", "4", "--until", "600",
         "--port", str(port), "--quiet"],
        tmp_path / "up.log",
    )  # fmt: skip
    try:
        wait_for(
            lambda: "started service=robot1/executor" in launcher.output(),
            timeout=60,
            what="the run to start",
        )
        # The text view of the secured run logs in as its viewer, as does the rerun view
        # (both at once).
        endpoint = f"tcp/127.0.0.1:{port}"
        text = subprocess.Popen(
            [str(BIN / "cbdi"), "view", "--text", "--frames", "2", "--connect", endpoint],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
            stdin=subprocess.DEVNULL,
        )  # fmt: skip
        rrd = tmp_path / "live.rrd"
        result = run("cbdi", "view", "--live", "--seconds", "3", "--rrd", str(rrd),
                     "--connect", endpoint)  # fmt: skip
        shown, errors = text.communicate(timeout=120)
        assert text.returncode == 0, errors
        assert shown.count("epoch") >= 2, shown
        assert result.returncode == 0, result.stderr
        logged = int(re.search(r"logged (\d+) live messages", result.stderr).group(1))  # type: ignore[union-attr]
        assert logged > 20  # a few epochs/s, each with several messages, and heartbeats
        assert run("rerun", "rrd", "verify", str(rrd)).returncode == 0
    finally:
        launcher.stop()
