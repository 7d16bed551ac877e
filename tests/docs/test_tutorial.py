"""The tutorial, "A complete example" in docs/your-own-domain.md: what it shows is the
example in docs/tutorial/, byte for byte, and its commands, run as shown over real Zenoh,
make the robot tidy up: the sensor's belief fires the rule, the planner plans `carry`,
the performer carries it out and the sensor's next readings achieve the goal.

The section's blocks are of two kinds: a file, preceded by a line naming it
(`` `docs/tutorial/NAME` ...``), and a terminal transcript (```` ```console ````), whose
first line is the command after `$ ` and the rest lines it prints, `...` standing for
any text (a line of `...` alone for any lines). The commands run as shown, from the
repository, but for the router's port (a free one, not 7447) and `runs/` (the test's
own directory).
"""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import signal
import subprocess
from pathlib import Path
from typing import TypeVar

import pytest

from cbdi.wire import decode
from cbdi.wire.agent import AgentReply, AgentRequest, DesireEvent
from cbdi.wire.base import Message
from cbdi.wire.world import ActionOutcome
from cbdi_monitor.reader import RecordedMessage, read_messages
from tests_support import BIN, REPO, Proc, free_port

DOC = REPO / "docs/your-own-domain.md"
EXAMPLE = REPO / "docs/tutorial"
HEADING = "## A complete example\n"
SHOWN_PORT = "7447"
FAULTHANDLER = {"PYTHONFAULTHANDLER": "1"}

# A paragraph whose first line names the file, then its block.
FILE_BLOCK = re.compile(
    r"^`(docs/tutorial/[^`]+)`[^\n]*\n(?:[^\n]+\n)*\n```\w+\n(.*?)^```$", re.M | re.S
)
CONSOLE_BLOCK = re.compile(r"^```console\n\$ ([^\n]+)\n(.*?)^```$", re.M | re.S)
FENCE = re.compile(r"^```", re.M)

M = TypeVar("M", bound=Message)


def section() -> str:
    """The tutorial's section of the page: from its heading to the next one."""
    text = DOC.read_text(encoding="utf-8")
    assert text.count(HEADING) == 1, f"{DOC} has no single {HEADING.strip()!r}"
    rest = text.split(HEADING, 1)[1]
    return rest.split("\n## ", 1)[0]


def shown_files() -> dict[str, str]:
    """The files the section shows: path -> the block's text."""
    shown: dict[str, str] = {}
    for path, body in FILE_BLOCK.findall(section()):
        assert path not in shown, f"{path} is shown twice"
        shown[path] = body
    return shown


def transcripts() -> list[tuple[str, list[str]]]:
    """The section's terminal transcripts: (command, the lines it prints), in order."""
    return [(cmd, out.splitlines()) for cmd, out in CONSOLE_BLOCK.findall(section())]


def printed(expected: str, output: str) -> bool:
    """Whether some line of `output` is `expected`, each `...` in it any text."""
    pattern = ".*".join(re.escape(part) for part in expected.split("..."))
    return any(re.fullmatch(pattern, line) for line in output.splitlines())


def missing(expected: list[str], output: str) -> list[str]:
    """The lines of a transcript that `output` lacks."""
    return [line for line in expected if line != "..." and not printed(line, output)]


def argv(command: str, port: int, runs: Path) -> list[str]:
    """The words of a shown command as the test runs it (its own port and `runs/`)."""
    words = shlex.split(command.replace(SHOWN_PORT, str(port)).replace("runs/", f"{runs}/"))
    if words[0].startswith(".venv/bin/"):  # the venv running the tests
        words[0] = str(BIN / words[0].removeprefix(".venv/bin/"))
    return words


def recorded_as(recorded: list[RecordedMessage], suffix: str, cls: type[M]) -> list[M]:
    """The messages recorded on keys ending in `suffix`, in order."""
    return [decode(m.payload, cls, m.key) for m in recorded if m.key.endswith(suffix)]


def test_the_section_shows_every_file_of_the_example_as_it_is() -> None:
    shown = shown_files()
    files = sorted(
        str(p.relative_to(REPO)) for p in EXAMPLE.iterdir() if p.is_file() and p.name[0] != "."
    )
    assert sorted(shown) == files
    for path, body in shown.items():
        assert body.encode() == (REPO / path).read_bytes(), f"the doc's {path} is not the file"


def test_every_block_of_the_section_is_a_file_or_a_transcript() -> None:
    blocks = len(FENCE.findall(section())) // 2
    assert blocks == len(shown_files()) + len(transcripts())
    commands = [cmd for cmd, _ in transcripts()]
    assert [c.split()[:2] for c in commands] == [
        [".venv/bin/python", "docs/tutorial/robot.py"],
        [".venv/bin/cbdi", "up"],
        [".venv/bin/cbdi", "inspect"],
    ]


def test_a_transcript_line_matches_with_any_text_for_its_dots() -> None:
    assert printed("a ... c", "x\na b c\n") and printed("a", "a")
    assert not printed("a ... c", "a b d") and not printed("a", "a b")
    assert missing(["...", "a", "b"], "b") == ["a"]


