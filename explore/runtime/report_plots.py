"""The pictures of a comparison's report: coverage against scans, scans to the stop, time per step and the
planners, one PNG each (matplotlib, headless)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import FINISHED
from explore.runtime.report_tables import Table, coverage_at, groups, median, num, unique, values


# -- plots --------------------------------------------------------------------------------------
def _whole_numbers() -> Any:
    """Tick locator for counts (scans): 1, 2, 3, never 1.5."""
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(integer=True)


def _figure(n_panels: int, width: float = 5.0, height: float = 3.8) -> tuple[Any, list[Any]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(n_panels, 3)
    lines = math.ceil(n_panels / cols)
    fig, axes = plt.subplots(lines, cols, figsize=(width * cols, height * lines), dpi=100, squeeze=False)
    flat = list(axes.ravel())
    for ax in flat[n_panels:]:
        ax.set_visible(False)
    return fig, flat[:n_panels]


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_coverage(rows: Sequence[dict[str, Any]], n_at: int, path: Path) -> Path | None:
    """Median coverage vs scans with the IQR band, one line per method, one panel per world."""
    done = [r for r in rows if r.get("status") in FINISHED and isinstance(r.get("coverage_per_scan"), list)]
    done = [r for r in done if r["coverage_per_scan"]]
    if not done:
        return None
    worlds = unique(done, "world")
    fig, axes = _figure(len(worlds))
    n = max(n_at, max(len(r["coverage_per_scan"]) for r in done))
    x = np.arange(1, n + 1)
    for ax, world in zip(axes, worlds, strict=True):
        for _, method, members in groups([r for r in done if r.get("world") == world]):
            curves = np.array([[coverage_at(r, k) for k in x] for r in members], dtype=float) * 100
            q1, med, q3 = np.percentile(curves, [25, 50, 75], axis=0)
            line = ax.plot(x, med, label=f"{method} (n={len(members)})")[0]
            ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.2, linewidth=0)
        ax.set_title(str(world))
        ax.set_xlabel("scans")
        ax.xaxis.set_major_locator(_whole_numbers())
        ax.set_ylabel("coverage c_a [%]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    return _save(fig, path)


def plot_scans(rows: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """Violin plots of the scans to termination per method, one panel per world."""
    done = [r for r in rows if r.get("status") in FINISHED and math.isfinite(num(r.get("scans")))]
    if not done:
        return None
    worlds = unique(done, "world")
    fig, axes = _figure(len(worlds))
    for ax, world in zip(axes, worlds, strict=True):
        parts = groups([r for r in done if r.get("world") == world])
        for i, (_, _, members) in enumerate(parts, start=1):
            data = values(members, "scans")
            color = f"C{(i - 1) % 10}"
            if len(data) > 1 and np.ptp(data) > 0:
                parts_i = ax.violinplot([data], positions=[i], showmedians=True, widths=0.8)
                for body in parts_i["bodies"]:
                    body.set_facecolor(color)
                for key in ("cbars", "cmins", "cmaxes", "cmedians"):
                    parts_i[key].set_color(color)
            else:
                ax.hlines(median(data), i - 0.3, i + 0.3, colors=color)
            ax.plot(np.full(len(data), i), data, "k.", alpha=0.4, markersize=4)
        ax.set_xticks(range(1, len(parts) + 1), [m for _, m, _ in parts], rotation=20, ha="right", fontsize=8)
        ax.set_title(str(world))
        ax.set_ylabel("scans to termination")
        ax.yaxis.set_major_locator(_whole_numbers())
        ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def plot_steps(table: Table | None, path: Path) -> Path | None:
    """Stacked bars: mean seconds per run in each step, per method."""
    if table is None or not table.values:
        return None
    steps = table.columns[2:]
    fig, axes = _figure(1, width=8.0, height=0.6 * len(table.values) + 2.0)
    ax = axes[0]
    methods = [v["method"] for v in table.values]
    left = np.zeros(len(methods))
    for step in steps:
        widths = np.array([v[step] for v in table.values])
        ax.barh(methods, widths, left=left, label=step)
        left += widths
    ax.set_xlabel("mean time per run [s]")
    ax.legend(fontsize=8, loc="best")
    ax.invert_yaxis()
    return _save(fig, path)


def plot_planners(table: Table, path: Path) -> Path | None:
    """Planning success and planning time per planner (all worlds pooled by planner and world)."""
    values = [v for v in table.values if math.isfinite(v["planning_success"]) or math.isfinite(v["planning_time_s"])]
    if not values:
        return None
    fig, axes = _figure(2)
    labels = [f"{v['planner']}\n{v['world']}" for v in values]
    worlds = list(dict.fromkeys(v["world"] for v in values))
    colors = [f"C{worlds.index(v['world']) % 10}" for v in values]
    axes[0].bar(labels, [v["planning_success"] * 100 if math.isfinite(v["planning_success"]) else 0 for v in values],
                color=colors)
    axes[0].set_ylabel("planning success [%]")
    axes[0].set_ylim(0, 105)
    axes[1].bar(labels, [v["planning_time_s"] if math.isfinite(v["planning_time_s"]) else 0 for v in values],
                color=colors)
    axes[1].set_ylabel("planning time per run [s]")
    from matplotlib.patches import Patch

    for ax in axes:
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(handles=[Patch(color=f"C{i % 10}", label=w) for i, w in enumerate(worlds)],
                  title="world", fontsize=8)
    return _save(fig, path)
