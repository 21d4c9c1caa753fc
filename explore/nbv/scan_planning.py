"""Planning and executing scans with a robot: scan-path IK, motion planning on the PVS, noise.

A next-best-scan candidate becomes a :class:`ScanPlan` in three checks (Kriegel thesis
Sec. 2 "motion planning" and Sec. 4.5.2; Kriegel et al. IROS 2012 Sec. B6):

1. **Reachability of the scan.** A linear scan path is split into 10 mm portions, each
   reached by IK from the previous one without an extra waypoint
   (:func:`explore.motion.linear_scan_path_ik`); a single view needs one IK solution. The IK
   already rejects configurations in collision with the *known* environment. A path that is
   reachable only in part (from either end) is shortened to its reachable part if that is
   at least ``min_scan_share`` of it (Kriegel thesis Algorithm 3 accepts a path that is at
   least 50 % collision-free).
2. **The PVS along the scan.** Every configuration of the scan must be valid for the motion
   problem (known environment + every robot surface point free in the PVS: occupancy
   p < 0.05, unknown counts as an obstacle). A blocked scan follows the NBS rule
   (:func:`explore.motion.classify_blocked`): through occupied space -> discard; through
   unknown space -> keep the candidate on the stack for later.
3. **The approach motion** from the robot's current configuration to the scan start, by the
   motion-planner plugin (OMPL, or ``straight_line``) in the same validity checker. A
   failure keeps the candidate for later (the blocking space may be observed free).

Before the first scan the PVS holds no information at all (everything is unknown), so the
initial scan is planned against the known environment alone (``use_pvs=False``): the thesis
gives the initial scan path rather than planning it, and a robot whose start posture lies
inside the region of interest could not move otherwise. The voxels the robot's body has stood
in count as free (:class:`explore.motion.BodyFreeSpace`), and a robot that noise left inside the
planning clearance (not touching anything) first backs out of it (:meth:`ScanMotion._escape`).

:class:`ScanMotion` also executes plans: :meth:`ScanMotion.execute_approach` and
:meth:`ScanMotion.execute_scan` call ``robot.execute`` (positioning noise, collision events
against the TRUE world; a mobile base re-localises and steers back onto its plan,
:func:`explore.motion.execute_following`) and turn the executed configurations into the sensor
target the scan is acquired from. Ground truth is never used for planning.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Pose, wrap_angle
from explore.motion import (
    BLOCK_OCCUPIED,
    BLOCK_UNKNOWN,
    BodyFreeSpace,
    Capability,
    Execution,
    MotionPlan,
    MotionProblem,
    ScanPathIK,
    classify_blocked,
    escape_motion,
    execute_following,
    joined_plans,
    linear_scan_path_ik,
    path_is_valid,
    path_length,
    scan_path_poses,
)
from explore.nbv.candidates import Candidate
from explore.sim import ScanPath

OK, UNREACHABLE, OCCUPIED, UNKNOWN, NO_PATH = "ok", "unreachable", "occupied", "unknown", "no_path"
KEEP_FOR_LATER = (UNKNOWN, NO_PATH)  # verdicts that leave the candidate on the stack


@dataclass
class ScanPlan:
    """The outcome of planning one candidate.

    ``verdict`` is ``ok`` or why not: ``unreachable`` (IK), ``occupied`` / ``unknown`` (the
    scan runs through occupied / unknown PVS space), ``no_path`` (no approach motion).
    ``scan_configs`` (m, dof) are the configurations along the scan (one for a single view);
    ``approach`` is the motion from the start configuration to ``scan_configs[0]`` (None when
    the robot is placed at the scan start, as the thesis' free-flying sensor at its first scan).
    """

    candidate: Candidate
    verdict: str
    reason: str = ""
    approach: MotionPlan | None = None
    scan_configs: np.ndarray | None = None
    planning_time: float = 0.0
    target: Pose | ScanPath | None = None  # the scan as planned (a shortened path); None = the candidate's

    @property
    def scan_target(self) -> Pose | ScanPath:
        return self.candidate.target if self.target is None else self.target

    @property
    def ok(self) -> bool:
        return self.verdict == OK

    @property
    def length(self) -> float:
        """Weighted configuration length of the approach (Vasquez-Gomez Eq. 8)."""
        return 0.0 if self.approach is None else float(self.approach.length)


@dataclass
class PlanRecord:
    """One planning attempt (for the metrics ``planning_success`` and ``planning_time_s``)."""

    scan: int  # number (1-based) of the scan it was planned for
    source: str
    verdict: str
    seconds: float
    planner: str


@dataclass
class MotionRecord:
    """One executed motion (approach or scan) as ``robot.execute`` reported it."""

    scan: int  # number (1-based) of the scan it belongs to
    kind: str  # "approach" | "scan"
    steps: int
    duration_s: float
    sensor_path_m: float
    config_length: float
    collided: bool
    bodies: tuple[str, ...] = ()
    completed: bool = True


class CapabilityMap:
    """Where a fixed-base robot can put its sensor: a cheap test and good IK seeds.

    A capability map in the sense of Zacharias et al. (2007): sensor poses (FK) of
    ``samples`` uniform random configurations. A pose passes :meth:`feasible` if some
    sampled sensor position lies within ``radius`` and its view axis within ``angle_deg``
    (generous tolerances, so a reachable pose rarely fails); :meth:`seeds` returns the
    configurations of the sampled poses closest to a target, from which IK (damped least
    squares) converges far more often than from random restarts: an unreachable scan path
    costs a few local IK runs instead of the robot's random restarts (about 1 s each
    direction on the iiwa).
    """

    def __init__(self, robot: Any, rng: np.random.Generator, samples: int = 10000, radius: float = 0.08,
                 angle_deg: float = 75.0) -> None:
        from scipy.spatial import cKDTree

        lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
        self.configs = rng.uniform(lower, upper, size=(int(samples), len(lower)))
        poses = np.array([robot.fk(q) for q in self.configs])
        self.positions, self.rotations = poses[:, :3, 3], poses[:, :3, :3]
        self.tree = cKDTree(self.positions)
        self.radius, self.cos_angle = float(radius), math.cos(math.radians(angle_deg))
        if hasattr(robot, "set_config"):
            robot.set_config(robot.q)

    def feasible(self, pose: Pose) -> bool:
        near = self.tree.query_ball_point(pose[:3, 3], self.radius)
        return bool(near) and bool(np.any(self.rotations[near][:, :, 2] @ pose[:3, 2] >= self.cos_angle))

    def seeds(self, pose: Pose, count: int = 6, metres_per_radian: float = 0.1) -> np.ndarray:
        """Configurations of the nearest samples by position error + ``metres_per_radian`` x rotation angle."""
        near = np.asarray(self.tree.query_ball_point(pose[:3, 3], self.radius), dtype=int)
        if len(near) == 0:
            return np.zeros((0, self.configs.shape[1]))
        cos = (np.einsum("nij,ij->n", self.rotations[near], pose[:3, :3]) - 1.0) / 2.0
        cost = np.linalg.norm(self.positions[near] - pose[:3, 3], axis=1) + metres_per_radian * np.arccos(
            np.clip(cos, -1.0, 1.0))
        return self.configs[near[np.argsort(cost)[:count]]]


@dataclass
class ScanMotion:
    """Plans (see the module docstring) and executes scans of one robot in one simulation.

    Parameters
    ----------
    robot : the robot plugin (attached to the simulation)
    pvs : the run's PVS (its ``is_free`` and ``probability`` are the planner's world model)
    planner : a ``motion_planner`` plugin object (``plan(problem, start, goal, seed)``)
    rng : random generator for IK restarts and the positioning noise
    plan_seed : first OMPL seed (each planning call uses the next one: deterministic runs)
    noise : execute with the robot's positioning noise model
    relocalise : a mobile base localises while it executes and steers back onto the plan
        (:func:`explore.motion.execute_following`, as a path-following controller would);
        False: open loop, whose heading errors add up over the whole approach (Vasquez-Gomez
        Sec. A6: decimetres after a few metres, which bumps the base into the table)
    leg_length : with ``relocalise``, a drive is re-aimed every this many metres
    drive_margin : with noise, a mobile base keeps this far from the known environment while it
        drives, away from the drive's ends (:class:`explore.motion.PlanarChecker`'s funnel; a leg
        of 0.25 m drifts centimetres sideways)
    step : length of a scan-path portion (thesis: 10 mm)
    min_scan_share : shortest acceptable part of a partly reachable scan path
    """

    robot: Any
    pvs: Any
    planner: Any
    rng: np.random.Generator
    plan_seed: int = 1
    noise: bool = True
    relocalise: bool = True
    leg_length: float = 0.25
    drive_margin: float = 0.1
    step: float = 0.01
    min_scan_share: float = 0.5
    plans: list[PlanRecord] = field(default_factory=list)
    motions: list[MotionRecord] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.free_space = BodyFreeSpace(self.pvs)  # the PVS, and where the robot has stood is free
        noisy_base = self.noise and bool(self.robot.base_dofs)
        self.problem = MotionProblem(self.robot, space_free=self.free_space.is_free,
                                     drive_margin=max(self.drive_margin, self.robot.drive_clearance) if noisy_base
                                     else None)
        self._calls = 0
        self._capability: CapabilityMap | None = None

    def capability(self) -> CapabilityMap | None:
        """The capability map of a fixed-base arm (built on first use); None for other robots."""
        robot = self.robot
        if robot.has(Capability.MOBILE_BASE) or not robot.has(Capability.ARM):
            return None
        if self._capability is None:
            self._capability = CapabilityMap(robot, np.random.default_rng(self.plan_seed))
        return self._capability

    def may_reach(self, target: Pose | ScanPath) -> bool:
        """Cheap pre-filter of candidates: a view pose, or either end of a scan path, may be reachable."""
        capability = self.capability()
        if capability is None:
            return True
        if isinstance(target, ScanPath):
            return capability.feasible(target.start) or capability.feasible(target.end)
        return capability.feasible(target)

    def _ik(self, pose: Pose) -> Array | None:
        """IK of one sensor pose: from the capability map's seeds, else the robot's own restarts."""
        capability = self.capability()
        if capability is None:
            return self.robot.ik(pose, self.rng)
        for seed in capability.seeds(pose):
            q = self.robot.ik(pose, self.rng, seed=seed)
            if q is not None:
                return q
        return None

    def _scan_ik(self, path: ScanPath) -> ScanPathIK:
        """IK along a scan path; a fixed-base arm starts from each capability seed in turn."""
        capability = self.capability()
        if capability is None:
            return linear_scan_path_ik(self.robot, path, self.step, self.rng)
        best = ScanPathIK(np.zeros((0, len(np.atleast_1d(self.robot.q)))), scan_path_poses(path, self.step), 0)
        for seed in capability.seeds(path.start):
            ik = linear_scan_path_ik(self.robot, path, self.step, self.rng, q_start=seed)
            if ik.reachable > best.reachable:
                best = ik
            if best.complete:
                break
        return best

    @property
    def planner_name(self) -> str:
        return str(getattr(self.planner, "name", type(self.planner).__name__))

    # -- planning -----------------------------------------------------------------------------
    def plan(self, candidate: Candidate, start: Array | None, scan_index: int = 1, use_pvs: bool = True) -> ScanPlan:
        """Scan reachability, the PVS along the scan (NBS rule), then the approach motion.

        ``start`` None places the robot at the scan start (no approach); ``use_pvs`` False
        checks the known environment only (the initial scan, see the module docstring).
        """
        t0 = time.perf_counter()
        problem = self.problem if use_pvs else MotionProblem(self.robot)
        start = None if start is None else np.asarray(start, dtype=float)
        result = self._plan(candidate, start, problem)
        result.planning_time = time.perf_counter() - t0
        self.plans.append(PlanRecord(scan_index, candidate.source, result.verdict, result.planning_time,
                                     self.planner_name))
        return result

    def _plan(self, candidate: Candidate, start: Array | None, problem: MotionProblem) -> ScanPlan:
        robot, target = self.robot, candidate.target
        if isinstance(target, ScanPath):
            reached = self._reachable_scan(target)
            if isinstance(reached, str):
                return ScanPlan(candidate, UNREACHABLE, reached)
            configs, target = reached
        else:
            q = self._ik(target)
            if q is None:
                return ScanPlan(candidate, UNREACHABLE, "view pose not reachable (IK)")
            configs = np.asarray(q, dtype=float)[None]
        if start is not None:
            shifted = self._near_heading(configs, start)
            if shifted is None:
                return ScanPlan(candidate, UNREACHABLE, "base heading outside the joint limits")
            configs = shifted
        if not all(problem.is_valid(q) for q in configs):
            verdict = (classify_blocked(robot, configs, self.pvs.probability, space_free=self.free_space.is_free,
                                        space_margin=problem.space_margin)
                       if problem.space_free is not None else None)
            if verdict == BLOCK_OCCUPIED:
                return ScanPlan(candidate, OCCUPIED, "the scan runs through occupied space", None, configs)
            if verdict == BLOCK_UNKNOWN:
                return ScanPlan(candidate, UNKNOWN, "the scan runs through unknown space", None, configs)
            return ScanPlan(candidate, UNREACHABLE, "the scan collides with the known environment", None, configs)
        plan = ScanPlan(candidate, OK, "placed at the scan start", None, configs,
                        target=None if target is candidate.target else target)
        if start is None:
            return plan
        self._calls += 1
        escape = None if problem.is_valid(start) else self._escape(start, problem)
        if escape is not None:
            start = escape.path[-1]
        approach = self.planner.plan(problem, start, configs[0], seed=self.plan_seed + self._calls)
        if approach is None:
            plan.verdict, plan.reason = NO_PATH, f"no collision-free motion to the scan start ({self.planner_name})"
            return plan
        if approach.controls is None and robot.base_dofs:
            approach = self._drivable(approach, problem)
            if approach is None:
                plan.verdict, plan.reason = NO_PATH, "the base cannot follow the path without a collision"
                return plan
        if escape is not None:
            approach = joined_plans(escape, approach, robot)
        plan.approach, plan.reason = approach, f"{approach.planner}: {approach.length:.3f}"
        return plan

    def _escape(self, start: Array, problem: MotionProblem) -> MotionPlan | None:
        """A small motion out of a start the planner calls invalid (:func:`explore.motion.escape_motion`)."""
        return escape_motion(self.robot, problem, start, np.random.default_rng(self.plan_seed + self._calls))

    def _drivable(self, approach: MotionPlan, problem: MotionProblem) -> MotionPlan | None:
        """The velocity controls a base executes for a geometric path (a differential drive turns,
        drives, turns) and their noise-free rollout, which must be valid in every control step
        (as :meth:`explore.nbv.nbvs.NBVSSession.plan`)."""
        robot = self.robot
        controls, nominal = robot.controls_from_path(approach.path)
        if len(controls) == 0:
            return approach
        if not path_is_valid(problem, nominal, resolution=np.inf, margin=None):
            return None
        return MotionPlan(nominal, controls=controls, dt=float(robot.dt), planner=approach.planner,
                          planning_time=approach.planning_time, length=path_length(robot, nominal))

    def _reachable_scan(self, path: ScanPath) -> tuple[np.ndarray, ScanPath] | str:
        """Configurations along the path (or along its longest reachable end part); a reason if none."""
        forward = self._scan_ik(path)
        if forward.complete:
            return forward.configs, path
        reverse_start = path.start.copy()
        reverse_start[:3, 3] = path.end[:3, 3]
        reverse = ScanPath(reverse_start, path.start, path.speed)
        backward = self._scan_ik(reverse)
        if backward.complete:
            return backward.configs, reverse
        best, along = (forward, path) if forward.reachable >= backward.reachable else (backward, reverse)
        portions = len(best.poses)
        if best.reachable < 2 or best.reachable < self.min_scan_share * portions:
            return f"scan path reachable for {best.reachable} of {portions} 10 mm portions"
        end = best.poses[best.reachable - 1]
        return best.configs, ScanPath(best.poses[0], end, along.speed)

    def _near_heading(self, configs: np.ndarray, start: Array) -> np.ndarray | None:
        """Shift a mobile base's heading by 2 pi k to the one closest to the start (within limits)."""
        base = list(self.robot.base_dofs)
        if not base:
            return configs
        th = base[2]
        shift = start[th] + wrap_angle(configs[0, th] - start[th]) - configs[0, th]
        out = configs.copy()
        for k in (0.0, 2 * math.pi, -2 * math.pi):
            out[:, th] = configs[:, th] + shift + k
            if np.all(out[:, th] >= self.robot.lower[th]) and np.all(out[:, th] <= self.robot.upper[th]):
                return out
        return None

    # -- execution ----------------------------------------------------------------------------
    def place(self, q: Array) -> None:
        """Put the robot at ``q`` without a motion (the free-flying sensor's first scan)."""
        q = np.asarray(q, dtype=float)
        self.robot.q = q.copy()
        if hasattr(self.robot, "set_config"):
            self.robot.set_config(q)

    def execute_approach(self, plan: ScanPlan, scan_index: int) -> Execution | None:
        """Execute the approach motion (noise, true-world collisions); None if there is none."""
        if plan.approach is None:
            assert plan.scan_configs is not None
            self.place(plan.scan_configs[0])
            return None
        return self._run(plan.approach, "approach", scan_index)

    def execute_scan(self, plan: ScanPlan, scan_index: int) -> tuple[Pose | ScanPath, Execution | None]:
        """Run the scan motion from the current configuration; the sensor target it realised.

        The nominal joint-space scan path is shifted to start at the (possibly noisy) current
        configuration. Without noise and collisions the candidate's own target is returned,
        so noise-free runs scan exactly the planned path.
        """
        assert plan.scan_configs is not None
        target = plan.scan_target
        robot = self.robot
        here = np.asarray(robot.q, dtype=float)
        at_start = bool(np.allclose(here, plan.scan_configs[0], atol=1e-9))
        if len(plan.scan_configs) == 1:
            return (target if at_start else robot.fk(here)), None
        path = plan.scan_configs - plan.scan_configs[0] + here
        run = self._run(path, "scan", scan_index)
        if at_start and not run.collided and np.allclose(run.final, path[-1], atol=1e-9):
            return target, run
        assert isinstance(target, ScanPath)
        start = robot.fk(run.configs[0])
        end = start.copy()
        end[:3, 3] = robot.fk(run.final)[:3, 3]
        return ScanPath(start, end, target.speed), run

    def _run(self, plan: MotionPlan | np.ndarray, kind: str, scan_index: int) -> Execution:
        robot = self.robot
        if self.relocalise and robot.base_dofs:
            run = execute_following(robot, plan, self.rng if self.noise else None, True, self.leg_length)
        else:
            run = robot.execute(plan, self.rng, noise=self.noise, world="true")
        self.free_space.stand(robot.link_points(run.final, within=(self.pvs.min_corner, self.pvs.max_corner)))
        positions = np.array([robot.fk(q)[:3, 3] for q in run.configs]) if len(run.configs) else np.zeros((0, 3))
        sensor_path = float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()) if len(positions) > 1 else 0.0
        config_length = float(sum(robot.distance(a, b) for a, b in zip(run.configs[:-1], run.configs[1:], strict=True)))
        bodies = tuple(sorted({b for event in run.collisions for b in event.bodies}))
        self.motions.append(MotionRecord(
            scan_index, kind, len(run.controls), float(run.times[-1]) if len(run.times) else 0.0, sensor_path,
            config_length, run.collided, bodies, run.completed,
        ))
        return run

    # -- metrics ------------------------------------------------------------------------------
    def metrics(self) -> dict[str, Any]:
        """Planning and execution numbers for ``metrics.json`` (see docs/metrics.md)."""
        attempts = len(self.plans)
        ok = sum(1 for p in self.plans if p.verdict == OK)
        verdicts = {v: sum(1 for p in self.plans if p.verdict == v) for v in (OK, UNREACHABLE, OCCUPIED, UNKNOWN,
                                                                             NO_PATH)}
        collided = [m for m in self.motions if m.collided]
        return {
            "planner": self.planner_name,
            "planning_attempts": attempts,
            "planning_success": ok / attempts if attempts else None,
            "planning_time_s": float(np.mean([p.seconds for p in self.plans])) if attempts else None,
            "planning_time_s_total": float(sum(p.seconds for p in self.plans)),
            "planning_verdicts": verdicts,
            "trajectories": len(self.motions),
            "collisions": len(collided),
            "collision_events": [{"scan": m.scan, "motion": m.kind, "bodies": list(m.bodies),
                                  "completed": m.completed} for m in collided],
            "motion_duration_s": float(sum(m.duration_s for m in self.motions)),
            "motion_config_length": float(sum(m.config_length for m in self.motions)),
        }


def make_planner(registry: Any, robot: Any, planner: Any, source: str = "--planner") -> Any:
    """A motion-planner plugin from a name, (name or None, params), an object, or None.

    A missing name means the robot's ``default_planner``.
    """
    params: dict = {}
    if isinstance(planner, tuple):
        planner, params = planner
    if planner is None:
        planner = registry.planner_for(robot)
    if isinstance(planner, str):
        return registry.create("motion_planner", planner, params or {}, source, "planner")
    return planner
