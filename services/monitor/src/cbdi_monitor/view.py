"""`cbdi view`: see a run in rerun, from a recording or live; `--text` for a terminal.

    cbdi view run.mcap --rrd run.rrd     # convert a recording to a rerun file
    cbdi view run.mcap                   # open it in the native rerun viewer
    cbdi view run.mcap --web             # serve the rerun web viewer on 127.0.0.1
    cbdi view --live --rrd live.rrd      # follow a running system into a file
    cbdi view --text                     # the character grid, live

rerun-sdk is an optional extra of the monitor (`pip install cbdi-monitor[rerun]`).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cbdi import keys
from cbdi.bus.zenoh_bus import BusConfig, open_bus
from cbdi.errors import CbdiError
from cbdi.security.login import config_as
from cbdi.security.policy import VIEWER
from cbdi_monitor.reader import RecordedMessage, read_messages
from cbdi_monitor.rerun_log import RerunLogger
from cbdi_monitor.schemas import peek_schema

__all__ = ["convert", "main"]

os.environ.setdefault("RERUN_TELEMETRY_ENABLED", "false")  # no network calls from the SDK


def _rerun() -> Any:
    try:
        import rerun
    except ImportError:
        raise CbdiError("rerun-sdk is not installed: pip install 'cbdi-monitor[rerun]'") from None
    return rerun


def _blueprint(rr: Any) -> Any:
    rrb = rr.blueprint
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="world", name="world"),
            rrb.Vertical(
                rrb.TextLogView(origin="agents", name="decisions"),
                rrb.TimeSeriesView(origin="plots", name="per agent"),
                rrb.TextLogView(origin="health", name="health"),
            ),
            column_shares=[3, 2],
        )
    )


def convert(recording: str | Path, rrd: str | Path) -> int:
    """Write `rrd` from the MCAP `recording`; return the number of messages read."""
    rr = _rerun()
    stream = rr.RecordingStream("cbdi", recording_id=Path(recording).stem)
    stream.save(str(rrd), default_blueprint=_blueprint(rr))
    logger = RerunLogger(rr, stream)
    count = 0
    for m in read_messages(recording):
        logger.handle(m)
        count += 1
    stream.flush()
    stream.disconnect()
    return count


def _open_viewer(rrd: Path, web: bool, port: int) -> int:
    exe = Path(sys.executable).parent / "rerun"
    argv = [str(exe if exe.exists() else "rerun"), str(rrd)]
    if web:
        argv += ["--web-viewer", "--bind", "127.0.0.1", "--web-viewer-port", str(port)]
        print(
            f"serving the rerun web viewer on http://127.0.0.1:{port} (Ctrl-C to stop)",
            file=sys.stderr,
        )
    # Its own session, so that stopping it reaches what it starts; SIGTERM to us is
    # passed on: the viewer never outlives `cbdi view` (it would hold the port).
    child = subprocess.Popen(argv, start_new_session=True)
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        return child.wait()
    except KeyboardInterrupt:
        return 0
    except _Terminated:
        return 128 + signal.SIGTERM
    finally:
        signal.signal(signal.SIGTERM, previous)
        _stop(child)


class _Terminated(Exception):
    """SIGTERM arrived while the viewer ran."""


def _terminated(signum: int, frame: object) -> None:
    raise _Terminated


def _stop(child: subprocess.Popen[bytes], grace: float = 5.0) -> None:
    """End the viewer's process group: SIGTERM, then SIGKILL after `grace` seconds."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(child.pid, sig)
        try:
            child.wait(grace)
            return
        except subprocess.TimeoutExpired:
            continue


async def _live(rrd: str, bus_config: BusConfig, seconds: float) -> int:
    rr = _rerun()
    stream = rr.RecordingStream("cbdi", recording_id=f"live-{int(time.time())}")
    stream.save(rrd, default_blueprint=_blueprint(rr))
    logger = RerunLogger(rr, stream)
    bus = await open_bus(bus_config)
    count = 0
    try:
        sub = bus.subscribe(keys.ALL)
        async with asyncio.timeout(seconds or None):
            async for s in sub:
                logger.handle(
                    RecordedMessage(
                        s.key,
                        s.payload,
                        time.time_ns(),
                        s.sent_ns,
                        s.seq,
                        peek_schema(s.payload),
                        "msgpack",
                    )
                )
                count += 1
    except (TimeoutError, asyncio.CancelledError):
        pass
    finally:
        await bus.close()
        stream.flush()
        stream.disconnect()
    return count


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cbdi view", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("file", nargs="?", help="an MCAP recording")
    p.add_argument("--rrd", help="write a rerun .rrd file instead of opening a viewer")
    p.add_argument("--web", action="store_true", help="serve the web viewer on 127.0.0.1")
    p.add_argument("--web-port", type=int, default=9090, help="port of the web viewer")
    p.add_argument("--live", action="store_true", help="follow a running system")
    p.add_argument("--seconds", type=float, default=0.0, help="--live: stop after N seconds")
    p.add_argument("--connect", default="tcp/127.0.0.1:7447", help="--live: Zenoh endpoint")
    p.add_argument(
        "--credentials",
        default="",
        help="--live: the run's viewer credentials (default: $CBDI_CREDENTIALS, else those"
        " of the local run on the --connect port; docs/security.md)",
    )
    p.add_argument("--text", action="store_true", help="live text view in the terminal")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi view`."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if "--text" in args_list:
        from cbdi.view import main as text_main

        return text_main([a for a in args_list if a != "--text"])
    args = _parser().parse_args(args_list)
    try:
        if args.live:
            out = args.rrd or "live.rrd"
            cfg = config_as(VIEWER, [args.connect], credentials=args.credentials)
            n = asyncio.run(_live(out, cfg, args.seconds))
            print(f"logged {n} live messages to {out}", file=sys.stderr)
            return 0
        if not args.file:
            print("cbdi view: give a recording (run.mcap), --live or --text", file=sys.stderr)
            return 2
        rrd = Path(args.rrd) if args.rrd else Path(tempfile.mkdtemp()) / "run.rrd"
        n = convert(args.file, rrd)
        print(f"converted {n} messages into {rrd}", file=sys.stderr)
        return 0 if args.rrd else _open_viewer(rrd, args.web, args.web_port)
    except CbdiError as exc:
        print(f"cbdi view: {exc}", file=sys.stderr)
        return 2
