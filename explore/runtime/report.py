"""The report of a comparison: summary.md, summary.json, PNG plots and one report.html.

Everything is computed from the rows of ``results.csv`` (plus the runs' ``trace.jsonl`` for
the time per step), so ``explore compare --plot-only DIR`` redraws it at any time.

Tables
------
* **Kriegel thesis Table 4.5 layout**, one per world: median scans ñ_s with the notch
  ±1.57·IQR/√n (IQR by linear interpolation, n = finished runs), mean coverage c_a at
  termination, mean c_a after N scans (the last value carried forward when a run stopped
  earlier; N = the grid's ``--max-scans``, else the longest run), mean path length, mean
  selection time per scan.
* **Vasquez-Gomez Table 5 layout**: mean / max coverage and the collision rate =
  collisions / executed trajectories (the metric ``trajectories`` when a run reports it,
  else scans − 1), plus the share of runs with a collision.
* **Planners**: run success, planning success (mean of ``planning_success``), planning time
  and path length per world and planner.
* **Runs**: how many runs succeeded, failed, crashed or timed out, and their wall time.
* **Time per step**: mean seconds per run spent in each long-running behaviour (from the
  trace: a leaf node's RUNNING -> SUCCESS/FAILURE intervals).

Crashed and timed-out runs count only in the runs table.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import FINISHED

STATUSES = (*FINISHED, "crashed", "timeout")
METHOD_DIMS = ("strategy", "planner", "robot")
NOTCH_FACTOR = 1.57
MISSING = "–"


@dataclass
class Table:
    """A titled table of formatted cells (the same cells go to Markdown and HTML)."""

    key: str
    title: str
    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    note: str = ""
    values: list[dict[str, Any]] = field(default_factory=list)  # the numbers behind the cells

    def markdown(self) -> str:
        lines = [f"### {self.title}", ""]
        if self.note:
            lines += [self.note, ""]
        lines.append("| " + " | ".join(self.columns) + " |")
        lines.append("|" + "|".join("---" for _ in self.columns) + "|")
        lines += ["| " + " | ".join(row) + " |" for row in self.rows]
        return "\n".join(lines) + "\n"

    def html(self) -> str:
        head = "".join(f"<th>{html.escape(c)}</th>" for c in self.columns)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in self.rows)
        note = f"<p class='note'>{html.escape(self.note)}</p>" if self.note else ""
        return (
            f"<section><h3>{html.escape(self.title)}</h3>{note}<table id='{self.key}'>"
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></section>"
        )


# -- numbers ------------------------------------------------------------------------------------
def _num(value: Any) -> float:
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, int | float) and math.isfinite(float(value)):
        return float(value)
    return math.nan


def _values(rows: Sequence[dict[str, Any]], key: str) -> np.ndarray:
    data = np.array([_num(r.get(key)) for r in rows], dtype=float)
    return data[np.isfinite(data)]


def _values_or(rows: Sequence[dict[str, Any]], key: str, fallback: str) -> np.ndarray:
    """``key`` of each row, ``fallback`` where the row has no number for it."""
    data = np.array([_num(r.get(key)) if math.isfinite(_num(r.get(key))) else _num(r.get(fallback)) for r in rows],
                    dtype=float)
    return data[np.isfinite(data)]


def mean(data: np.ndarray) -> float:
    return float(np.mean(data)) if len(data) else math.nan


def median(data: np.ndarray) -> float:
    return float(np.median(data)) if len(data) else math.nan


def notch(data: np.ndarray) -> float:
    """Kriegel's notch half-width 1.57·IQR/√n (Eq. 4.41)."""
    if not len(data):
        return math.nan
    q1, q3 = np.percentile(data, [25, 75])
    return float(NOTCH_FACTOR * (q3 - q1) / math.sqrt(len(data)))


def coverage_at(row: dict[str, Any], n: int) -> float:
    """c_a after ``n`` scans; the last value carried forward if the run stopped earlier."""
    curve = row.get("coverage_per_scan")
    if not isinstance(curve, list) or not curve or n < 1:
        return math.nan
    return _num(curve[min(n, len(curve)) - 1])


def fmt(value: float, digits: int = 2, scale: float = 1.0, prefix: str = "") -> str:
    if not math.isfinite(value):
        return MISSING
    return f"{prefix}{value * scale:.{digits}f}"


