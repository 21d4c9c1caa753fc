"""Writing a run directory: metrics.json, meshes, pvs.npz, pictures and the tree diagram."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

from .run import METRICS_SCHEMA_VERSION, RunContext, _jsonable


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON through a temporary file so an interrupt never leaves half a file."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_jsonable(data), indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def write_tree_diagram(root: Any, out_dir: Path, name: str = "tree") -> list[Path]:
    """The tree as Graphviz dot (always) and PNG (when the ``dot`` program exists)."""
    import py_trees

    graph = py_trees.display.dot_tree(root, collapse_decorators=False)
    dot_path = out_dir / f"{name}.dot"
    dot_path.write_text(graph.to_string(), encoding="utf-8")
    written = [dot_path]
    if shutil.which("dot"):
        png = out_dir / f"{name}.png"
        subprocess.run(["dot", "-Tpng", str(dot_path), "-o", str(png)], check=False, capture_output=True, timeout=60)
        if png.exists():
            written.append(png)
    return written


def write_outputs(context: RunContext, tree_file: Any, root: Any, status: str, reason: str) -> dict[str, Any]:
    """Collect metrics from the run's library objects, write every output, return metrics."""
    config = context.config
    metrics: dict[str, Any] = {
        "schema_version": METRICS_SCHEMA_VERSION,
        "tree": tree_file.name,
        "tree_file": str(tree_file.path),
        "world": context.sim.spec.name,
        "robot": context.sim.robot.name if context.sim.robot is not None else None,
        "sensor": context.sim.sensor.name if context.sim.sensor is not None else None,
        "strategy": config.strategy,
        "planner": config.planner,
        "seed": config.seed,
        "settings": config.settings,
        "status": status,
        "reason": reason,
        "collisions": 0,
        "objects": [],
    }
    for key in sorted(context.state):
        provider = context.state[key]
        if hasattr(provider, "run_outputs"):
            metrics.update(provider.run_outputs(context.out_dir))
    metrics["elapsed_s"] = round(context.elapsed(), 3)
    write_tree_diagram(root, context.out_dir)
    write_json_atomic(context.out_dir / "metrics.json", metrics)
    return metrics
