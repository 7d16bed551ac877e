"""Table I as a figure: per situation, both modes' mean moves with 95% bootstrap bars.

One panel per planning speed factor; the paper's means are marked beside each mode, the
static optimum is a line across. A bare `Figure` draws on matplotlib's Agg canvas: no
pyplot, no display, no global backend to choose.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.figure import Figure
from table1_bounds import Bound
from table1_model import PAPER
from table1_stats import Sample
from table1_summary import Row

__all__ = ["draw_figure"]

COLOURS = {"offline": "#c0504d", "online": "#4f81bd"}
OFFSET = {"offline": -0.17, "online": 0.17}


def _bar(sample: Sample) -> tuple[float, float, float] | None:
    """Return (mean, below, above) for an error bar, None without a mean."""
    if sample.mean is None or sample.interval is None:
        return None
    return sample.mean, sample.mean - sample.interval.low, sample.interval.high - sample.mean


def _panel(ax: Axes, rows: Sequence[Row], static: Bound | None, title: str) -> None:
    xs = list(range(len(rows)))
    for mode in ("offline", "online"):
        points = [
            (x + OFFSET[mode], bar)
            for x, r in zip(xs, rows, strict=True)
            if (bar := _bar(getattr(r, mode).moves)) is not None
        ]
        if points:
            ax.errorbar(
                [p[0] for p in points],
                [p[1][0] for p in points],
                yerr=[[p[1][1] for p in points], [p[1][2] for p in points]],
                fmt="o",
                color=COLOURS[mode],
                capsize=3,
                label=f"{mode} (mean, 95% CI)",
            )
        paper = [PAPER[r.situation][0 if mode == "offline" else 1].mu for r in rows]
        ax.scatter(
            [x + OFFSET[mode] for x in xs],
            paper,
            marker="D",
            facecolors="none",
            edgecolors=COLOURS[mode],
            label=f"{mode}, paper mu",
        )
    clair = [(x, r.clairvoyant.mean) for x, r in zip(xs, rows, strict=True) if r.clairvoyant.mean]
    if clair:
        ax.hlines(
            [c[1] for c in clair],
            [c[0] - 0.35 for c in clair],
            [c[0] + 0.35 for c in clair],
            colors="black",
            linestyles=":",
            label="clairvoyant best found (mean)",
        )
    if static is not None and static.moves is not None:
        ax.axhline(static.moves, color="grey", linestyle="--", label="static optimum")
    ax.set_xlim(-0.6, len(rows) - 0.4)
    ax.set_xticks(xs, [r.situation.label for r in rows], rotation=45)
    ax.set_xlabel("situation (move, det_area, known litter)")
    ax.set_ylabel("moves")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)


def draw_figure(rows: Sequence[Row], static: Bound | None, path: Path) -> None:
    """Draw one panel per planning speed factor and write the PNG to `path`."""
    factors = sorted({r.factor for r in rows})
    fig = Figure(figsize=(11, 4.2 * max(len(factors), 1)))
    axes = fig.subplots(max(len(factors), 1), 1, squeeze=False)
    for ax, factor in zip(axes[:, 0], factors, strict=False):
        mine = [r for r in rows if r.factor == factor]
        _panel(ax, mine, static, f"Table I moves, planning speed x{factor:g}")
    if factors:
        axes[0, 0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    else:
        axes[0, 0].text(0.5, 0.5, "no lockstep runs", ha="center", va="center")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png", dpi=100, metadata={"Software": None})
