"""Single-object modelling loop (thesis Fig. 4.1) usable from Python, one step at a time.

::

    from explore.nbv.modelling import ModellingSession
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    with Simulation("bunny_pedestal", registry) as sim:
        session = ModellingSession(sim, "ig_quality/bs_hr", registry, seed=0, max_scans=10)
        result = session.run()
        print(result.metrics["coverage"])      # ground-truth c_a after every scan

Each step is a method so a behaviour tree can call them one at a time: ``generate``,
``select``, ``terminate``, ``plan_best`` (or ``plan_initial`` before the first scan),
``execute``, ``acquire``, ``register``, ``integrate``. ``plan`` checks one candidate (scan-path
IK in 10 mm portions, the PVS along the scan with the NBS rule, the approach motion by the
motion-planner plugin, see :mod:`explore.nbv.scan_planning`); ``execute`` runs the approach with
the robot's positioning noise and records collisions with the true world; ``acquire`` runs
the scan motion and takes the scan; ``integrate`` updates PVS and mesh and appends the
:class:`ScanRecord` of the iteration (the steps before it leave their numbers in the
session, so a tree and :meth:`step` record the same). The planning side (PVS, surface
model, candidates, utility, termination, motion planning) never touches the ground truth;
only :meth:`ModellingSession.metrics` reads it, through :mod:`explore.mapping.metrics`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from explore.core import BUDGET, FAILURE, NO_CANDIDATES, Array, Pose
from explore.mapping import PVS, GroundTruthMetrics, SurfaceModel, VoxelGrid
from explore.motion import Capability, Execution
from explore.nbv.candidates import (
    STOP,
    Candidate,
    CandidateStack,
    Decision,
    PlanningContext,
    frame_from,
    modelling_standoff,
)
from explore.nbv.modelling_metrics import Evaluation
from explore.nbv.modelling_planning import CandidatePlanning
from explore.nbv.modelling_records import (
    FALLBACK_PREFIX,
    ModellingResult,
    ScanRecord,
    require_an_object,
    resolve_strategy,
)
from explore.nbv.scan_planning import ScanMotion, ScanPlan, make_planner
from explore.perception import rebase_scan, require_role, scan_points_and_normals
from explore.sim import Scan, ScanPath


class ModellingSession(Evaluation, CandidatePlanning):
    """World + robot + sensor + strategy -> planned, executed scans until termination -> metrics.

    One iteration (:meth:`step`): :meth:`generate` candidates, :meth:`select` the best by
    the utility, :meth:`terminate` (stop / switch to hole mode), :meth:`plan_best` (scan-path
    IK in 10 mm portions, the PVS along the scan with the NBS rule, the approach motion by
    the motion planner; the next best candidates when that fails), :meth:`execute` (approach
    motion with positioning noise, collisions with the true world), :meth:`acquire` (scan
    motion + scan), optionally :meth:`register` (local ICP), :meth:`integrate` (PVS, mesh,
    features; appends the :class:`ScanRecord`). The first scan uses :meth:`plan_initial`.
    A scan taken with :meth:`acquire` from a pose or scan path (no plan) puts the sensor
    there, as before motion planning existed. Planning and execution numbers:
    :meth:`motion_metrics`.

    Parameters
    ----------
    sim : Simulation with sensor and robot attached
    strategy : strategy name (e.g. "ig_quality/bs_hr"), (name, params) or a Strategy
    registry : the plugin registry
    seed : seeds the initial scan path, the sensor noise and random choices
    resolution : PVS voxel edge l_v (thesis: 5 mm)
    max_scans : hard cap on the scans (the thesis runs 30 regardless of the termination)
    planner : motion planner: plugin name, (name or None, params), plugin object, or None for
        ``rrt_connect`` (straight line first; around the PVS's unknown space when that is blocked)
    continue_after_stop : keep scanning to ``max_scans`` after the termination said stop,
        recording the scan count at which it did (the thesis' n_s); for benchmarks
    pvs_params, surface_params : extra keyword arguments of the PVS and the surface model
    fallback_generator : view generator used only when the strategy's generator leaves the
        stack empty (``ctx.exhausted``: the termination rule decides whether the run goes on with
        these candidates) or none of its candidates can be planned; None (default) disables it.
        Its scans are recorded with the source ``fallback_<name>`` and counted in
        ``metrics()["fallback_scans"]``.
    noise : execute motions with the robot's positioning noise model (Vasquez-Gomez Sec. A6)
    relocalise : a mobile base re-localises while it executes and steers back onto the plan
        (:class:`explore.nbv.scan_planning.ScanMotion`); False: open loop
    max_plan_attempts : candidates tried per iteration when planning the best one fails
    place_first : put the robot at the first scan instead of planning a motion to it (the
        thesis' free-flying sensor starts at its random initial scan path); None = only for
        a robot with the FREE_FLYER capability
    register_scans : :meth:`step` registers each scan to the model (:meth:`register`, the
        thesis' local ICP) before integrating it, as the ``register_scan`` behaviour does
    region : (min corner, max corner) of the box to model instead of the world's region (scene
        exploration models one cluster's box)
    obstacles : extra (lo, hi) boxes the planning treats as known environment (the rest of the scene)
    standoff : sensor distance of the views (m); None: :func:`explore.nbv.modelling_standoff` (the
        sensor's optimal distance, nearer for a sensor too coarse for the model's point spacing);
        0: the sensor's optimal distance
    """

    def __init__(self, sim: Any, strategy: Any, registry: Any, seed: int = 0, resolution: float = 0.005,
                 max_scans: int = 30, planner: Any = None, continue_after_stop: bool = False,
                 pvs_params: dict | None = None, surface_params: dict | None = None,
                 fallback_generator: str | None = None, noise: bool = True, relocalise: bool = True,
                 max_plan_attempts: int = 10,
                 place_first: bool | None = None, register_scans: bool = False,
                 region: tuple[Array, Array] | None = None,
                 obstacles: Sequence[tuple[Array, Array]] = (), standoff: float | None = None) -> None:
        if region is None:
            require_an_object(sim)
        self.sim = sim
        self.registry = registry
        self.strategy = resolve_strategy(strategy, registry)
        self.generator, self.utility, self.termination = self.strategy.build(registry)
        for part in (self.generator, self.termination):
            if hasattr(part, "reset"):
                part.reset()
        self.seed = seed
        self.max_scans = int(max_scans)
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
            stack=self.stack, rng=self.rng_plan, registry=registry, fallback_available=self.fallback is not None,
            standoff=modelling_standoff(self.sensor, self.surface.point_spacing) if standoff is None else standoff,
        )
        self.records: list[ScanRecord] = []
        self.scans: list[Scan] = []
        self.point_history: list[np.ndarray] = []  # reconstructed points after each scan (for metrics only)
        self.status = "running"
        self.reason = ""
        self.first_stop: int | None = None
        self.first_stop_reason = ""
        self.first_stop_outcome = ""
        self._end_outcome = ""
        self.selection_times: list[float] = []
        self.selection_sizes: list[int] = []
        self._metrics: GroundTruthMetrics | None = None
        self.max_plan_attempts = max(1, int(max_plan_attempts))
        self.register_scans = bool(register_scans)
        self.place_first = self.robot.has(Capability.FREE_FLYER) if place_first is None else place_first
        self.motion = ScanMotion(self.robot, self.pvs, make_planner(registry, self.robot, planner),
                                 np.random.default_rng(rng.integers(2**63)), int(rng.integers(1, 2**31 - 1)),
                                 noise=bool(noise), relocalise=bool(relocalise))
        self.planner = self.motion.planner
        self.plan_failure = ""
        self.take_fallback = False  # the next selection picks among the fallback's candidates (a FALLBACK decision)
        self._new_pending()

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
    def _initial_options(self) -> list[Pose | ScanPath]:
        """Scans along the 5 sides and 8 edges of the region box (thesis Sec. 4.7).

        The bottom side and bottom edges are left out (they overlap the pedestal). They stand at
        the sensor's optimal distance, not the (possibly nearer) modelling standoff: the first
        scan is to see the whole region.
        """
        lo, hi = self.ctx.region_min, self.ctx.region_max
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        x, y, z = np.eye(3)
        options = [(z, x), (x, z), (-x, z), (y, z), (-y, z)]  # (outward normal, sweep)
        options += [((s * x + z) / np.sqrt(2), y) for s in (1, -1)] + [((s * y + z) / np.sqrt(2), x) for s in (1, -1)]
        options += [((sx * x + sy * y) / np.sqrt(2), z) for sx in (1, -1) for sy in (1, -1)]
        standoff = float(self.sensor.optimal_distance)
        targets: list[Pose | ScanPath] = []
        for normal, sweep in options:
            depth = float(np.abs(normal) @ half)
            eye = centre + normal * (standoff + 0.5 * depth)
            pose = frame_from(-normal, sweep, eye)
            assert pose is not None
            if self.sensor.geometry != "line":
                targets.append(pose)
                continue
            length = float(2.0 * np.abs(sweep) @ half) + 0.04
            start, end = pose.copy(), pose.copy()
            start[:3, 3] -= 0.5 * length * pose[:3, 1]
            end[:3, 3] += 0.5 * length * pose[:3, 1]
            targets.append(ScanPath(start, end, getattr(self.sensor, "speed", 0.05)))
        return targets

    def initial_target(self) -> Pose | ScanPath:
        """Random initial scan among the 5 sides and 8 edges of the region box (thesis Sec. 4.7)."""
        options = self._initial_options()
        return options[int(self.rng_plan.integers(len(options)))]

    def initial_candidates(self) -> list[Candidate]:
        """The random initial scan first, then the other sides and edges (for robots that
        cannot reach the first one)."""
        options = self._initial_options()
        first = int(self.rng_plan.integers(len(options)))
        order = [(first + k) % len(options) for k in range(len(options))]
        return [Candidate(options[i], "initial", {"kind": "initial", "option": i}) for i in order]

    def _new_pending(self) -> None:
        """Numbers of the iteration in progress; :meth:`integrate` turns them into its record."""
        self._pending: dict[str, Any] = {
            "t0": time.perf_counter(), "source": "initial", "info": {"kind": "initial"}, "score": float("nan"),
            "selection_s": 0.0, "candidates": 0, "decision": "", "reason": "", "scan_length": 0.0, "travel": 0.0,
            "margin": float("nan"), "termination_margin": float("nan"),
        }

    def _pend_candidate(self, candidate: Candidate) -> None:
        self._pending.update(source=candidate.source, info=dict(candidate.info), score=candidate.score)

    def acquire(self, target: Pose | ScanPath | ScanPlan) -> tuple[Scan, float, float]:
        """Scan; returns the scan, the scan length and the travel since the last scan.

        With a :class:`ScanPlan` (after :meth:`execute`) the robot runs the scan motion from
        where the approach left it (noise, collisions with the true world) and the sensor
        scans along the executed motion. With a pose or scan path the sensor is put there
        (no robot motion; travel = straight distance, as the thesis' free-flying sensor).
        """
        if isinstance(target, ScanPlan):
            executed, run = self.motion.execute_scan(target, self.n_scans + 1)
            self._pend_candidate(target.candidate)
            travel = self._pending["travel"] + (self.motion.motions[-1].sensor_path_m if run is not None else 0.0)
            if run is not None:
                self._check_collision(run, "scan")
            target = executed
        else:
            start = target.start if isinstance(target, ScanPath) else target
            here = self.ctx.sensor_pose
            travel = 0.0 if here is None else float(np.linalg.norm(start[:3, 3] - here[:3, 3]))
            travel += target.length if isinstance(target, ScanPath) else 0.0
            end = target.end if isinstance(target, ScanPath) else target
            if self.robot is not None and hasattr(self.robot, "ik"):
                q = self.robot.ik(end)
                if q is not None:
                    self.robot.q = q
        scan_length = target.length if isinstance(target, ScanPath) else 0.0
        scan = self.sensor.acquire(self.sim, target, self.rng_sensor)
        end = target.end if isinstance(target, ScanPath) else target
        self.ctx.sensor_pose = np.asarray(end).copy()
        self.ctx.executed.append(np.asarray(target.mid if isinstance(target, ScanPath) else target).copy())
        self.scans.append(scan)
        self._pending.update(scan_length=scan_length, travel=travel)
        return scan, scan_length, travel

    def register(self, scan: Scan, registrar: Any = None, min_fitness: float = 0.3, max_shift: float = 0.01,
                 max_angle_deg: float = 3.0) -> tuple[Scan, Any]:
        """Local ICP of a new scan to the model before integration (Kriegel thesis Sec. 3.2.3).

        ``registrar`` is a :class:`~explore.perception.ScanToModelRegistrar` (default
        ``icp``: 3 mm radius, 3 iterations, 60 deg normal gate) matching the scan's points to
        the model mesh. The correction is applied to every beam
        (:func:`explore.perception.rebase_scan`) unless the match is weak (fitness below
        ``min_fitness``) or implausibly large (the scan's centroid moves more than
        ``max_shift``, or it turns more than ``max_angle_deg``); returns the (corrected) scan
        and the ICP result (None before there is a model).
        """
        model = self.surface.mesh
        if len(model.vertices) < 50 or not scan.hits.any():
            return scan, None
        registrar = require_role(registrar or self.registry.create(
            "registrar", *self.registry.default("registrar", "scan_to_model"), "<session>"), "scan_to_model")
        points, normals = scan_points_and_normals(scan)
        result = registrar.register(points, normals, model.vertices, self.surface.vertex_normals)
        transform = result.transformation
        centre = points.mean(axis=0)
        shift = float(np.linalg.norm(transform[:3, :3] @ centre + transform[:3, 3] - centre))
        angle = float(np.degrees(np.arccos(np.clip((np.trace(transform[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))))
        if result.fitness < min_fitness or shift > max_shift or angle > max_angle_deg:
            return scan, result
        return rebase_scan(scan, transform @ scan.sensor_poses[0]), result

    def integrate(self, scan: Scan) -> dict[str, Any]:
        """PVS + surface model + surface features into the PVS (thesis Fig. 4.1); records the scan."""
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
        coverage, off_support = self.surface.coverage_areas(support_z=float(self.ctx.region_min[2]))
        self.ctx.coverage_history.append(coverage)
        self.ctx.off_support_history.append(off_support)
        self.ctx.fallback_scans += self._pending["source"].startswith(FALLBACK_PREFIX)
        self.ctx.density_history.append(float(self.surface.mean_density()))
        self.ctx.unknown_history.append(int(self.pvs.counts()["unknown"]))
        out["integrate_s"] = time.perf_counter() - start
        pending = self._pending
        self.records.append(ScanRecord(
            index=self.n_scans, source=pending["source"], info=pending["info"], scan_length_m=pending["scan_length"],
            travel_m=pending["travel"], selection_s=pending["selection_s"], candidates=pending["candidates"],
            coverage_estimate=coverage, coverage_border=float(self.surface.coverage_border()),
            coverage_off_support=off_support,
            density=self.ctx.density_history[-1], unknown_voxels=self.ctx.unknown_history[-1],
            decision=pending["decision"], reason=pending["reason"], score=pending["score"],
            margin=pending["margin"], termination_margin=pending["termination_margin"],
            step_s=time.perf_counter() - pending["t0"],
        ))
        self._new_pending()
        return out

    def integrate_view(self, scan: Scan, sensor_pose: Array, source: str | None = None) -> dict[str, Any]:
        """Integrate a scan taken outside the session (a scene exploration view) from ``sensor_pose``;
        it is recorded with ``source``, or with the selected candidate's source when None."""
        self.scans.append(scan)
        self.ctx.executed.append(np.asarray(sensor_pose, dtype=float).copy())
        if source is not None:
            self._pending.update(source=source, info={"kind": source}, score=float("nan"))
        return self.integrate(scan)

    def execute(self, plan: ScanPlan) -> Execution | None:
        """Run the approach motion with the robot's positioning noise (collisions with the true world).

        A collision that stops the motion (robot ``on_collision: stop``) ends the session
        with status ``collided``.
        """
        run = self.motion.execute_approach(plan, self.n_scans + 1)
        if run is not None:
            self._pending["travel"] = self.motion.motions[-1].sensor_path_m
            self._check_collision(run, "approach")
        return run

    def _check_collision(self, run: Execution, kind: str) -> None:
        if run.collided and not run.completed:
            bodies = ", ".join(run.collisions[0].bodies)
            self.finish("collided", f"collision with {bodies} during the {kind} motion of scan {self.n_scans + 1}")

    def step(self) -> ScanRecord | None:
        """One iteration: (generate, select, terminate,) plan, execute, acquire, (register,) integrate.

        None when finished.
        """
        if self.status != "running":
            return None
        if self.n_scans == 0:
            plan = self.plan_initial()
            if plan is None:
                return self.finish("failed", f"no reachable initial scan ({self.plan_failure})")
        else:
            if self.n_scans >= self.max_scans:
                return self.finish("stopped", f"max_scans = {self.max_scans} reached", BUDGET)
            self.generate()
            candidate = self.select()
            decision = self.terminate()
            if decision.stop:
                self.note_stop(decision)
            if decision.stop and not self.continue_after_stop:
                return self.finish("stopped", decision.reason, decision.outcome)
            if candidate is None:
                self.note_stop(Decision(STOP, "no candidate left", NO_CANDIDATES))
                return self.finish("stopped", "no candidate left", NO_CANDIDATES)
            plan = self.plan_best(candidate)
            if plan is None:
                reason = f"no reachable candidate ({self.plan_failure})"
                self.note_stop(Decision(STOP, reason, NO_CANDIDATES))
                return self.finish("stopped", reason, NO_CANDIDATES)
        self.execute(plan)
        if self.status != "running":
            return None
        scan, _, _ = self.acquire(plan)
        if self.status != "running":
            return None
        if self.register_scans:
            scan, _ = self.register(scan)
        self.integrate(scan)
        return self.records[-1]

    def finish(self, status: str, reason: str, outcome: str = "") -> None:
        """End the session: ``stopped`` (a normal end, with its ``outcome``), ``failed`` or ``collided``."""
        self.status, self.reason, self._end_outcome = status, reason, outcome
        return None

    def note_stop(self, decision: Decision) -> None:
        """A stop decision; the first one gives n_s (thesis Table 4.5) and the run's outcome."""
        if self.first_stop is None:
            self.first_stop, self.first_stop_reason = self.n_scans, decision.reason
            self.first_stop_outcome = decision.outcome

    @property
    def outcome(self) -> str:
        """How the modelling ended (:mod:`explore.core.outcomes`): a failure or collision fails it; else the
        first stop decides (scanning on after it, as the thesis benchmark does, changes nothing)."""
        if self.status in ("failed", "collided"):
            return FAILURE
        if self.status == "running":
            return ""
        return self.first_stop_outcome or self._end_outcome or BUDGET

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
