"""Writing a run directory: metrics.json, meshes, pvs.npz, pictures and the tree diagram.

:func:`write_outputs` always writes ``metrics.json``, also after an early failure: every
other output is written by a provider in ``context.state`` (an object with
``run_outputs(out_dir) -> dict``), and a provider that fails is reported in
``output_errors`` instead of stopping the rest. The schema is in ``docs/metrics.md``.
"""

from __future__ import annotations

import shutil
import subprocess
import unicodedata
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import save_curves_png
from explore.mapping import GroundTruthMetrics
from explore.motion import wall_guard_stops
from explore.runtime.context import RunContext
from explore.runtime.run_inputs import METRICS_SCHEMA_VERSION, write_json_atomic

OBJECT_MODELLED = 0.8  # c_a from which an object counts as modelled (the thesis' coverage target)


def object_result(coverage: float | None) -> str:
    """What happened to a modelled object: ``modelled`` (c_a >= :data:`OBJECT_MODELLED`), ``partial``
    or ``not_seen``."""
    if coverage is None or coverage <= 0.0:
        return "not_seen"
    return "modelled" if coverage >= OBJECT_MODELLED else "partial"


def tree_dot(root: Any) -> Any:
    """py_trees' dot graph with plain-text labels.

    py_trees prefixes composite labels with Unicode symbols (circled M for memory, a
    lightning bolt for synchronised parallels) that Graphviz' default fonts lack; they
    become words on a second line instead of missing-glyph boxes.
    """
    import py_trees

    graph = py_trees.display.dot_tree(root, collapse_decorators=False)
    words = {"\u24c2": "memory", "\u26a1": "synchronised"}
    for node in graph.get_nodes():
        label = node.get("label")
        if not label:
            continue
        text = label.strip('"')
        notes = [words.get(ch, "") for ch in text if ch in words]
        plain = "".join(ch for ch in text if unicodedata.category(ch) != "So" and ch not in words).strip()
        if notes:
            plain += "\\n(" + ", ".join(n for n in notes if n) + ")"
        node.set("label", f'"{plain}"')
    _add_legend(graph)
    return graph


# py_trees' node styles (display.dot_tree): what each shape and colour stands for
LEGEND = (
    ("sequence", "box", "orange"), ("selector", "octagon", "cyan"), ("parallel", "parallelogram", "gold"),
    ("decorator", "ellipse", "ghostwhite"), ("behaviour", "ellipse", "gray"),
)


def _add_legend(graph: Any) -> None:
    """A boxed key of the node kinds beside the tree."""
    import pydot

    legend = pydot.Cluster("legend", label="legend", fontsize="9", style="dashed", color="gray")
    names = []
    for kind, shape, colour in LEGEND:
        name = f"legend_{kind}"
        legend.add_node(pydot.Node(name, label=kind, shape=shape, style="filled", fillcolor=colour, fontsize="9"))
        names.append(name)
    for a, b in zip(names, names[1:], strict=False):  # stacked in this order
        legend.add_edge(pydot.Edge(a, b, style="invis"))
    graph.add_subgraph(legend)


def write_tree_diagram(root: Any, out_dir: Path, name: str = "tree") -> list[Path]:
    """The tree as Graphviz dot (always) and PNG (when the ``dot`` program exists)."""
    dot_path = out_dir / f"{name}.dot"
    dot_path.write_text(tree_dot(root).to_string(), encoding="utf-8")
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
    sim = context.sim
    metrics: dict[str, Any] = {
        "schema_version": METRICS_SCHEMA_VERSION,
        "tree": tree_file.name,
        "tree_file": str(tree_file.path),
        "world": sim.spec.name,
        "robot": sim.robot.name if sim.robot is not None else None,
        "sensor": sim.sensor.name if sim.sensor is not None else None,
        "strategy": config.strategy,
        "planner": config.planner,
        "seed": config.seed,
        "planning_clock": config.planning_clock,
        # plans the work clock's hang guard cut (wall time decided them: the run may not repeat)
        "wall_guard_stops": wall_guard_stops() if config.planning_clock == "work" else None,
        "settings": config.settings,
        "status": status,
        "reason": reason,
        "collisions": 0,
        "trajectories": 0,
        "objects": [],
    }
    errors: list[str] = []
    for key in sorted(context.state):
        provider = context.state[key]
        if hasattr(provider, "run_outputs"):
            try:
                metrics.update(provider.run_outputs(context.out_dir))
            except Exception as error:  # noqa: BLE001 - the other outputs and metrics.json still get written
                errors.append(f"{key}: {type(error).__name__}: {error}")
    if root is not None:
        try:
            write_tree_diagram(root, context.out_dir)
        except Exception as error:  # noqa: BLE001
            errors.append(f"tree diagram: {type(error).__name__}: {error}")
    if errors:
        metrics["output_errors"] = errors
        for line in errors:
            context.trace("output_error", error=line)
    metrics["elapsed_s"] = round(context.elapsed(), 3)
    write_json_atomic(context.out_dir / "metrics.json", metrics)
    return metrics


