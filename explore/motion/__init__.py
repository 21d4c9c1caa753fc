"""Motion: robots, validity checking, OMPL planners, noisy execution and the planning clock.

* :class:`BulletCollider` checks robot parts against pybullet bodies (AABB pre-filter,
  ``getClosestPoints`` with a margin) and precomputed self-collision link pairs, in the style
  of pybullet-planning's ``get_collision_fn``.
* :class:`MotionProblem` is a robot plus a validity checker: robot vs the KNOWN static
  environment (``sim.environment_ids()``) and, optionally, a ``space_free(points) -> bool``
  callable (the PVS distance field: everything not confidently free, p >= 0.05, is an
  obstacle; Kriegel thesis Sec. 3.2.2) evaluated on points sampled on the robot's links.
* :func:`plan` wraps every OMPL geometric planner the installed bindings offer, by name, within
  its time limit (search, re-check and retry included); a differential base is checked as it
  drives (turn-drive-turn). :func:`plan_kinodynamic` (``ompl.control``, unicycle or
  omnidirectional model) and :func:`plan_mobile` (geometric base path) move a mobile robot:
  arm to its travel configuration, base, arm to the goal, with per-step velocity controls;
  :class:`PlanarChecker` tests base poses of the rigid robot fast; :func:`validate_path`
  re-checks a path densely.
* :func:`linear_scan_path_ik` validates a linear Cartesian scan path in 10 mm portions with
  IK and continuity (Kriegel thesis Sec. 2 motion planning); :func:`classify_blocked`
  applies the NBS rule (through occupied -> discard, through unknown -> keep for later).
* :class:`Execution` is what ``robot.execute(plan, rng)`` returns; :func:`truncated_normal`
  and :func:`truncated_normal_logpdf` implement the Vasquez-Gomez noise model (Sec. A6:
  noisy velocity controls truncated at beta = 3 sigma, Eq. 2 transition density).
"""

# The names other packages use (they import from the package, never from its modules).
from explore.motion.bullet_robot import BulletRobot
from explore.motion.collision import BulletCollider, Part, self_collision_pairs
from explore.motion.escape import escape_motion, joined_plans
from explore.motion.feedback import Rollouts, control_pieces, execute_following, follow_plan, plan_controls
from explore.motion.geometric import OPTIONAL_GEOMETRIC, geometric_planner_names, plan, planner_class, straight_line
from explore.motion.kernels import rigid_clearances, rigid_first_hit
from explore.motion.kinodynamic import control_planner_names, plan_kinodynamic
from explore.motion.mobile import PlanarChecker, box_distance, plan_mobile
from explore.motion.noise import truncated_normal, truncated_normal_logpdf
from explore.motion.planner import MotionPlanner
from explore.motion.planning_clock import COSTS, WALL_FACTOR, Budget, wall_guard_stops, work_clock
from explore.motion.problem import BodyFreeSpace, MotionProblem, path_is_valid, path_length, validate_path
from explore.motion.records import CollisionEvent, Execution, MotionPlan
from explore.motion.robot import Capability, Robot
from explore.motion.scan_paths import (
    BLOCK_OCCUPIED,
    BLOCK_UNKNOWN,
    ScanPathIK,
    classify_blocked,
    linear_scan_path_ik,
    scan_path_poses,
)

__all__ = [
    "BLOCK_OCCUPIED",
    "BLOCK_UNKNOWN",
    "Budget",
    "BodyFreeSpace",
    "BulletCollider",
    "BulletRobot",
    "COSTS",
    "Capability",
    "CollisionEvent",
    "Execution",
    "MotionPlan",
    "MotionPlanner",
    "MotionProblem",
    "OPTIONAL_GEOMETRIC",
    "Part",
    "PlanarChecker",
    "Robot",
    "Rollouts",
    "ScanPathIK",
    "WALL_FACTOR",
    "box_distance",
    "classify_blocked",
    "control_pieces",
    "control_planner_names",
    "escape_motion",
    "execute_following",
    "follow_plan",
    "geometric_planner_names",
    "joined_plans",
    "linear_scan_path_ik",
    "path_is_valid",
    "path_length",
    "plan",
    "plan_controls",
    "plan_kinodynamic",
    "plan_mobile",
    "planner_class",
    "rigid_clearances",
    "rigid_first_hit",
    "scan_path_poses",
    "self_collision_pairs",
    "straight_line",
    "truncated_normal",
    "truncated_normal_logpdf",
    "validate_path",
    "wall_guard_stops",
    "work_clock",
]
