"""The robot contract: configurations, kinematics, collision and execution, and what the robot can do.

A robot turns goal sensor poses into configurations (IK) and configurations into sensor poses
(FK), checks configurations for collisions and executes motions in the simulation, with its
own positioning noise. What it *can* do is declared in :attr:`Robot.capabilities`; the library
asks for capabilities (``robot.has(Capability.MOBILE_BASE)``), never for plugin names.
:class:`~explore.motion.bullet_robot.BulletRobot` implements everything but the kinematics
for robots built from pybullet bodies.

Units: metres and radians; poses are 4x4 homogeneous matrices, world_T_sensor with the sensor
frame of OpenCV (z along the optical axis, y down the image).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from enum import StrEnum
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from explore.core import Array, Plugin, Points3, Pose

if TYPE_CHECKING:
    from explore.motion.records import Execution, MotionPlan
    from explore.sim import Simulation


class Capability(StrEnum):
    """What a robot can do; the library's choices follow these, never a robot's name."""

    #: the sensor itself, placed at any pose: the first scan needs no motion, scene
    #: exploration moves it without planning (Kriegel's free-flying sensor)
    FREE_FLYER = "free_flyer"
    #: a manipulator whose reach is mapped (capability map) when its base is fixed
    ARM = "arm"
    #: a base that drives (``base_dofs`` = x, y, theta indices; ``drive``, ``propagate_base``,
    #: ``base_control_limits``, ``n_base_controls``, ``base_to_full_controls``)
    MOBILE_BASE = "mobile_base"
    #: an arm that tucks into :meth:`Robot.travel_joints` before the base drives
    TRAVEL_POSE = "travel_pose"
    #: execution errs: :meth:`Robot.control_sigma`, :meth:`Robot.noise_mask`, ``truncation``
    #: (Vasquez-Gomez Sec. A6: truncated Gaussian velocity errors)
    POSITIONING_NOISE = "positioning_noise"
    #: a planar 360-degree localisation laser at ``laser_height`` (``laser_range``, ``laser_sigma``)
    PLANAR_LASER = "planar_laser"


class Robot(Plugin, ABC):
    """Contract of kind ``robot``.

    Attributes
    ----------
    dof : configuration size; ``q`` (dof,) is the current (true) configuration
    lower, upper : (dof,) joint limits (m or rad; +-inf for unbounded)
    capabilities : the :class:`Capability` set this robot declares
    default_planner : the motion planner plugin its moves use when a run names none ("": the
        registry's default motion planner)
    base_dofs : indices (x, y, theta) of a mobile base in ``q``; empty without one
    base_pose : world_T_base of a fixed base (None when the base moves or there is none)
    dt : seconds each velocity control is held during execution
    clearance : distance (m) planning keeps from known obstacles and non-free voxels (the
        PVS test of the link points keeps :attr:`space_margin`, which adds :attr:`sample_gap`)
    drive_clearance : extra margin (m) kept while a base drives
    camera_height : height (m) of a camera fixed on the base (views are planned at it), or None
    laser_height : height (m) of the planar localisation laser (0: none)
    replan_distance : scene exploration drives in legs of this length (m), 0 = in one go; a noisy
        base with legs stops clear of the known environment by its last leg's heading swing
    truncation : positioning noise is truncated at ``truncation`` x sigma
    sim : the :class:`~explore.sim.simulation.Simulation` after :meth:`attach`
    """

    kind = "robot"
    dof: int = 0
    capabilities: frozenset[Capability] = frozenset()
    default_planner: ClassVar[str] = ""
    base_dofs: tuple[int, ...] = ()
    base_pose: Pose | None = None
    dt: float = 0.05
    clearance: float = 0.0
    drive_clearance: float = 0.0
    camera_height: float | None = None
    laser_height: float = 0.0
    replan_distance: float = 0.0
    truncation: float = 3.0

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.sim: Simulation | None = None
        self.q: Array = np.zeros(self.dof)
        self.lower: Array = np.full(self.dof, -np.inf)
        self.upper: Array = np.full(self.dof, np.inf)

    def has(self, capability: Capability) -> bool:
        """Whether the robot declares ``capability``."""
        return capability in self.capabilities

    def attach(self, sim: Simulation) -> None:
        """Add the robot to the simulation (load bodies, read limits, set ``q`` to its start)."""
        self.sim = sim

    @property
    def sample_gap(self) -> float:
        """Largest distance (m) from any point of the robot surface to the nearest of its
        :meth:`link_points` (0: the points are the whole surface)."""
        return 0.0

    @property
    def space_margin(self) -> float:
        """Margin (m) each link point keeps from non-free voxels of the PVS, :attr:`clearance` +
        :attr:`sample_gap`: the surface between the points then keeps the clearance too."""
        return float(self.clearance) + float(self.sample_gap)

    # -- kinematics ----------------------------------------------------------------------------
    @abstractmethod
    def fk(self, q: Array) -> Pose:
        """world_T_sensor (4x4) for configuration ``q`` (dof,)."""

    @abstractmethod
    def ik(self, world_T_sensor: Pose, rng: np.random.Generator | None = None) -> Array | None:
        """A collision-free configuration (dof,) that puts the sensor at ``world_T_sensor``, or None."""

    @property
    def sensor_pose(self) -> Pose:
        return self.fk(self.q)

    def distance(self, a: Array, b: Array) -> float:
        """Configuration distance (Vasquez-Gomez Eq. 8 with unit weights): Euclidean by default."""
        return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))

    def within_limits(self, q: Array) -> bool:
        q = np.asarray(q)
        return bool(np.all(q >= self.lower - 1e-9) and np.all(q <= self.upper + 1e-9))

    def sample_config(self, rng: np.random.Generator) -> Array:
        """A uniform configuration within the limits (not checked for collisions)."""
        return rng.uniform(self.lower, self.upper)

    @property
    def travel_joints(self) -> Array | None:
        """The configuration of ``q`` while the base drives (TRAVEL_POSE), None without one."""
        return None

    @property
    def joint_dofs(self) -> list[int]:
        """Indices of ``q`` that are not the base's."""
        return [i for i in range(self.dof) if i not in self.base_dofs]

    # -- the simulation ------------------------------------------------------------------------
    @abstractmethod
    def set_config(self, q: Array) -> None:
        """Put the robot's bodies in the simulation at ``q`` (for collision checks and rendering)."""

    @abstractmethod
    def in_collision(self, q: Array, world: str = "known", margin: float | None = None) -> bool:
        """Whether ``q`` collides with itself or the ``world`` ("known": the environment the
        planner may know; "true": everything, objects included) within ``margin`` m
        (None: :attr:`clearance`)."""

    @abstractmethod
    def link_points(self, q: Array, within: tuple[Array, Array] | None = None, pad: float = 0.05,
                    spacing: float | None = None) -> Points3:
        """(n, 3) world points on the robot's surface at ``q``, only of the parts whose box
        overlaps ``within`` (lo, hi) grown by ``pad``; the PVS free-space test uses them."""

    # -- execution -----------------------------------------------------------------------------
    def execution_path(self, path: np.ndarray) -> np.ndarray:
        """The piecewise-linear path (m, dof) that :meth:`controls_from_path` follows; ``path`` by
        default (a differential base turns, drives and turns instead)."""
        return np.asarray(path, dtype=float)

    @abstractmethod
    def controls_from_path(self, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nominal velocity controls (k, nc) held ``dt`` s each that follow ``path`` (m, dof),
        and the nominal configurations (k + 1, dof)."""

    @abstractmethod
    def execute(self, plan: MotionPlan | np.ndarray, rng: np.random.Generator | None = None, noise: bool = True,
                world: str = "true") -> Execution:
        """Execute a plan (with its controls, or a path turned into controls) in the simulation,
        with positioning noise when ``noise``; collisions against ``world`` are recorded. Sets ``q``."""

    def control_sigma(self) -> Array:
        """(nc,) standard deviation of each control's error (zeros: no POSITIONING_NOISE)."""
        nc = len(self.joint_dofs)
        return np.zeros(nc)

    def noise_mask(self, controls: np.ndarray) -> np.ndarray:
        """(k, nc) True where a control error is sampled (all controls by default)."""
        controls = np.asarray(controls, dtype=float)
        return np.ones(controls.shape, dtype=bool)
