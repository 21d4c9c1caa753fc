"""Single-object modelling loop (thesis Fig. 4.1) usable from Python, one step at a time.

::

    from explore.modelling import ModellingSession
    from explore.registry import Registry
    from explore.simulation import Simulation

    registry = Registry.load()
    with Simulation("bunny_pedestal", registry) as sim:
        session = ModellingSession(sim, "ig_quality/bs_hr", registry, seed=0, max_scans=10)
        result = session.run()
        print(result.metrics["coverage"])      # ground-truth c_a after every scan

Each step is a method so a behaviour tree can call them one at a time: ``initial_target``,
``acquire``, ``integrate``, ``generate``, ``select``, ``terminate``. The planning side (PVS,
surface model, candidates, utility, termination) never touches the ground truth; only
:meth:`ModellingSession.metrics` reads it, through :mod:`explore.metrics`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .candidates import STOP, SWITCH, Candidate, CandidateStack, Decision, PlanningContext, frame_from
from .scan import Scan, ScanPath
from .typed import Array, Pose
from .visibility import VoxelGrid


@dataclass
class ScanRecord:
    """What one iteration did."""

    index: int
    source: str
    info: dict[str, Any]
    scan_length_m: float
    travel_m: float
    selection_s: float
    candidates: int
    coverage_estimate: float
    coverage_border: float
    density: float
    unknown_voxels: int
    decision: str = ""
    reason: str = ""
    score: float = float("nan")
    step_s: float = 0.0
    coverage: float = float("nan")  # ground-truth c_a, filled by metrics()


@dataclass
class ModellingResult:
    """The outcome of :meth:`ModellingSession.run`."""

    status: str
    reason: str
    records: list[ScanRecord]
    metrics: dict[str, Any] = field(default_factory=dict)


def resolve_strategy(strategy: Any, registry: Any) -> Any:
    """A :class:`explore_plugins.strategies.Strategy` from a name, (name, params) or an object."""
    if isinstance(strategy, str):
        return registry.create("strategy", strategy, {}, "<strategy>").strategy
    if isinstance(strategy, tuple):
        return registry.create("strategy", strategy[0], strategy[1], "<strategy>").strategy
    return getattr(strategy, "strategy", strategy)


class ModellingSession:
    """World + free-flying sensor + strategy -> scans until termination -> metrics.

    Parameters
    ----------
    sim : Simulation with sensor and robot attached
    strategy : strategy name (e.g. "ig_quality/bs_hr"), (name, params) or a Strategy
    registry : the plugin registry
    seed : seeds the initial scan path, the sensor noise and random choices
    resolution : PVS voxel edge l_v (thesis: 5 mm)
    max_scans : hard cap on the scans (the thesis runs 30 regardless of the termination)
    planner : motion planner plugin or None (the free flyer moves in straight lines)
    continue_after_stop : keep scanning to ``max_scans`` after the termination said stop,
        recording the scan count at which it did (the thesis' n_s); for benchmarks
    pvs_params, surface_params : extra keyword arguments of the PVS and the surface model
    fallback_generator : view generator used only when the strategy's generator leaves the
        stack empty (so that a benchmark run can go on to ``max_scans``); None disables it.
        Its candidates are recorded with their own source name.
    region : (min corner, max corner) of the box to model instead of the world's region (scene
        exploration models one cluster's box)
    obstacles : extra (lo, hi) boxes the planning treats as known environment (the rest of the scene)
    """

    def __init__(self, sim: Any, strategy: Any, registry: Any, seed: int = 0, resolution: float = 0.005,
                 max_scans: int = 30, planner: Any = None, continue_after_stop: bool = False,
                 pvs_params: dict | None = None, surface_params: dict | None = None,
                 fallback_generator: str | None = "sphere", region: tuple[Array, Array] | None = None,
                 obstacles: Sequence[tuple[Array, Array]] = ()) -> None:
        from .pvs import PVS
        from .surface import SurfaceModel

        self.sim = sim
        self.registry = registry
        self.strategy = resolve_strategy(strategy, registry)
        self.generator, self.utility, self.termination = self.strategy.build(registry)
        for part in (self.generator, self.termination):
            if hasattr(part, "reset"):
                part.reset()
        self.seed = seed
        self.max_scans = int(max_scans)
        self.planner = planner
        self.continue_after_stop = continue_after_stop
        self.sensor = sim.sensor
        self.robot = sim.robot
        region_min = np.asarray(sim.spec.region_min if region is None else region[0], dtype=float)
        region_max = np.asarray(sim.spec.region_max if region is None else region[1], dtype=float)
        self.obstacles = [(np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)) for lo, hi in obstacles]
        self.pvs = PVS.for_region(region_min, region_max, resolution, **(pvs_params or {}))
        self.surface = SurfaceModel(region_min, region_max, **(surface_params or {}))
        self.stack = CandidateStack()
        self.fallback = (registry.create("view_generator", fallback_generator, {}, "<session>")
                         if fallback_generator and fallback_generator != self.strategy.generator else None)
        rng = np.random.default_rng(seed)
        self.rng_sensor = np.random.default_rng(rng.integers(2**63))
        self.rng_plan = np.random.default_rng(rng.integers(2**63))
        self.ctx = PlanningContext(
            pvs=self.pvs, surface=self.surface, grid=self._snapshot(), sensor=self.sensor, robot=self.robot,
            region_min=region_min, region_max=region_max, environment_boxes=self._environment_boxes(),
            stack=self.stack, rng=self.rng_plan,
        )
        self.records: list[ScanRecord] = []
        self.scans: list[Scan] = []
        self.point_history: list[np.ndarray] = []  # reconstructed points after each scan (for metrics only)
        self.status = "running"
        self.reason = ""
        self.first_stop: int | None = None
        self.first_stop_reason = ""
        self.selection_times: list[float] = []
        self.selection_sizes: list[int] = []
        self._pending: Candidate | None = None
        self._metrics = None

    # -- setup helpers -------------------------------------------------------------------
    def _environment_boxes(self) -> list[tuple[Array, Array]]:
        """Boxes of the known static environment (the planner may know it)."""
        return [tuple(b.mesh.bounds) for b in self.sim.bodies if not b.is_object] + list(self.obstacles)

    def _snapshot(self) -> VoxelGrid:
        """Dense copy of the PVS with the surface features for the utilities."""
        pvs = self.pvs
        prob = (1.0 / (1.0 + np.exp(-pvs.log_odds.astype(np.float64)))).astype(np.float32)
        grid = VoxelGrid(prob, np.asarray(pvs.origin, dtype=float), float(pvs.resolution))
        feats = pvs.features
        if "density" in feats:
            density = feats["density"]
            has = np.isfinite(density)
            grid.has_feature = has
            grid.density = np.nan_to_num(density).astype(np.float32)
            grid.border = np.nan_to_num(feats.get("border", np.zeros_like(density))).astype(np.float32)
            normal = np.nan_to_num(feats.get("normal", np.zeros(density.shape + (3,)))).astype(np.float32)
            norm = np.linalg.norm(normal, axis=-1, keepdims=True)
            grid.normal = np.divide(normal, norm, out=np.zeros_like(normal), where=norm > 0)
        grid.ensure_features()
        return grid

    @property
    def n_scans(self) -> int:
        return len(self.records)

    # -- the steps -----------------------------------------------------------------------
    def initial_target(self) -> Pose | ScanPath:
        """Random initial scan among the 5 sides and 8 edges of the region box (thesis Sec. 4.7).

        The bottom side and bottom edges are left out (they overlap the pedestal).
        """
        lo, hi = self.ctx.region_min, self.ctx.region_max
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        x, y, z = np.eye(3)
        options = [(z, x), (x, z), (-x, z), (y, z), (-y, z)]  # (outward normal, sweep)
        options += [((s * x + z) / np.sqrt(2), y) for s in (1, -1)] + [((s * y + z) / np.sqrt(2), x) for s in (1, -1)]
        options += [((sx * x + sy * y) / np.sqrt(2), z) for sx in (1, -1) for sy in (1, -1)]
        normal, sweep = options[int(self.rng_plan.integers(len(options)))]
        standoff = float(self.sensor.optimal_distance)
        depth = float(np.abs(normal) @ half)
        eye = centre + normal * (standoff + 0.5 * depth)
        pose = frame_from(-normal, sweep, eye)
        assert pose is not None
        if self.sensor.geometry != "line":
            return pose
        length = float(2.0 * np.abs(sweep) @ half) + 0.04
        start, end = pose.copy(), pose.copy()
        start[:3, 3] -= 0.5 * length * pose[:3, 1]
        end[:3, 3] += 0.5 * length * pose[:3, 1]
        return ScanPath(start, end, getattr(self.sensor, "speed", 0.05))

    def acquire(self, target: Pose | ScanPath) -> tuple[Scan, float, float]:
        """Move (free flyer: straight line) and acquire; returns the scan, scan length and travel."""
        start = target.start if isinstance(target, ScanPath) else target
        here = self.ctx.sensor_pose
        travel = 0.0 if here is None else float(np.linalg.norm(start[:3, 3] - here[:3, 3]))
        scan_length = target.length if isinstance(target, ScanPath) else 0.0
        scan = self.sensor.acquire(self.sim, target, self.rng_sensor)
        end = target.end if isinstance(target, ScanPath) else target
        if self.robot is not None and hasattr(self.robot, "ik"):
            q = self.robot.ik(end)
            if q is not None:
                self.robot.q = q
        self.ctx.sensor_pose = np.asarray(end).copy()
        self.ctx.executed.append(np.asarray(target.mid if isinstance(target, ScanPath) else target).copy())
        self.scans.append(scan)
        return scan, scan_length, travel + scan_length

    def integrate(self, scan: Scan) -> dict[str, Any]:
        """PVS + surface model + surface features into the PVS (thesis Fig. 4.1)."""
        start = time.perf_counter()
        out: dict[str, Any] = {"pvs": self.pvs.integrate(scan), "surface": self.surface.integrate(scan)}
        resolution = self.pvs.resolution
        ijk, density, normals, border = self.surface.voxel_features(resolution, self.pvs.origin)
        self.pvs.features.clear()  # features are recomputed from the current mesh every time
        if len(ijk):
            self.pvs.set_features(self.pvs.centers(ijk), density, normals, border)
        self.ctx.grid = self._snapshot()
        self.point_history.append(np.array(self.surface.points, dtype=np.float32))
        self.ctx.iteration += 1
        self.ctx.last_scan = scan
        coverage = float(self.surface.coverage_area())
        self.ctx.coverage_history.append(coverage)
        self.ctx.density_history.append(float(self.surface.mean_density()))
        self.ctx.unknown_history.append(int(self.pvs.counts()["unknown"]))
        out["integrate_s"] = time.perf_counter() - start
        return out

    def generate(self) -> int:
        """Add the generator's candidates to the stack (stale ones are dropped); returns how many."""
        keep = ("sphere",) if getattr(self.generator, "persistent", False) else ()
        self.stack.drop_stale(self.ctx.iteration, self.ctx.executed, keep_sources=keep)
        new = [c for c in self.generator.generate(self.ctx)
               if not any(self.stack._similar(c.pose, pose) for pose in self.ctx.executed)]
        self.stack.push(new)
        if len(self.stack) == 0 and self.fallback is not None and self.continue_after_stop:
            if hasattr(self.fallback, "reset"):
                self.fallback.reset()
            extra = self.fallback.generate(self.ctx)
            for cand in extra:
                cand.source = f"fallback_{cand.source}"
            self.stack.push(extra)
            new = new + extra
        return len(new)

    def select(self) -> Candidate | None:
        """Score the stack with the utility and pop the best candidate (timed)."""
        self.ctx.available = len(self.stack)
        if len(self.stack) == 0:
            return None
        start = time.perf_counter()
        items = list(self.stack)
        scores = np.asarray(self.utility.score(items, self.ctx), dtype=float)
        for cand, value in zip(items, scores, strict=True):
            cand.score = float(value)
        best = int(np.argmax(np.where(np.isfinite(scores), scores, -np.inf)))
        elapsed = time.perf_counter() - start
        self.selection_times.append(elapsed)
        self.selection_sizes.append(len(items))
        chosen = self.stack.pop(best)
        self.ctx.best_diagnostics = dict(chosen.diagnostics)
        if hasattr(self.generator, "remember"):
            self.generator.remember(chosen)
        return chosen

    def terminate(self) -> Decision:
        """Ask the termination plugin (and the hard cap); a ``switch`` sets the hole mode."""
        if self.n_scans >= self.max_scans:
            return Decision(STOP, f"max_scans = {self.max_scans} reached")
        decision = self.termination.decide(self.ctx)
        if decision.action == SWITCH:
            self.ctx.mode = "hole"
        return decision

    def step(self) -> ScanRecord | None:
        """One iteration: (generate, select, terminate,) acquire, integrate. None when finished."""
        if self.status != "running":
            return None
        t0 = time.perf_counter()
        selection_s, n_cands, decision = 0.0, 0, Decision()
        if self.n_scans == 0:
            candidate = Candidate(self.initial_target(), "initial", {"kind": "initial"})
        else:
            if self.n_scans >= self.max_scans:
                return self._finish("stopped", f"max_scans = {self.max_scans} reached")
            self.generate()
            n_cands = len(self.stack)
            candidate = self.select()
            selection_s = self.selection_times[-1] if candidate is not None else 0.0
            decision = self.terminate()
            if decision.stop and self.first_stop is None:
                self.first_stop, self.first_stop_reason = self.n_scans, decision.reason
            if decision.stop and not self.continue_after_stop:
                return self._finish("stopped", decision.reason)
            if candidate is None:
                if self.first_stop is None:
                    self.first_stop, self.first_stop_reason = self.n_scans, "no candidate left"
                return self._finish("stopped", "no candidate left")
        scan, scan_length, travel = self.acquire(candidate.target)
        self.integrate(scan)
        record = ScanRecord(
            index=self.n_scans, source=candidate.source, info=dict(candidate.info), scan_length_m=scan_length,
            travel_m=travel, selection_s=selection_s, candidates=n_cands,
            coverage_estimate=self.ctx.coverage_history[-1], coverage_border=float(self.surface.coverage_border()),
            density=self.ctx.density_history[-1], unknown_voxels=self.ctx.unknown_history[-1],
            decision=decision.action, reason=decision.reason, score=candidate.score,
            step_s=time.perf_counter() - t0,
        )
        self.records.append(record)
        return record

    def _finish(self, status: str, reason: str) -> None:
        self.status, self.reason = status, reason
        return None

    def run(self, progress: Callable[[ScanRecord], None] | None = None) -> ModellingResult:
        """Step until the termination (or ``max_scans``) stops the run."""
        while self.status == "running":
            record = self.step()
            if record is None:
                break
            if progress is not None:
                progress(record)
        if self.status == "running":
            self.status = "stopped"
        return ModellingResult(self.status, self.reason, self.records, self.metrics())

    # -- evaluation (the only place that reads the ground truth) -------------------------
    def ground_truth(self) -> Any:
        if self._metrics is None:
            self._metrics = GroundTruth(self.sim)
        return self._metrics

    def coverage_curve(self) -> list[float]:
        """Ground-truth c_a after every scan (from the point sets kept after each integration)."""
        gt = self.ground_truth()
        return [gt.coverage(points) for points in self.point_history]

    def metrics(self, ground_truth: bool = True) -> dict[str, Any]:
        """Scans, c_a and ĉ_m per scan, density, path lengths, selection times, status."""
        curve = self.coverage_curve() if ground_truth and self.point_history else []
        for record, value in zip(self.records, curve, strict=False):
            record.coverage = value
        n_s = self.first_stop if self.first_stop is not None else self.n_scans
        return {
            "strategy": self.strategy.name,
            "world": self.sim.spec.name,
            "seed": self.seed,
            "scans": self.n_scans,
            "n_s": n_s,
            "stop_reason": self.first_stop_reason or self.reason,
            "status": self.status,
            "reason": self.reason,
            "coverage": curve,
            "coverage_at_stop": curve[n_s - 1] if curve and n_s >= 1 else float("nan"),
            "coverage_estimate": [r.coverage_estimate for r in self.records],
            "coverage_border": [r.coverage_border for r in self.records],
            "density": [r.density for r in self.records],
            "scan_path_m": float(sum(r.scan_length_m for r in self.records)),
            "travel_m": float(sum(r.travel_m for r in self.records)),
            "scan_path_at_stop_m": float(sum(r.scan_length_m for r in self.records[:n_s])),
            "selection_s": list(self.selection_times),
            "selection_candidates": list(self.selection_sizes),
            "sources": [r.source for r in self.records],
        }


class GroundTruth:
    """c_a of a surface model against the object's ground truth (via :mod:`explore.metrics` when present)."""

    def __init__(self, sim: Any, tau: float = 0.003) -> None:
        self.tau = tau
        self.impl = None
        try:
            from .metrics import GroundTruthMetrics

            self.impl = GroundTruthMetrics(sim, tau=tau)
        except ImportError:
            self.impl = None
        if self.impl is None:
            self._fallback(sim)

    def _fallback(self, sim: Any) -> None:
        """Dense samples of the object surface above the support (no visibility test)."""
        from scipy.spatial import cKDTree

        mesh = sim.object_mesh()
        tri = mesh.vertices[mesh.triangles]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        rng = np.random.default_rng(0)
        count = int(min(60000, max(2000, area.sum() / (0.0015**2))))
        pick = rng.choice(len(tri), count, p=area / area.sum())
        u, v = rng.random((2, count))
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        pts = tri[pick, 0] + u[:, None] * (tri[pick, 1] - tri[pick, 0]) + v[:, None] * (tri[pick, 2] - tri[pick, 0])
        floor = sim.spec.region_min[2] + 0.004
        self.samples = pts[pts[:, 2] > floor]
        self._tree = cKDTree

    def coverage(self, points: Any) -> float:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if self.impl is not None:
            return float(self.impl.coverage(points))
        if len(points) == 0:
            return 0.0
        dist, _ = self._tree(points).query(self.samples, distance_upper_bound=self.tau)
        return float(np.mean(np.isfinite(dist)))
