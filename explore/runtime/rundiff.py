"""What must repeat between two runs with the same seed, and where two runs differ.

Everything in ``metrics.json`` and ``trace.jsonl`` repeats except wall times
(:data:`WALL_TIME_FIELDS`, marked "timing" in ``docs/metrics.md``), tick numbers (how many
ticks a step took depends on the machine's speed, not on what it decided) and absolute paths
(the run folder, databases). :func:`run_differences` lists every other difference; the
determinism tests and ``benchmarks/same_metrics.py`` use it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

WALL_TIME_FIELDS = frozenset({
    "t", "elapsed_s", "scene_elapsed_s", "timings_s", "planning_time_s", "planning_time_s_total", "selection_s",
    "selection_s_mean", "selection_s_per_scan", "seconds", "step_s", "integrate_s", "planning_s", "median_s",
    "total_s", "stage_s", "stage_times_s", "wall_s", "selection_s_median", "stage_s_per_move",
})
TICK_FIELDS = frozenset({"tick"})
_ABSOLUTE_PATH = re.compile(r"(?<![\w.~])/[^\s,;:'\"()]+")


def comparable(value: Any) -> Any:
    """``value`` without wall times and tick numbers, absolute paths replaced by ``<path>``."""
    if isinstance(value, dict):
        return {k: comparable(v) for k, v in value.items() if k not in WALL_TIME_FIELDS | TICK_FIELDS}
    if isinstance(value, list):
        return [comparable(v) for v in value]
    if isinstance(value, str):
        return _ABSOLUTE_PATH.sub("<path>", value)
    return value


def differences(a: Any, b: Any, where: str = "") -> list[str]:
    """Every place where two JSON values differ, as ``path: a != b`` lines."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: list[str] = []
        for key in sorted(set(a) | set(b), key=str):
            if key not in a or key not in b:
                out.append(f"{where}.{key}: only in {'the second' if key not in a else 'the first'}")
            else:
                out += differences(a[key], b[key], f"{where}.{key}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: {len(a)} items != {len(b)} items"]
        return [line for i, (x, y) in enumerate(zip(a, b, strict=True)) for line in differences(x, y, f"{where}[{i}]")]
    return [] if a == b else [f"{where}: {str(a)[:60]} != {str(b)[:60]}"]


def load_run(run_dir: str | Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A run directory's metrics and trace events."""
    run_dir = Path(run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    lines = (run_dir / "trace.jsonl").read_text(encoding="utf-8").splitlines()
    return metrics, [json.loads(line) for line in lines if line.strip()]


def run_differences(first: str | Path, second: str | Path) -> list[str]:
    """Differences between two run directories beyond wall times, tick numbers and paths."""
    (m1, t1), (m2, t2) = load_run(first), load_run(second)
    out = [f"metrics{line}" for line in differences(comparable(m1), comparable(m2))]
    out += [f"trace{line}" for line in differences(comparable(t1), comparable(t2))]
    return out
