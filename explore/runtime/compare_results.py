"""A comparison's results: which runs are finished (a complete metrics.json or the driver's result.json), their
rows, and results.csv written atomically after every finished run and read back with numbers and lists parsed (a bad
file is one BadInput line)."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from explore.core import FINISHED, BadInput, brief, read_text
from explore.runtime.compare_grid import (
    ID_COLUMNS,
    LIST_COLUMNS,
    METRIC_COLUMNS,
    NUMBER_COLUMNS,
    RESULT_FILE,
    ROW_STATUSES,
    Grid,
    RunSpec,
    read_grid_file,
)


# -- run directories ---------------------------------------------------------------------------
def read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def complete_metrics(run_dir: Path) -> dict[str, Any] | None:
    """The run's metrics if its ``metrics.json`` is complete (parses, has a final status)."""
    metrics = read_json(run_dir / "metrics.json")
    if isinstance(metrics, dict) and metrics.get("status") in FINISHED:
        return metrics
    return None


def finished_row(spec: RunSpec) -> dict[str, Any] | None:
    """The results row of an already finished run (None: the run must be executed)."""
    row = read_json(spec.path / RESULT_FILE)
    if isinstance(row, dict) and row.get("status") in FINISHED and row.get("run_id") == spec.run_id:
        return row
    metrics = complete_metrics(spec.path)
    return row_from_metrics(spec, metrics, math.nan) if metrics is not None else None


def _flat(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def row_from_metrics(spec: RunSpec, metrics: dict[str, Any], wall_s: float) -> dict[str, Any]:
    """One results row: the grid values, the status and every metric of the run."""
    row: dict[str, Any] = spec.grid_values()
    row["status"] = metrics.get("status", "failure")
    row["reason"] = metrics.get("reason", "")
    for key, value in metrics.items():
        if key in ID_COLUMNS or key == "settings":
            continue
        row[key] = _flat(value)
    if metrics.get("planner"):
        row["planner_used"] = metrics["planner"]  # the grid's "default" names no planner
    row["wall_s"] = None if not math.isfinite(wall_s) else round(wall_s, 3)
    return row


def failed_row(spec: RunSpec, status: str, reason: str, wall_s: float) -> dict[str, Any]:
    """The row of a run that crashed or timed out (no metrics)."""
    row = spec.grid_values()
    row.update(status=status, reason=reason, wall_s=round(wall_s, 3))
    return row


# -- results.csv ---------------------------------------------------------------------------------
def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if not math.isfinite(value) else repr(value)
    if isinstance(value, list | dict | tuple):
        return json.dumps(value, separators=(",", ":"), default=str)
    return str(value)


def result_columns(rows: Iterable[dict[str, Any]]) -> list[str]:
    """Column order: grid values and status, the documented metrics, then the rest sorted."""
    present: set[str] = set()
    for row in rows:
        present.update(row)
    known = [c for c in METRIC_COLUMNS if c in present]
    rest = sorted(present - set(ID_COLUMNS) - set(known))
    return [*ID_COLUMNS, *known, *rest]


def write_results(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Write ``results.csv`` atomically (temporary file + rename)."""
    buffer = io.StringIO()
    columns = result_columns(rows)
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(buffer.getvalue(), encoding="utf-8")
    os.replace(tmp, path)


def _parse_cell(text: str) -> Any:
    if text == "":
        return None
    if text[0] in "[{":
        try:
            return json.loads(text)
        except ValueError:
            return text
    if text in ("true", "false"):
        return text == "true"
    try:
        number = float(text)
    except ValueError:
        return text
    return int(number) if re.fullmatch(r"-?\d+", text) else number


def read_results(path: Path) -> list[dict[str, Any]]:
    """Rows of a ``results.csv`` with numbers, booleans and JSON lists parsed (BadInput if it is not one)."""
    text = read_text(path)
    try:
        rows = list(csv.DictReader(io.StringIO(text, newline=""), strict=True))
    except csv.Error as error:
        raise BadInput(str(path), None, f"not a results table: {error}") from None
    if rows and ("run_id" not in rows[0] or "status" not in rows[0]):
        raise BadInput(str(path), None, "not a results table of explore compare (no run_id and status columns)")
    parsed = [{str(k): _parse_cell(v if isinstance(v, str) else "") for k, v in row.items()} for row in rows]
    for line, row in enumerate(parsed, start=2):
        _check_row(path, line, row)
    return parsed


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_missing(value: Any) -> bool:
    """A scan without a value in a per-scan list (JSON null or NaN)."""
    return value is None or (isinstance(value, float) and math.isnan(value))


def _check_row(path: Path, line: int, row: dict[str, Any]) -> None:
    """A row as ``explore compare`` writes it: a run id, a status it knows, numbers where the metrics are numbers,
    so that a hand-edited or foreign table is refused with its line, not summarised as if it were results."""
    def bad(column: str, what: str) -> BadInput:
        return BadInput(str(path), f"line {line}, {column}", what)

    if row.get("run_id") in (None, ""):
        raise bad("run_id", "empty")
    if row.get("status") not in ROW_STATUSES:
        raise bad("status", f"{brief(row.get('status'))} is not one of {', '.join(ROW_STATUSES)}")
    for column in NUMBER_COLUMNS:
        value = row.get(column)
        if value is not None and not _is_number(value):
            raise bad(column, f"expected a finite number or nothing, got {brief(value)}")
    for column in LIST_COLUMNS:
        value = row.get(column)
        if value is not None and not (isinstance(value, list) and all(_is_number(v) or _is_missing(v) for v in value)):
            raise bad(column, f"expected a JSON list of numbers or nothing, got {brief(value)}")


def check_grid_file(out: Path, grid: Grid) -> None:
    """Refuse to mix runs with different defining settings in one results folder."""
    previous = read_grid_file(out)
    if previous is None:
        return
    current = json.loads(json.dumps(grid.to_dict()))
    for key in Grid.DEFINING:
        if key in previous and previous[key] != current[key]:
            raise BadInput(
                str(out), key,
                f"holds a comparison with {key}={brief(previous[key])}, not {brief(current[key])}; "
                "choose another --out",
            )
