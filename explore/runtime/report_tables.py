"""The tables of a comparison's report: Kriegel's Table 4.5 layout (scans to the stop, coverage, path, selection
time), Vasquez-Gomez's Table 5 (coverage and collision rate per method), the planners and the time per tree step,
with medians and notched intervals."""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import FINISHED
from explore.runtime.compare_grid import DEFAULT, ROW_STATUSES

METHOD_DIMS = ("strategy", "planner", "robot", "variant")


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
            f"<section><h3>{html.escape(self.title)}</h3>{note}<div class='scroll'><table id='{self.key}'>"
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div></section>"
        )


# -- numbers ------------------------------------------------------------------------------------
def num(value: Any) -> float:
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, int | float) and math.isfinite(float(value)):
        return float(value)
    return math.nan


def values(rows: Sequence[dict[str, Any]], key: str) -> np.ndarray:
    data = np.array([num(r.get(key)) for r in rows], dtype=float)
    return data[np.isfinite(data)]


def _values_or(rows: Sequence[dict[str, Any]], key: str, fallback: str) -> np.ndarray:
    """``key`` of each row, ``fallback`` where the row has no number for it."""
    data = np.array([num(r.get(key)) if math.isfinite(num(r.get(key))) else num(r.get(fallback)) for r in rows],
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
    return num(curve[min(n, len(curve)) - 1])


def fmt(value: float, digits: int = 2, scale: float = 1.0, prefix: str = "") -> str:
    if not math.isfinite(value):
        return MISSING
    return f"{prefix}{value * scale:.{digits}f}"


def fmt_count(value: float) -> str:
    if not math.isfinite(value):
        return MISSING
    return f"{value:.0f}" if float(value).is_integer() else f"{value:.1f}"


# -- grouping -----------------------------------------------------------------------------------
def unique(rows: Sequence[dict[str, Any]], key: str) -> list[Any]:
    seen: list[Any] = []
    for row in rows:
        if row.get(key) not in seen:
            seen.append(row.get(key))
    return seen


def method_label(row: dict[str, Any], varying: Sequence[str]) -> str:
    parts = [str(row.get(d)) for d in varying]
    return " · ".join(parts) if parts else str(row.get("strategy"))


def varying_dims(rows: Sequence[dict[str, Any]]) -> list[str]:
    dims = [d for d in METHOD_DIMS if len(unique(rows, d)) > 1]
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
            "path_length_m": mean(values(done, "path_length_m")),
            "selection_s": mean(values(done, "selection_s_mean")),
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
        c = num(row.get("collisions"))
        t = num(row.get("trajectories"))
        if not math.isfinite(t):
            s = num(row.get("scans"))
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
        cov = values(done, "coverage")
        hit = values(done, "collisions")
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
        used = {str(r["planner_used"]) for r in members if r.get("planner_used")}
        if planner == DEFAULT and len(used) == 1:
            planner = f"{used.pop()} (default)"  # the planner the robot or the registry chose
        done = [r for r in members if r.get("status") in FINISHED]
        value = {
            "world": world, "planner": planner, "runs": len(members),
            "run_success": float(np.mean([r.get("status") == "success" for r in members])),
            "planning_success": mean(values(done, "planning_success")),
            "planning_time_s": mean(values(done, "planning_time_s")),
            "path_length_m": mean(values(done, "path_length_m")),
        }
        table.values.append(value)
        table.rows.append([
            world, planner, str(len(members)), fmt(value["run_success"], 0, 100),
            fmt(value["planning_success"], 0, 100), fmt(value["planning_time_s"], 3), fmt(value["path_length_m"]),
        ])
    return table


def status_table(rows: Sequence[dict[str, Any]]) -> Table:
    table = Table("runs", "Runs", ["World", "Method", *ROW_STATUSES, "Mean wall time / s"])
    for world, method, members in groups(rows):
        counts = {s: sum(r.get("status") == s for r in members) for s in ROW_STATUSES}
        wall = mean(values(members, "wall_s"))
        table.values.append({"world": world, "method": method, **counts, "wall_s": wall})
        table.rows.append([world, method, *(str(counts[s]) for s in ROW_STATUSES), fmt(wall, 1)])
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