def fmt_count(value: float) -> str:
    if not math.isfinite(value):
        return MISSING
    return f"{value:.0f}" if float(value).is_integer() else f"{value:.1f}"


# -- grouping -----------------------------------------------------------------------------------
def _unique(rows: Sequence[dict[str, Any]], key: str) -> list[Any]:
    seen: list[Any] = []
    for row in rows:
        if row.get(key) not in seen:
            seen.append(row.get(key))
    return seen


def method_label(row: dict[str, Any], varying: Sequence[str]) -> str:
    parts = [str(row.get(d)) for d in varying]
    return " · ".join(parts) if parts else str(row.get("strategy"))


def varying_dims(rows: Sequence[dict[str, Any]]) -> list[str]:
    dims = [d for d in METHOD_DIMS if len(_unique(rows, d)) > 1]
    return dims or ["strategy"]


def groups(rows: Sequence[dict[str, Any]], by_world: bool = True) -> list[tuple[str, str, list[dict[str, Any]]]]:
    """(world, method, rows) in the order of first appearance."""
    dims = varying_dims(rows)
    out: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        key = (str(row.get("world")) if by_world else "all", method_label(row, dims))
        out.setdefault(key, []).append(row)
    return [(w, m, rs) for (w, m), rs in out.items()]


def scans_at(rows: Sequence[dict[str, Any]], grid: dict[str, Any] | None) -> int:
    """N of c_a(N): the grid's --max-scans, else the longest coverage curve (at least 1)."""
    if grid and grid.get("max_scans"):
        return int(grid["max_scans"])
    lengths = [len(r["coverage_per_scan"]) for r in rows if isinstance(r.get("coverage_per_scan"), list)]
    return max(lengths, default=30) or 1


# -- tables -------------------------------------------------------------------------------------
def kriegel_tables(rows: Sequence[dict[str, Any]], n_at: int) -> list[Table]:
    tables: dict[str, Table] = {}
    for world, method, members in groups(rows):
        done = [r for r in members if r.get("status") in FINISHED]
        # n_s: where the termination first said stop (runs that scan on to the budget record it)
        scans = _values_or(done, "n_s", "scans")
        at_stop = _values_or(done, "coverage_at_stop", "coverage")
        cov_n = np.array([coverage_at(r, n_at) for r in done], dtype=float)
        cov_n = cov_n[np.isfinite(cov_n)]
        value = {
            "world": world, "method": method, "n": len(done), "median_scans": median(scans), "notch": notch(scans),
            "coverage_at_termination": mean(at_stop), "coverage_at_n": mean(cov_n),
            "path_length_m": mean(_values(done, "path_length_m")),
            "selection_s": mean(_values(done, "selection_s_mean")),
        }
        table = tables.setdefault(world, Table(
            f"kriegel-{world}", f"Kriegel Table 4.5 layout — {world}",
            ["Method", "n", "ñ_s", "Notch", "c̄_a(n_s) %", f"c̄_a({n_at}) %", "l̄_s / m", "t̄_nbs / s"],
            note="ñ_s median scans; notch ±1.57·IQR/√n; c̄_a mean actual coverage at termination and after "
            f"{n_at} scans; l̄_s mean path length; t̄_nbs mean selection time per scan.",
        ))
        table.values.append(value)
        table.rows.append([
            method, str(len(done)), fmt_count(value["median_scans"]), fmt(value["notch"], prefix="±"),
            fmt(value["coverage_at_termination"], scale=100), fmt(value["coverage_at_n"], scale=100),
            fmt(value["path_length_m"]), fmt(value["selection_s"], digits=3),
        ])
    return list(tables.values())


def collision_rate(rows: Sequence[dict[str, Any]]) -> float:
    """Collisions / executed trajectories (``trajectories``, else scans − 1) over the runs."""
    collisions = trajectories = 0.0
    for row in rows:
        c = _num(row.get("collisions"))
        t = _num(row.get("trajectories"))
        if not math.isfinite(t):
            s = _num(row.get("scans"))
            t = max(s - 1.0, 0.0) if math.isfinite(s) else math.nan
        if math.isfinite(c) and math.isfinite(t):
            collisions += c
            trajectories += t
    if trajectories > 0:
        return collisions / trajectories
    return 0.0 if rows and collisions == 0 and trajectories == 0 else math.nan


