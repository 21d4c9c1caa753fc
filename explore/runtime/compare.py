"""Comparisons: the product of runs over worlds x strategies x planners x robots x seeds.

Every run is one isolated process (``python -m explore.runtime.compare --worker SPEC``) that calls
:func:`explore.runtime.run.execute` and writes its own run directory under ``DIR/runs/<run id>``.
Run ids are stable folder names built from the grid values, so re-running the same command
skips every run whose directory already holds a complete ``metrics.json`` (or a
``result.json`` written by the driver). A crash or a timeout is recorded with its reason
(status ``crashed`` / ``timeout``) and does not stop the others; such runs are tried again
on the next invocation. ``results.csv`` (one row per finished run, grid order) is rewritten
atomically after every finished run, so an interrupt loses nothing.

Runs get the same environment on every executor (``PYTHONHASHSEED=0``, ``threads`` BLAS /
OpenMP / numba threads each), so the same seeds give the same results locally and on Ray.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

from explore.core import FINISHED
from explore.runtime.compare_grid import (
    GRID_FILE,
    RESULT_FILE,
    RESULTS_FILE,
    Grid,
    RunSpec,
)
from explore.runtime.compare_results import (
    check_grid_file,
    finished_row,
    write_results,
)
from explore.runtime.isolated_runs import worker_main
from explore.runtime.report import write_report
from explore.runtime.run_inputs import write_json_atomic


class _Progress:
    """A rich progress bar with ETA (terminal) or one line per finished run (log)."""

    def __init__(self, total: int, done: int, console: Any) -> None:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.console = console
        self.total = total
        self.count = done
        self.started = time.monotonic()
        self.new = 0
        self.bar = None
        if console is not None and console.is_terminal:
            self.bar = Progress(
                TextColumn("[bold]compare"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=False,
            )
            self.task = self.bar.add_task("runs", total=total, completed=done)
            self.bar.start()

    def eta(self) -> str:
        if not self.new:
            return "?"
        left = (time.monotonic() - self.started) / self.new * (self.total - self.count)
        return f"{left:.0f} s"

    def advance(self, row: dict[str, Any]) -> None:
        self.count += 1
        self.new += 1
        if self.console is not None:
            extra = "" if row.get("scans") is None else f" scans={row['scans']}"
            if row.get("coverage") is not None:
                extra += f" coverage={row['coverage']:.3f}"
            line = f"[{self.count}/{self.total}] {row['run_id']}: {row['status']}{extra}"
            if row["status"] not in FINISHED:
                line += f" ({row['reason']})"
            self.console.print(f"{line}  ETA {self.eta()}", markup=False, highlight=False, soft_wrap=True)
        if self.bar is not None:
            self.bar.advance(self.task)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def compare(grid: Grid, out: Path, executor: Any, console: Any = None, report: bool = True) -> list[dict[str, Any]]:
    """Run every missing run of ``grid`` with ``executor``; write results.csv and the report."""
    out.mkdir(parents=True, exist_ok=True)
    check_grid_file(out, grid)
    write_json_atomic(out / GRID_FILE, grid.to_dict(), digits=None)
    specs = grid.runs(out)
    rows: dict[str, dict[str, Any]] = {}
    for spec in specs:
        row = finished_row(spec)
        if row is not None:
            rows[spec.run_id] = row
    order = [s.run_id for s in specs]
    results = out / RESULTS_FILE

    def ordered() -> list[dict[str, Any]]:
        return [rows[i] for i in order if i in rows]

    write_results(results, ordered())
    todo = [s for s in specs if s.run_id not in rows]
    if console is not None:
        console.print(
            f"{len(specs)} runs: {len(rows)} already finished, {len(todo)} to run", highlight=False, soft_wrap=True
        )
    progress = _Progress(len(specs), len(rows), console)

    def on_done(spec: RunSpec, row: dict[str, Any]) -> None:
        rows[spec.run_id] = row
        if row["status"] in FINISHED:
            spec.path.mkdir(parents=True, exist_ok=True)
            write_json_atomic(spec.path / RESULT_FILE, row, digits=None)
        write_results(results, ordered())
        progress.advance(row)

    try:
        if todo:
            executor.run(todo, on_done)
    finally:
        progress.close()
    final = ordered()
    if report:
        write_report(out, final)
    return final


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--worker":
        code = worker_main(sys.argv[2:])
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.stderr.write("usage: python -m explore.runtime.compare --worker SPEC.json (use `explore compare`)\n")
    raise SystemExit(2)