class ModellingOutputs:
    """What a run shows and writes about its :class:`~explore.nbv.modelling.ModellingSession`.

    Live numbers for the view (scans, ĉ_m, ground-truth c_a after each integration), and at
    the end the metrics, the mesh (PLY + PNG), ``pvs.npz`` and the coverage curve. The ground
    truth is read here for reporting only; planners never see it.
    """

    def __init__(self, session: Any, strategy: str, context: Any = None) -> None:
        self.session = session
        self.strategy = strategy
        self.context = context
        self.coverage: list[float] = []  # c_a after each scan, for the live view

    def after_integration(self) -> None:
        """c_a of the points after the latest integration (one KD-tree query, ~30 ms)."""
        session = self.session
        self.coverage.append(float(session.ground_truth().coverage(session.point_history[-1])))

    @property
    def end_reason(self) -> str:
        """Why the modelling ended (the run's reason when the tree succeeds)."""
        return str(self.session.reason)

    @property
    def end_outcome(self) -> str:
        """How the modelling ended (:mod:`explore.core.outcomes`; the run's status when the tree succeeds)."""
        return self.session.outcome

    def live_stats(self) -> dict[str, Any]:
        s = self.session
        stats: dict[str, Any] = {"strategy": self.strategy, "scans": s.n_scans}
        if s.records:
            stats["ĉ_m (estimate)"] = float(s.records[-1].coverage_estimate)
        if self.coverage:
            stats["c_a (ground truth)"] = self.coverage[-1]
        stats["candidates"] = len(s.stack)
        motion = s.motion
        if motion.plans:
            stats["planning ok"] = f"{sum(p.verdict == 'ok' for p in motion.plans)}/{len(motion.plans)}"
        collided = sum(m.collided for m in motion.motions)
        if collided:
            stats["collisions"] = collided
        return stats

    def status_line(self) -> str:
        s = self.session
        parts = [f"scans {s.n_scans}"]
        if s.records:
            parts.append(f"ĉ_m {s.records[-1].coverage_estimate:.3f}")
        if self.coverage:
            parts.append(f"c_a {self.coverage[-1]:.3f}")
        return "  ".join(parts)

    def run_outputs(self, out_dir: Any) -> dict[str, Any]:
        """Meshes, PVS, pictures and the modelling metrics for metrics.json."""
        out_dir = Path(out_dir)
        s = self.session
        metrics = s.metrics()
        files: dict[str, str | None] = {"mesh": None, "mesh_png": None, "pvs": None, "pvs_octomap": None,
                                         "coverage_png": None}
        if len(s.surface.mesh.triangles):  # nothing to write before the first scan
            s.surface.save_ply(out_dir / "model.ply")
            s.surface.save_png(out_dir / "model.png", f"{s.sim.spec.name}: {s.n_scans} scans")
            files["mesh"], files["mesh_png"] = "model.ply", "model.png"
        s.pvs.save(out_dir / "pvs.npz")
        s.pvs.save_octomap(out_dir / "pvs.bt")
        files["pvs"], files["pvs_octomap"] = "pvs.npz", "pvs.bt"
        coverage = list(metrics.get("coverage") or [])
        estimate = list(metrics.get("coverage_estimate") or [])
        off_support = list(metrics.get("coverage_off_support") or [])
        if estimate:
            x = np.arange(1, len(estimate) + 1)
            curves = {"ĉ_m (estimate)": (x, np.asarray(estimate))}
            if off_support:
                curves["ĉ_m without the support opening"] = (x, np.asarray(off_support))
            if coverage:
                curves["c_a (ground truth)"] = (x[: len(coverage)], np.asarray(coverage))
            save_curves_png(curves, out_dir / "coverage.png", "scans", "coverage", self.strategy)
            files["coverage_png"] = "coverage.png"
        selection = list(metrics.get("selection_s") or [])
        motion = s.motion_metrics()
        return {
            "strategy": self.strategy,
            "planner": motion.pop("planner"),
            "scans": s.n_scans,
            "modelling_status": s.status,
            "modelling_reason": s.reason,
            "coverage": coverage[-1] if coverage else None,
            "coverage_per_scan": coverage,
            "coverage_estimate": estimate[-1] if estimate else None,
            "coverage_estimate_per_scan": estimate,
            "coverage_off_support_per_scan": off_support,
            "density_per_scan": metrics.get("density"),
            "path_length_m": metrics.get("travel_m"),
            "scan_path_m": metrics.get("scan_path_m"),
            "selection_s_mean": float(np.mean(selection)) if selection else None,
            "selection_s_per_scan": selection,
            "n_s": metrics.get("n_s"),
            "coverage_at_stop": metrics.get("coverage_at_stop"),
            "stop_reason": metrics.get("stop_reason"),
            "sources": metrics.get("sources"),
            **motion,
            "objects": object_results(s, coverage[-1] if coverage else None),
            "files": files,
        }


def object_results(session: Any, overall: float | None) -> list[dict[str, Any]]:
    """Per object: c_a of the final model against that object's observable surface, and a verdict.

    ``result`` is ``modelled`` (c_a >= :data:`OBJECT_MODELLED`), ``partial`` (some of it),
    ``not_seen`` (c_a = 0) or ``outside_region`` (its box does not meet the region of interest).
    """
    sim = session.sim
    objects = sim.objects()
    points = session.point_history[-1] if session.point_history else np.zeros((0, 3))
    lo, hi = np.asarray(sim.spec.region_min, dtype=float), np.asarray(sim.spec.region_max, dtype=float)
    out = []
    for body in objects:
        blo, bhi = body.mesh.bounds
        inside = bool(np.all(bhi >= lo) and np.all(blo <= hi))
        if not inside:
            coverage: float | None = None
        elif len(objects) == 1 and overall is not None:
            coverage = overall
        else:
            coverage = float(GroundTruthMetrics(sim, gt_mesh=sim.object_mesh(body.name)).coverage(points))
        result = object_result(coverage) if inside else "outside_region"
        out.append({"name": body.name, "known": body.known, "coverage": coverage, "result": result})
    return out