def vasquez_table(rows: Sequence[dict[str, Any]]) -> Table:
    table = Table(
        "vasquez", "Vasquez-Gomez Table 5 layout",
        ["World", "Method", "n", "Mean cov. %", "Max cov. %", "Collision rate %", "Runs with collision %"],
        note="coverage at termination; collision rate = collisions / executed trajectories.",
    )
    for world, method, members in groups(rows):
        done = [r for r in members if r.get("status") in FINISHED]
        cov = _values(done, "coverage")
        hit = _values(done, "collisions")
        value = {
            "world": world, "method": method, "n": len(done), "mean_coverage": mean(cov),
            "max_coverage": float(np.max(cov)) if len(cov) else math.nan, "collision_rate": collision_rate(done),
            "runs_with_collision": float(np.mean(hit > 0)) if len(hit) else math.nan,
        }
        table.values.append(value)
        table.rows.append([
            world, method, str(len(done)), fmt(value["mean_coverage"], 1, 100), fmt(value["max_coverage"], 1, 100),
            fmt(value["collision_rate"], 1, 100), fmt(value["runs_with_collision"], 0, 100),
        ])
    return table


def planner_table(rows: Sequence[dict[str, Any]]) -> Table:
    table = Table(
        "planners", "Planners",
        ["World", "Planner", "runs", "Run success %", "Planning success %", "Planning time / s", "Path / m"],
        note="planning success = mean of the runs' planning_success; run success = tree succeeded.",
    )
    by: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        by.setdefault((str(row.get("world")), str(row.get("planner"))), []).append(row)
    for (world, planner), members in by.items():
        done = [r for r in members if r.get("status") in FINISHED]
        value = {
            "world": world, "planner": planner, "runs": len(members),
            "run_success": float(np.mean([r.get("status") == "success" for r in members])),
            "planning_success": mean(_values(done, "planning_success")),
            "planning_time_s": mean(_values(done, "planning_time_s")),
            "path_length_m": mean(_values(done, "path_length_m")),
        }
        table.values.append(value)
        table.rows.append([
            world, planner, str(len(members)), fmt(value["run_success"], 0, 100),
            fmt(value["planning_success"], 0, 100), fmt(value["planning_time_s"], 3), fmt(value["path_length_m"]),
        ])
    return table


def status_table(rows: Sequence[dict[str, Any]]) -> Table:
    table = Table("runs", "Runs", ["World", "Method", *STATUSES, "Mean wall time / s"])
    for world, method, members in groups(rows):
        counts = {s: sum(r.get("status") == s for r in members) for s in STATUSES}
        wall = mean(_values(members, "wall_s"))
        table.values.append({"world": world, "method": method, **counts, "wall_s": wall})
        table.rows.append([world, method, *(str(counts[s]) for s in STATUSES), fmt(wall, 1)])
    return table


def step_times(trace: Path) -> dict[str, float]:
    """Seconds per leaf behaviour from a trace's RUNNING -> SUCCESS/FAILURE intervals."""
    since: dict[str, float] = {}
    intervals: list[tuple[str, float, float]] = []
    ends: list[tuple[float, str]] = []
    try:
        lines = trace.read_text(encoding="utf-8").splitlines()
    except OSError:
        return {}
    for line in lines:
        try:
            event = json.loads(line)
        except ValueError:
            continue
        if event.get("event") != "status" or "t" not in event:
            continue
        node, status, t = str(event.get("node")), event.get("status"), float(event["t"])
        if status == "RUNNING":
            since[node] = t
        elif status in ("SUCCESS", "FAILURE"):
            ends.append((t, node))
            if node in since:
                intervals.append((node, since.pop(node), t))
        else:
            since.pop(node, None)
    composite = {n for n, t0, t1 in intervals if any(t0 < t < t1 and m != n for t, m in ends)}
    out: dict[str, float] = {}
    for node, t0, t1 in intervals:
        if node not in composite:
            out[node] = out.get(node, 0.0) + (t1 - t0)
    return out


def time_table(rows: Sequence[dict[str, Any]], runs_dir: Path) -> Table | None:
    per_method: dict[str, list[dict[str, float]]] = {}
    dims = varying_dims(rows)
    for row in rows:
        if row.get("status") not in FINISHED:
            continue
        times = step_times(runs_dir / str(row.get("run_id")) / "trace.jsonl")
        if times:
            per_method.setdefault(method_label(row, dims), []).append(times)
    if not per_method:
        return None
    steps: list[str] = []
    for runs in per_method.values():
        for times in runs:
            steps += [s for s in times if s not in steps]
    table = Table("steps", "Time per step (mean s per run)", ["Method", "runs", *steps])
    for method, runs in per_method.items():
        means = {s: float(np.mean([t.get(s, 0.0) for t in runs])) for s in steps}
        table.values.append({"method": method, "runs": len(runs), **means})
        table.rows.append([method, str(len(runs)), *(fmt(means[s], 2) for s in steps)])
    return table


