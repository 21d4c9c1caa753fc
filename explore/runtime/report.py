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
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from explore.core import FINISHED
from explore.runtime.compare_grid import RUNS_DIR, read_grid_file
from explore.runtime.report_plots import plot_coverage, plot_planners, plot_scans, plot_steps
from explore.runtime.report_tables import (
    Table,
    kriegel_tables,
    planner_table,
    scans_at,
    status_table,
    time_table,
    vasquez_table,
)
from explore.runtime.run_inputs import write_json_atomic


# -- writing ------------------------------------------------------------------------------------
def _png_data(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;padding:0 1em;max-width:1200px;color:#222}
.scroll{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;margin:.5em 0 1.5em}th,td{border:1px solid #bbb;padding:.25em .6em;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}.note{color:#555;font-size:.9em}
figure{margin:1em 0}img{max-width:100%;border:1px solid #ddd}figcaption{color:#555}
"""


def write_report(out: Path, rows: Sequence[dict[str, Any]]) -> dict[str, Path]:
    """Write summary.md, summary.json, the PNGs and report.html into ``out``; return the paths."""
    grid = read_grid_file(out)
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
    videos = run_videos(out, rows)
    md = ["# Comparison summary", "", header, ""]
    md += [t.markdown() for t in tables]
    md += [f"![{caption}]({p.name})\n" for p, caption in figures]
    if videos:
        md += ["## Videos", "", *[f"- [{label}]({path})" for label, path in videos], ""]
    (out / "summary.md").write_text("\n".join(md), encoding="utf-8")
    write_json_atomic(out / "summary.json", {t.key: {"title": t.title, "rows": t.values} for t in tables}, digits=None)
    body = [f"<h1>Comparison report</h1><p>{html.escape(header)}</p>"]
    body += [t.html() for t in tables]
    body += [
        f"<figure><img src='{_png_data(p)}' alt='{html.escape(c)}'><figcaption>{html.escape(c)}</figcaption></figure>"
        for p, c in figures
    ]
    if videos:
        body.append("<h2>Videos</h2>" + "".join(
            f"<figure><video controls width='960' src='{html.escape(path)}'></video>"
            f"<figcaption>{html.escape(label)}</figcaption></figure>" for label, path in videos))
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>explore compare report</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>\n"
    )
    (out / "report.html").write_text(page, encoding="utf-8")
    written = {name: out / name for name in ("summary.md", "summary.json", "report.html")}
    written.update({p.name: p for p, _ in figures})
    return written


def run_videos(out: Path, rows: Sequence[dict[str, Any]]) -> list[tuple[str, str]]:
    """(method, path relative to ``out``) of every run that wrote a video (``explore compare
    --video``: each method's first seed)."""
    found = []
    for row in rows:
        path = out / RUNS_DIR / str(row.get("run_id")) / "run.mp4"
        if path.is_file():
            method = " / ".join(str(row.get(k)) for k in ("world", "strategy", "planner", "robot") if row.get(k))
            found.append((f"{method}, seed {row.get('seed')}", path.relative_to(out).as_posix()))
    return found


def _find(tables: Sequence[Table], key: str) -> Table:
    return next(t for t in tables if t.key == key)
