"""Moving the robot to a view for scene exploration: IK, planning, noisy execution, odometry.

The scene session asks for a sensor target (a pose or, for line sensors, a scan path);
:class:`Mover` finds a configuration (the robot plugin's IK, for scan paths the 10 mm
portion IK of :func:`explore.motion.linear_scan_path_ik`), plans a collision-free motion with
a motion-planner plugin (known environment plus the scene PVS: nothing may enter space the
PVS has seen occupied), and executes it with the robot's positioning noise
(``Robot.execute``, Vasquez-Gomez Sec. A6). The free flyer is the thesis' sensor without a
robot: it moves in a straight line without noise.

The robot's *belief* about where its sensor is comes from odometry: the base advances by
the nominal (noise-free) motion of the executed controls, the arm joints are measured
exactly. With a noisy base the believed pose drifts from the true one. A base with a planar
localisation laser localises as it drives, as AMCL does on Görner's robot: after every leg
and at the end of a motion its laser scan is matched against the known environment
(:class:`~explore.perception.LikelihoodField`) within three sigma of the odometry's drift,
and the belief becomes the match. Scans are recorded at the believed pose; for a base without
such a laser the gtsam pose graph (:mod:`explore.perception.pose_graph`) corrects them. The true
pose is kept for the metrics only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, invert, pose_error, transform_points
from explore.motion import Capability, MotionPlan, MotionProblem, PlanarChecker, linear_scan_path_ik
from explore.perception import LikelihoodField, PlanarSurface
from explore.scene.scene_objects import ENVIRONMENT_MARGIN, FLOOR, environment_surface
from explore.sim import ScanPath

Target = Pose | ScanPath


@dataclass
class Move:
    """The outcome of one motion to a view.

    ``target`` is where the sensor really is (what the simulated sensor uses), ``believed``
    where the robot thinks its sensor is at the start of the target (odometry/kinematics);
    both are world_T_sensor (OpenCV frame).
    """

    target: Target
    believed: Pose
    travel_m: float
    planning_s: float
    collisions: int
    planner: str


STOP_SIGMAS = 2.0  # a noisy base stops this many sigma of its last leg's heading swing clear (Mover.stop_margin)


def _split_drive(robot: Any, plan: Any, length: float) -> tuple[Any, Any]:
    """(first leg, rest) of a plan at the base motion time of a straight ``length`` m drive;
    rest None when the plan moves its base for less than 1.5 legs (no short last leg).

    Legs are cut by time, not distance: the base's control noise errs at every step the base
    moves (Vasquez-Gomez Sec. A6), and a turn in place drifts the heading as a drive does.
    """
    if plan.controls is None:
        controls, path = robot.controls_from_path(plan.path)
        plan = MotionPlan(path, controls=controls, dt=float(robot.dt), planner=plan.planner)
    moved = np.cumsum(robot.noise_mask(plan.controls)[:, : robot.n_base_controls].any(axis=1))
    speed = float(robot.base_control_limits()[0])  # the straight drive speed (m/s)
    leg_steps = max(1, math.ceil(length / (speed * float(robot.dt))))
    if len(moved) == 0 or moved[-1] < 1.5 * leg_steps:
        return plan, None
    k = int(np.searchsorted(moved, leg_steps)) + 1
    first = MotionPlan(plan.path[: k + 1], controls=plan.controls[:k], dt=plan.dt, planner=plan.planner)
    rest = MotionPlan(plan.path[k:], controls=plan.controls[k:], dt=plan.dt, planner=plan.planner)
    return first, rest


def _driven(configs: np.ndarray, base_dofs: tuple[int, ...]) -> float:
    """Metres the base travels along ``configs`` (its x, y)."""
    xy = np.asarray(configs, dtype=float)[:, list(base_dofs[:2])]
    return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))


def target_start(target: Target) -> Pose:
    return target.start if isinstance(target, ScanPath) else np.asarray(target, dtype=float)


def _ending_at(path: ScanPath, position: Array) -> ScanPath:
    """``path`` from its start to ``position`` (the end of the part of it that can be scanned)."""
    end = path.end.copy()
    end[:3, 3] = position
    return ScanPath(path.start, end, path.speed)


def _planar(x: float, y: float, theta: float) -> Pose:
    out = np.eye(4)
    c, s = math.cos(theta), math.sin(theta)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:2, 3] = (x, y)
    return out


def _planar_params(pose: Pose) -> tuple[float, float, float]:
    return float(pose[0, 3]), float(pose[1, 3]), math.atan2(pose[1, 0], pose[0, 0])


class OccupiedClearance:
    """A fixed-base arm's free-space test in a scene (:meth:`Mover._problem`): a robot point is free
    unless a voxel with p >= ``occupied_from`` lies within the clearance plus half a voxel diagonal.

    Unknown space is passable (a scene's region is mostly unseen when the robot starts); occupied
    space is kept at the robot's ``space_margin`` (clearance plus the gaps between its surface
    points), as modelling and view/state planning keep it from non-free voxels: in
    ``random_workcell_45`` the arm planned to 4 mm from an object's occupied voxels and touched it
    between its points. Voxels of the known environment (within ``ENVIRONMENT_MARGIN`` and half a
    voxel diagonal of it) are left to the collision checker, which tests its meshes at the robot's
    clearance; kept here, the table's own voxels held the arm 4 cm above the table. Usable as
    ``space_free``: it takes a clearance and has the PVS's ``version``, so motions are cached."""

    def __init__(self, pvs: Any, occupied_from: float, environment: Any = None) -> None:
        self.pvs = pvs
        self.occupied_from = float(occupied_from)
        self.environment = environment
        self.half_diagonal = 0.5 * math.sqrt(3.0) * float(pvs.resolution)
        self._tree: Any = None
        self._tree_version: Any = None

    @property
    def version(self) -> Any:
        return self.pvs.version

    def is_free(self, points: Points3, clearance: float = 0.0) -> np.ndarray:
        """(n,) bool: no occupied voxel centre within ``clearance`` + half a voxel diagonal."""
        from scipy.spatial import cKDTree

        if self._tree_version != self.pvs.version:
            occupied = self.pvs.occupied_points(self.occupied_from)
            if self.environment is not None and len(occupied):
                nearest, _ = self.environment.closest(occupied)
                apart = np.linalg.norm(nearest - occupied, axis=1) > ENVIRONMENT_MARGIN + self.half_diagonal
                occupied = occupied[apart]
            self._tree = cKDTree(occupied) if len(occupied) else None
            self._tree_version = self.pvs.version
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if self._tree is None or not len(points):
            return np.ones(len(points), dtype=bool)
        reach = float(clearance) + self.half_diagonal
        distance, _ = self._tree.query(points, distance_upper_bound=reach)
        return distance > reach