# -- plots --------------------------------------------------------------------------------------
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
    worlds = _unique(done, "world")
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
        ax.set_ylabel("coverage c_a [%]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    return _save(fig, path)


def plot_scans(rows: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """Violin plots of the scans to termination per method, one panel per world."""
    done = [r for r in rows if r.get("status") in FINISHED and math.isfinite(_num(r.get("scans")))]
    if not done:
        return None
    worlds = _unique(done, "world")
    fig, axes = _figure(len(worlds))
    for ax, world in zip(axes, worlds, strict=True):
        parts = groups([r for r in done if r.get("world") == world])
        for i, (_, _, members) in enumerate(parts, start=1):
            data = _values(members, "scans")
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
    axes[0].bar(labels, [v["planning_success"] * 100 if math.isfinite(v["planning_success"]) else 0 for v in values])
    axes[0].set_ylabel("planning success [%]")
    axes[0].set_ylim(0, 105)
    axes[1].bar(labels, [v["planning_time_s"] if math.isfinite(v["planning_time_s"]) else 0 for v in values])
    axes[1].set_ylabel("planning time per run [s]")
    for ax in axes:
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


# -- writing ------------------------------------------------------------------------------------
def _png_data(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}th,td{border:1px solid #bbb;padding:.25em .6em;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}.note{color:#555;font-size:.9em}
figure{margin:1em 0}img{max-width:100%;border:1px solid #ddd}figcaption{color:#555}
"""


def write_report(out: Path, rows: Sequence[dict[str, Any]]) -> dict[str, Path]:
    """Write summary.md, summary.json, the PNGs and report.html into ``out``; return the paths."""
    from explore.runtime.compare import GRID_FILE, RUNS_DIR, _write_json_atomic

    grid = None
    if (out / GRID_FILE).is_file():
        grid = json.loads((out / GRID_FILE).read_text(encoding="utf-8"))
    n_at = scans_at(rows, grid)
    tables = [*kriegel_tables(rows, n_at), vasquez_table(rows), planner_table(rows), status_table(rows)]
    steps = time_table(rows, out / RUNS_DIR)
    if steps is not None:
        tables.append(steps)
    figures: list[tuple[Path, str]] = []
    for made, caption in (
        (plot_coverage(rows, n_at, out / "coverage_vs_scans.png"), "Coverage c_a vs scans: median and IQR band"),
        (plot_scans(rows, out / "scans_violin.png"), "Scans to termination"),
        (plot_steps(steps, out / "time_per_step.png"), "Time per step (mean per run)"),
        (plot_planners(_find(tables, "planners"), out / "planners.png"), "Planner success and time"),
    ):
        if made is not None:
            figures.append((made, caption))
    finished = sum(r.get("status") in FINISHED for r in rows)
    header = f"{len(rows)} runs ({finished} finished)"
    if grid:
        header += f"; tree {Path(str(grid.get('tree'))).stem}, max scans {grid.get('max_scans') or 'tree default'}"
    md = ["# Comparison summary", "", header, ""]
    md += [t.markdown() for t in tables]
    md += [f"![{caption}]({p.name})\n" for p, caption in figures]
    (out / "summary.md").write_text("\n".join(md), encoding="utf-8")
    _write_json_atomic(out / "summary.json", {t.key: {"title": t.title, "rows": t.values} for t in tables})
    body = [f"<h1>Comparison report</h1><p>{html.escape(header)}</p>"]
    body += [t.html() for t in tables]
    body += [
        f"<figure><img src='{_png_data(p)}' alt='{html.escape(c)}'><figcaption>{html.escape(c)}</figcaption></figure>"
        for p, c in figures
    ]
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>explore compare report</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>\n"
    )
    (out / "report.html").write_text(page, encoding="utf-8")
    written = {name: out / name for name in ("summary.md", "summary.json", "report.html")}
    written.update({p.name: p for p, _ in figures})
    return written


def _find(tables: Sequence[Table], key: str) -> Table:
    return next(t for t in tables if t.key == key)
