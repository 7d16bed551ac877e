"""The paper's Table I, a first look: moves of the BDI robot in its 12 situations.

Runs `cbdi up paper-7x7 --json` for every situation (people step every 4 or 8 epochs,
detection depth 1 to 3, 2 or 3 litter items known at the start) in offline
(plan-then-act) and online (continual planning) mode, one run each, and prints the
moves beside the paper's means (`mu`; the paper averaged repeated runs).

Run: `make bench-table1` or `python benchmarks/table1.py [--seed 1] [--csv out.csv]`.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CBDI = str(Path(sys.executable).parent / "cbdi")

# (move_step, det_area, known_litter): (offline mu, online mu), the paper's Table I.
PAPER = {
    (4, 1, 2): (56.0, 42.5),
    (8, 1, 2): (58.5, 43.0),
    (4, 2, 2): (58.5, 36.0),
    (8, 2, 2): (58.0, 35.5),
    (4, 3, 2): (66.0, 42.5),
    (8, 3, 2): (57.0, 42.0),
    (4, 1, 3): (48.0, 43.5),
    (8, 1, 3): (57.8, 36.0),
    (4, 2, 3): (48.0, 35.5),
    (8, 2, 3): (57.0, 37.0),
    (4, 3, 3): (48.0, 42.0),
    (8, 3, 3): (48.0, 39.5),
}


def run(situation: tuple[int, int, int], mode: str, seed: int) -> dict[str, object]:
    """Run one situation in one mode; return moves, result and counts from the summary."""
    move, det, known = situation
    argv = [CBDI, "up", "paper-7x7", "--json", "--quiet", "--mode", mode, "--seed", str(seed)]
    argv += ["--move-step", str(move), "--det-area", str(det), "--known-litter", str(known)]
    done = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=600)
    try:
        summary = json.loads(done.stdout)
    except json.JSONDecodeError:
        return {"result": f"no summary (exit {done.returncode})", "moves": -1}
    robot = summary["stats"]["agents"]["robot1"]
    planner = summary["planner"]["agents"].get("robot1", {})
    return {
        "result": summary["result"],
        "moves": robot["moves"],
        "recycled": robot["recycled"],
        "sim_time": summary["sim_time"],
        "replans": planner.get("replans", 0),
        "forecast_repairs": planner.get("forecast_repairs", 0),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=1, help="the world's seed for every run")
    parser.add_argument("--csv", type=Path, help="also write the rows to this CSV file")
    args = parser.parse_args(argv)
    rows = []
    head = (
        f"{'move det known':<15} {'paper off':>9} {'ours off':>8} {'paper on':>8}"
        f" {'ours on':>7} {'repairs':>7}  results (off/on)"
    )
    print(head)
    print("-" * len(head))
    for situation, (paper_off, paper_on) in PAPER.items():
        off = run(situation, "offline", args.seed)
        on = run(situation, "online", args.seed)
        rows.append({"situation": situation, "offline": off, "online": on})
        print(
            f"{'  '.join(map(str, situation)):<15} {paper_off:>9.1f} {off['moves']:>8}"
            f" {paper_on:>8.1f} {on['moves']:>7} {on.get('forecast_repairs', 0):>7}"
            f"  {off['result']}/{on['result']}",
            flush=True,
        )
    ok = [r for r in rows if r["offline"]["result"] == "done" and r["online"]["result"] == "done"]
    if ok:
        mean_off = sum(int(r["offline"]["moves"]) for r in ok) / len(ok)  # type: ignore[call-overload]
        mean_on = sum(int(r["online"]["moves"]) for r in ok) / len(ok)  # type: ignore[call-overload]
        paper = [PAPER[r["situation"]] for r in ok]  # type: ignore[index]
        print(
            f"\nmean over {len(ok)} situations both modes finished: offline {mean_off:.1f}"
            f" (paper {sum(p[0] for p in paper) / len(paper):.1f}), online {mean_on:.1f}"
            f" (paper {sum(p[1] for p in paper) / len(paper):.1f})"
        )
    if args.csv:
        with args.csv.open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["move_step", "det_area", "known_litter", "mode", "paper_mu", "moves"])
            for r in rows:
                paper_off, paper_on = PAPER[r["situation"]]  # type: ignore[index]
                for mode, mu in (("offline", paper_off), ("online", paper_on)):
                    out.writerow([*r["situation"], mode, mu, r[mode]["moves"]])  # type: ignore[misc]
    return 0


if __name__ == "__main__":
    sys.exit(main())