@pytest.mark.e2e
def test_the_tutorial_runs_as_shown(tmp_path: Path) -> None:
    (robot_cmd, robot_out), (up_cmd, up_out), (inspect_cmd, inspect_out) = transcripts()
    port = free_port()
    # With faulthandler: a robot that outlives its Ctrl-C shows where it hangs (SIGABRT).
    robot = Proc(argv(robot_cmd, port, tmp_path), tmp_path / "robot.log", FAULTHANDLER)
    try:
        up = subprocess.run(
            argv(up_cmd, port, tmp_path),
            capture_output=True,
            text=True,
            timeout=300,
            cwd=REPO,
            stdin=subprocess.DEVNULL,
        )
        assert robot.alive(), robot.output()[-3000:]
        robot.popen.send_signal(signal.SIGINT)  # Ctrl-C, as the tutorial says
        try:
            robot.popen.wait(60)
        except subprocess.TimeoutExpired:
            robot.popen.send_signal(signal.SIGABRT)
            robot.popen.wait(30)
            stacks = robot.output()[-8000:]
            raise AssertionError(f"robot.py outlived its Ctrl-C:\n{stacks}") from None
        said = robot.output()
    finally:
        robot.stop()
    assert robot.popen.returncode == 0, said[-3000:]
    assert up.returncode == 0, up.stderr[-3000:]
    assert missing(up_out, up.stdout + up.stderr) == [], up.stderr[-3000:]
    assert missing(robot_out, said) == [], said[-3000:]

    inspected = subprocess.run(
        argv(inspect_cmd, port, tmp_path), capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert inspected.returncode == 0, inspected.stderr
    assert missing(inspect_out, inspected.stdout) == [], inspected.stdout
    assert "agent robot1: failed=0 requests=1 first action at t=" in inspected.stdout  # the carry

    recorded = list(read_messages(argv(inspect_cmd, port, tmp_path)[-1]))
    # The sensor told the agent where the cup is, and was heard.
    told = recorded_as(recorded, "/robot1/scheduler/rpc/request/request", AgentRequest)
    assert ("sensors", "add_belief", "(on cup table)") in [
        (r.group, r.op, r.belief) for r in told
    ], told
    answers = recorded_as(recorded, "/robot1/scheduler/rpc/request/reply", AgentReply)
    assert answers and all(a.accepted for a in answers), answers
    # The rule made the desire of it, and the goal was reached.
    desires = recorded_as(recorded, "/robot1/scheduler/desires", DesireEvent)
    events = [(e.desire, e.event) for e in desires]
    assert ("tidy_cup", "added") in events and ("tidy_cup", "achieved") in events, events
    achieved = [e.goal for e in desires if e.event == "achieved"]
    assert achieved == [[["on", "cup", "shelf"]]], desires
    # By the performer: its carry succeeded; the world was asked to do nothing.
    outcomes = recorded_as(recorded, "/robot1/performer/outcomes", ActionOutcome)
    assert [(o.action, o.status) for o in outcomes] == [("carry", "succeeded")]
    assert not [m for m in recorded if m.key == "cbdi/trace/world/rpc/act/request"]


@pytest.mark.e2e
def test_the_tutorial_in_lockstep_is_the_same_run_twice_and_replays(tmp_path: Path) -> None:
    """`cbdi up docs/tutorial/scenario.toml --lockstep`: robot.py is a lockstep member
    (cbdi.robot), the run waits for it each epoch, and its carry's outcome is part of
    the run's trace: two runs, each with a fresh robot.py, give the same trace, and the
    recording's agent decides again as it did (`cbdi replay --check`)."""
    (robot_cmd, _), (up_cmd, _), _ = transcripts()
    digests = []
    for run in (1, 2):
        port = free_port()
        record = tmp_path / f"tidy{run}.mcap"
        robot = Proc(argv(robot_cmd, port, tmp_path), tmp_path / f"robot{run}.log", FAULTHANDLER)
        try:
            up = subprocess.run(
                [
                    *argv(up_cmd.split(" --record")[0], port, tmp_path),
                    *("--lockstep", "--speed", "0", "--json", "--record", str(record)),
                ],
                capture_output=True,
                text=True,
                timeout=300,
                cwd=REPO,
                stdin=subprocess.DEVNULL,
            )
            said = robot.output()
        finally:
            robot.stop()
        assert up.returncode == 0, up.stderr[-3000:]
        summary = json.loads(up.stdout)
        assert summary["result"] == "time_limit" and not summary["stalls"], summary
        assert summary["performed"] == {"robot1": {"carry": 1}}, summary
        assert "put the cup on the shelf" in said and "lockstep_member" in said, said[-3000:]
        outcomes = recorded_as(list(read_messages(record)), "/performer/outcomes", ActionOutcome)
        assert [(o.action, o.status) for o in outcomes] == [("carry", "succeeded")]
        digests.append(summary["trace_digest"])
    assert digests[0] == digests[1] != hashlib.sha256().hexdigest()  # not an empty trace
    check = subprocess.run(
        [
            *(str(BIN / "cbdi"), "replay", str(tmp_path / "tidy1.mcap"), "--agent", "robot1"),
            *("--check", "--agent-file", str(EXAMPLE / "agent.toml")),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )
    assert check.returncode == 0, check.stdout + check.stderr