class Mover:
    """Moves a simulation's robot to sensor targets and tracks its believed sensor pose.

    Parameters
    ----------
    sim : Simulation with robot and sensor attached
    registry : plugin registry (for the motion planner)
    planner : motion-planner plugin name; default ``tuck_and_drive`` for an arm on a base
        (a robot with ``travel_joints``: the base drives only with the arm tucked, so its
        odometry drifts only while it drives; RRT-Connect in the full 10-D space finds no
        path among furniture, benchmarks/planners.py), else ``rrt_connect`` (an arm; the mobile
        base's pan-tilt head); the free flyer moves in a straight line
    noise : execute with the robot's positioning noise
    occupied_from : PVS probability from which a voxel is an obstacle (a fixed-base arm keeps its
        ``space_margin`` from it, :class:`OccupiedClearance`; unknown space is passable)
    seed : seeds IK restarts and the execution noise
    planning_time : time limit of one motion plan (s on the planning clock,
        :mod:`explore.motion.planning_clock`); generous, so that the path simplification normally runs
        to completion (on the wall clock a limit hit under CPU load changes the path, the noise
        drawn along it and so the run)
    min_path_fraction : shortest reachable share of a scan path that is still scanned
    localise : a base with a planar laser localises its belief in the known environment after
        every leg (:meth:`localise`); False: odometry only
    refine_localisation : refine each correlative laser match by point-to-plane ICP on the known
        surfaces (:class:`~explore.perception.PlanarSurface`)
    min_obstacle_height : a driving robot's PVS test ignores voxels lower than this above the floor
        (``FLOOR``), as costmap_2d's ``min_obstacle_height`` does: a depth camera's noise at room
        range (Kinect sigma 1.7 cm at 3.5 m, with its per-frame bias) leaves occupied voxels 1-3 cm up
        the floor, which held the base of ``room40`` where it stood; the known floor itself is tested
        exactly by the collision checker
    """

    def __init__(self, sim: Any, registry: Any, planner: str | None = None, noise: bool = True,
                 occupied_from: float = 0.75, seed: int = 0, planning_time: float = 10.0,
                 min_path_fraction: float = 0.4, localise: bool = True, refine_localisation: bool = True,
                 min_obstacle_height: float = 0.05) -> None:
        self.sim = sim
        self.robot = sim.robot
        self.noise = bool(noise)
        self.occupied_from = float(occupied_from)
        self.min_path_fraction = float(min_path_fraction)
        self.min_obstacle_height = float(min_obstacle_height)
        self.rng = np.random.default_rng(seed)
        self.pvs: Any = None
        self.free_flyer = self.robot is None or self.robot.has(Capability.FREE_FLYER)
        self.planner = None
        if not self.free_flyer:
            planner = planner or registry.planner_for(self.robot)
            self.planner = registry.create("motion_planner", planner,
                                           {"time_limit": planning_time}, "<scene>")
        self.base_dofs: tuple[int, ...] = () if self.robot is None else tuple(self.robot.base_dofs)
        self.believed_q: Array | None = None if self.robot is None else np.asarray(self.robot.q, dtype=float).copy()
        self.travel_m = 0.0
        self.collisions = 0
        self.touched: set[str] = set()  # the bodies of the true world the robot has touched
        self.failed_moves = 0
        self._pose: Pose | None = None  # free flyer: current sensor pose
        self._last_path: np.ndarray | None = None  # configurations of the last execution
        self._odometry_var = np.zeros(2)  # (translation m^2, rotation rad^2) since the last view
        self._drift_var = np.zeros(2)  # the same since the belief was last localised
        self._laser_rng = np.random.default_rng([seed, 1])
        self._stop_margin: float | None = None
        self._occupied: OccupiedClearance | None = None  # the PVS's occupied voxels, for planning
        self._field: Any = None  # likelihood field of the known environment, built on first use
        self._surface: Any = None  # its surface samples and normals (a PlanarSurface), with the field
        self.localisations = 0
        self.localising = bool(localise)
        self.refine_localisation = bool(refine_localisation)

    # -- queries ---------------------------------------------------------------------------
    @property
    def localises(self) -> bool:
        """The belief is localised in the known environment as the base drives (:meth:`localise`)."""
        return bool(self.localising and self.base_dofs and self.noise and self.robot.has(Capability.PLANAR_LASER))

    @property
    def true_pose(self) -> Pose | None:
        """The sensor's true world pose (metrics only)."""
        if self.free_flyer:
            return self._pose
        return self.robot.fk(self.robot.q)

    def believed_pose(self) -> Pose | None:
        """The sensor pose the robot believes it has."""
        if self.free_flyer:
            return self._pose
        pose = self.robot.fk(self.believed_q)
        self.robot.set_config(self.robot.q)  # fk may move the bodies
        return pose

    def plausible(self, eye: Array, focus: Array) -> bool:
        """Cheap pre-filter before IK: a fixed-base arm only sees objects from its own side
        (its eye is not farther from the base than the object); anything else passes."""
        base = None if self.robot is None else self.robot.base_pose
        if self.free_flyer or self.base_dofs or base is None:
            return True
        here = np.asarray(base)[:2, 3]
        return float(np.linalg.norm(eye[:2] - here)) <= float(np.linalg.norm(focus[:2] - here)) + 0.05

    def reach(self, target: Target) -> tuple[Target, list] | None:
        """(target, configurations) realising ``target``, or None if unreachable.

        A view needs one IK solution. A scan path needs IK for every 2 cm portion with
        continuity (:func:`explore.motion.linear_scan_path_ik`); if only a leading part of at
        least ``min_path_fraction`` is reachable, the path is shortened to that part.
        """
        if self.free_flyer:
            return target, []
        robot = self.robot
        if isinstance(target, ScanPath):
            ik = linear_scan_path_ik(robot, target, step=0.02, rng=self.rng)
            if ik.reachable < 2 or ik.fraction < self.min_path_fraction:
                return None
            if not ik.complete:
                target = _ending_at(target, ik.poses[ik.reachable - 1][:3, 3])
            return target, list(ik.configs)
        q = robot.ik(np.asarray(target, dtype=float), self.rng)
        if q is None or not self._room_to_stop(q):
            return None
        return target, [q]

    def laser_points(self, frame: Pose, rng: np.random.Generator, beams: int = 720) -> Points3 | None:
        """A planar 360-degree scan of the base's localisation laser (robot parameter
        ``laser_height`` > 0) at the base's true pose, in ``frame`` (the true sensor pose the
        view's scan is recorded at: the arm joints are measured, so the robot knows where its
        laser is relative to its camera); None without a laser. Görner's robot localises
        with such a scanner (AMCL)."""
        if not self.base_dofs or not self.robot.has(Capability.PLANAR_LASER):
            return None
        ix, iy, ith = self.base_dofs
        q = np.asarray(self.robot.q, dtype=float)
        angles = q[ith] + np.linspace(0.0, 2.0 * math.pi, beams, endpoint=False)
        directions = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(beams)])
        origins = np.tile([q[ix], q[iy], float(self.robot.laser_height)], (beams, 1))
        distance, _, _ = self.sim.raycaster.cast(origins, directions)
        hit = np.isfinite(distance) & (distance <= float(self.robot.laser_range))
        measured = distance[hit] + rng.normal(0.0, float(self.robot.laser_sigma), int(hit.sum()))
        world = origins[hit] + directions[hit] * measured[:, None]
        return (world - frame[:3, 3]) @ frame[:3, :3]

    # -- motion ----------------------------------------------------------------------------
    def _problem(self) -> Any:
        pvs, limit = self.pvs, self.occupied_from
        if pvs is None:
            return MotionProblem(self.robot)
        bounds = (pvs.min_corner, pvs.max_corner)  # outside its grid nothing is occupied
        if self.base_dofs:
            # a driving robot: each of its points only outside occupied voxels. At room scale the PVS
            # holds stray occupied voxels from depth noise of centimetres at 3 m, and keeping the
            # margin from them cost room40 (seed 0) 18 of its 42 views and two known objects' accuracy
            normal, offset, low = np.asarray(FLOOR[:3]), FLOOR[3], self.min_obstacle_height

            def space_free(points: Points3) -> np.ndarray:
                return pvs.probability_below(points, limit) | (points @ normal + offset < low)

            return MotionProblem(self.robot, space_free=space_free, space_bounds=bounds)
        if self._occupied is None or self._occupied.pvs is not pvs:
            self._occupied = OccupiedClearance(pvs, limit, self.sim.environment_caster())
        return MotionProblem(self.robot, space_free=self._occupied.is_free, space_bounds=bounds)

    def move(self, target: Target, configs: list | None = None) -> Move | None:
        """Go to ``target`` (IK unless ``configs`` from :meth:`reach` is given); None if impossible."""
        if self.free_flyer:
            return self._fly(target)
        if configs is None:
            reached = self.reach(target)
            if reached is None:
                self.failed_moves += 1
                return None
            target, configs = reached
        sweep = np.atleast_2d(np.asarray(configs, dtype=float))
        robot = self.robot
        problem = self._problem()
        if isinstance(target, ScanPath) and len(sweep) > 1:
            shortened = self._valid_sweep(problem, target, sweep)
            if shortened is None:
                self.failed_moves += 1
                return None
            target, sweep = shortened
        self._recover(problem)
        start = np.asarray(robot.q, dtype=float).copy()
        t0 = time.perf_counter()
        plan = self.planner.plan(problem, start, sweep[0], seed=int(self.rng.integers(2**31)))
        planning_s = time.perf_counter() - t0
        if plan is None:
            self.failed_moves += 1
            return None
        start_pose = robot.fk(start)
        before = self.collisions
        self._drive(problem, plan)
        true_start = robot.fk(robot.q)
        travel = float(np.linalg.norm(true_start[:3, 3] - start_pose[:3, 3]))
        self.travel_m += travel
        if self.collisions > before and isinstance(target, ScanPath):  # stopped short of the scan's start: no sweep
            self.failed_moves += 1
            return None
        believed = self.believed_pose()
        true_target: Target = true_start
        if isinstance(target, ScanPath) and len(sweep) > 1:
            path = np.vstack([robot.q, sweep[1:] - sweep[0] + robot.q])
            self._execute(path)
            true_end = robot.fk(robot.q)
            end = true_start.copy()
            end[:3, 3] = true_end[:3, 3]
            true_target = ScanPath(true_start, end, target.speed)
        return Move(true_target, believed, travel, planning_s, self.collisions - before, getattr(plan, "planner", ""))

    @property
    def stop_margin(self) -> float:
        """How much farther than its clearance a noisy base that drives in legs keeps its goal from
        the known environment (:meth:`reach`): ``STOP_SIGMAS`` sigma of how far the heading error
        of a last leg (at most 1.5 legs, :func:`_split_drive`) swings the robot's outermost point
        about its base. The heading errs sigma_omega dt at each of the leg's n steps (Vasquez-Gomez
        Sec. A6), sigma_omega dt sqrt(n) at its end. The scene patrols' contacts came in the last
        steps of a last leg, at goals 1-2 cm from a table. 0 without noise or legs (an open-loop
        base's error has no such bound)."""
        if self._stop_margin is None:
            self._stop_margin = 0.0
            leg = float(self.robot.replan_distance) if self.base_dofs else 0.0
            if self.noise and leg > 0.0:
                robot = self.robot
                speed = float(robot.base_control_limits()[0])
                steps = 1.5 * math.ceil(leg / (speed * float(robot.dt)))
                heading = float(robot.control_sigma()[robot.n_base_controls - 1]) * float(robot.dt) * math.sqrt(steps)
                ix, iy, _ = self.base_dofs
                q = np.asarray(robot.q, dtype=float)
                points = robot.link_points(q)
                radius = float(np.hypot(points[:, 0] - q[ix], points[:, 1] - q[iy]).max(initial=0.0))
                self._stop_margin = STOP_SIGMAS * heading * radius
        return self._stop_margin

    def _room_to_stop(self, goal: Array) -> bool:
        """The base at ``goal`` keeps its clearance plus :attr:`stop_margin` from the known
        environment's bodies beside it (:class:`~explore.motion.PlanarChecker`; not the floor)."""
        if self.stop_margin <= 0.0:
            return True
        problem = self._problem()
        checker = PlanarChecker(problem, goal, drive_margin=problem.margin + self.stop_margin)
        return checker(np.asarray(goal, dtype=float)[list(self.base_dofs)])

    def _valid_sweep(self, problem: Any, target: ScanPath, sweep: Array) -> tuple[ScanPath, Array] | None:
        """The scan's configurations up to the first one the motion problem refuses (the PVS's
        occupied space, the known environment), with the path shortened to match; None if that
        leaves less than ``min_path_fraction`` of it. The approach is planned in the same problem;
        the sweep itself was not checked, and an arm swept its camera through a modelled object
        (benchmarks/random_scenes.py --like workcell, scene 45)."""
        valid = [bool(problem.is_valid(q)) for q in sweep]
        if all(valid):
            return target, sweep
        keep = valid.index(False)
        if keep < 2 or keep < self.min_path_fraction * len(sweep):
            return None
        last = self.robot.fk(sweep[keep - 1])[:3, 3]
        self.robot.set_config(self.robot.q)  # fk may move the bodies
        return _ending_at(target, last), sweep[:keep]

    def _drive(self, problem: Any, plan: Any) -> None:
        """Execute ``plan`` with noise (a contact ends the drive).

        With the robot parameter ``replan_distance`` > 0 (a base that localises while it
        drives, as a path-following controller would) the plan is executed in legs of that
        much base travel; after each leg a short plan takes the robot back to where the leg
        should have ended, and the next leg starts from there. Open loop, a drive of several
        metres with sigma_omega = 0.28 rad/s ends decimetres off its path (Vasquez-Gomez
        Sec. A6). A correction that cannot be planned is skipped (the leg goes on open loop).
        """
        leg_length = float(self.robot.replan_distance)
        while True:
            leg, rest = (plan, None) if leg_length <= 0.0 or not self.base_dofs else \
                _split_drive(self.robot, plan, leg_length)
            execution = self._execute(leg)
            self.localise()
            if execution.collided or rest is None:
                return
            correction = self._correction(problem, rest.path[0])
            if correction is not None and self._execute(correction).collided:
                return
            plan = rest

    def _execute(self, plan: Any) -> Any:
        """Execute a plan or path with noise against the true world; contacts, odometry and bumper stop."""
        start = np.asarray(self.robot.q, dtype=float).copy()
        execution = self.robot.execute(plan, self.rng, noise=self.noise, world="true")
        self.collisions += len(execution.collisions)
        self.touched.update(body for event in execution.collisions for body in event.bodies)
        self._odometry(start, execution)
        self._back_off(execution)
        return execution

    def localise(self, min_score: float = 0.3) -> bool:
        """Match the base laser's scan against the known environment near the believed base pose
        and take the match as the belief (AMCL-like); True if the scan matched.

        The search window is three sigma of the drift since the last localisation (at least
        5 cm / 1 deg, at most 0.5 m / 15 deg): a leg of a metre drifts centimetres, so the
        window stays narrow and a symmetric room cannot pull the belief to its mirror image; an
        answer beyond the window's border (a rarer, larger error: 18.5 deg after a leg whose
        sigma was 5.6 deg) moves the window on, up to twice.
        A match scoring below ``min_score`` (mean likelihood of the beams) leaves the belief
        to odometry.
        """
        if not self.localises or self.believed_q is None:
            return False
        ix, iy, ith = self.base_dofs
        q = np.asarray(self.robot.q, dtype=float)
        local = self.laser_points(_planar(q[ix], q[iy], q[ith]), self._laser_rng)
        if local is None or len(local) < 20:
            return False
        if self._field is None:
            points, normals = environment_surface(self.sim)
            self._field, self._surface = LikelihoodField(points), PlanarSurface(points, normals)
        believed = _planar(*self.believed_q[[ix, iy, ith]])
        trans, rot = np.sqrt(self._drift_var)
        search = (float(np.clip(3.0 * trans, 0.05, 0.5)), float(np.clip(3.0 * rot, math.radians(1.0),
                                                                          math.radians(15.0))))
        correction, score = self._field.match(transform_points(believed, local), believed[:2, 3], *search, recentre=2)
        if score < min_score:
            return False
        matched = correction @ believed
        if self.refine_localisation:  # the correlative match is a 1 cm grid answer: refine it on the surfaces
            refined = self._surface.refine(transform_points(matched, local), matched[:2, 3])
            if refined is not None:
                moved, turned = pose_error(refined[0] @ matched, matched)
                if moved <= 0.03 and turned <= math.radians(1.0):  # within the correlative match's cell
                    matched = refined[0] @ matched
        self.believed_q[[ix, iy, ith]] = _planar_params(matched)
        self._drift_var = np.zeros(2)
        self.localisations += 1
        return True

    def _correction(self, problem: Any, nominal: Array) -> Any:
        """A plan from the robot's configuration to ``nominal`` (None: none needed or found).

        A correction is a short manoeuvre back onto the path: a plan whose base drives further
        than a leg (a sampling planner's detour around the table to undo 3 cm, executed open
        loop with the heading noise of a full turn) is not one, and the drive goes on without it.
        """
        here = np.asarray(self.robot.q, dtype=float).copy()
        base = list(self.base_dofs)
        if np.linalg.norm(here[base] - np.asarray(nominal)[base]) < 0.01:
            return None
        plan = self.planner.plan(problem, here, np.asarray(nominal, dtype=float), seed=int(self.rng.integers(2**31)))
        if plan is None:
            return None
        return plan if _driven(plan.path, self.base_dofs) <= float(self.robot.replan_distance) else None

    def _fly(self, target: Target) -> Move:
        start = target_start(target)
        travel = 0.0 if self._pose is None else float(np.linalg.norm(start[:3, 3] - self._pose[:3, 3]))
        end = target.end if isinstance(target, ScanPath) else start
        self._pose = np.asarray(end, dtype=float).copy()
        if self.robot is not None:
            q = self.robot.ik(self._pose)
            if q is not None:
                self.robot.q = q
        self.travel_m += travel
        return Move(target, start.copy(), travel, 0.0, 0, "straight_line")

    def _recover(self, problem: Any, attempts: int = 3) -> None:
        """If noise left the robot closer to an obstacle than its planning clearance (planning
        would refuse to start), move to a nearby configuration that is valid again: back along
        the last motion, else (a base) straight back or forward along its heading. Each try
        is executed with noise, so it is repeated while the robot is still too close."""
        for _ in range(attempts):
            if problem.is_valid(self.robot.q):
                return
            goal = self._escape(problem)
            if goal is None:
                return
            self._execute(np.vstack([self.robot.q, goal]))

    def _escape(self, problem: Any) -> Array | None:
        """The latest valid configuration of the last motion, else (a base) the nearest base
        shift (2-20 cm) that is valid, with twice the clearance if it can: straight back or
        forward along the heading first, then sideways and diagonally (a base driving along a
        table's edge cannot leave its clearance along its heading)."""
        for candidate in [] if self._last_path is None else self._last_path[::-1]:
            if problem.is_valid(candidate):
                return candidate
        if not self.base_dofs:
            return None
        q = np.asarray(self.robot.q, dtype=float)
        ix, iy, ith = self.base_dofs
        shifts = []
        for turn in (0.0, 0.5 * math.pi, 0.25 * math.pi, 0.75 * math.pi):
            axis = np.array([math.cos(q[ith] + turn), math.sin(q[ith] + turn)])
            for step in (0.02, 0.05, 0.1, 0.2):
                for sign in (-1.0, 1.0):
                    shifted = q.copy()
                    shifted[[ix, iy]] += sign * step * axis
                    shifts.append(shifted)
        for margin in (2.0 * problem.margin, problem.margin):
            for candidate in shifts:
                if problem.is_valid(candidate, margin=margin):
                    return candidate
        return None

    def _accumulate(self, execution: Any) -> None:
        """Grow the odometry variance by a motion's control noise (the robot plugin's sigmas):
        per step (sigma dt)^2 in speed and turn rate; the heading error also moves the base
        sideways over the distance driven."""
        if not self.base_dofs or not self.noise or len(execution.controls) == 0:
            return
        dt = float(self.robot.dt)
        steps = len(execution.controls)
        sigma = np.asarray(execution.sigma, dtype=float)
        rot_var = float((sigma[self.robot.n_base_controls - 1] * dt) ** 2 * steps)
        trans_var = float((sigma[0] * dt) ** 2 * steps)
        driven = _driven(execution.configs, self.base_dofs)
        for var in (self._odometry_var, self._drift_var):
            var += [trans_var + driven**2 * (var[1] + rot_var), rot_var]

    def odometry_sigmas(self) -> Array | None:
        """Sigmas (gtsam Pose3 order: rotation, translation) of the motion since the last call; resets."""
        if not self.base_dofs or not self.noise:
            return None
        trans, rot = np.sqrt(np.maximum(self._odometry_var, 1e-12))
        self._odometry_var = np.zeros(2)
        return np.array([rot] * 3 + [trans] * 3)

    def _back_off(self, execution: Any) -> None:
        """After a contact the robot stops at its last configuration before it (a bumper stop),
        so that it can plan its way out; the belief moves back with it."""
        if not execution.collided or len(execution.configs) < 2:
            return
        last = np.asarray(execution.configs[-2], dtype=float)
        step = last - np.asarray(execution.configs[-1], dtype=float)
        self.robot.q = last
        self.robot.set_config(last)
        if self.believed_q is not None:
            self.believed_q = self.believed_q + step

    def _odometry(self, start: Array, execution: Any) -> None:
        """Advance the believed configuration by the nominal motion of the executed controls."""
        self._last_path = np.asarray(execution.configs, dtype=float)
        self._accumulate(execution)
        final = np.asarray(execution.final, dtype=float)
        believed = final.copy()
        if self.base_dofs and self.believed_q is not None:
            nominal, _, _ = self.robot.rollout(start, execution.controls, None, noise=False)
            ix, iy, ith = self.base_dofs
            step = invert(_planar(start[ix], start[iy], start[ith])) @ _planar(*nominal[-1][[ix, iy, ith]])
            moved = _planar(*self.believed_q[[ix, iy, ith]]) @ step
            believed[[ix, iy, ith]] = _planar_params(moved)
        self.believed_q = believed
