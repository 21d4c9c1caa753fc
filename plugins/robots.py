"""Robot plugins: the free flyer and the fixed arm (pybullet bodies); the robots on a planar base
are in :mod:`explore_plugins.mobile_robots`, the pieces they share in :mod:`explore_plugins.robot_parts`.

Every robot exposes FK to the sensor pose (OpenCV frame), IK with restarts, joint limits
(``lower``/``upper``), collision geometry (pybullet bodies without visual shapes, plus
points sampled on the links for the PVS), the weighted configuration distance of
Vasquez-Gomez Eq. 8, and ``execute(plan, rng, noise=True)``: velocity controls with
truncated Gaussian noise (Vasquez-Gomez Sec. A6: sigma_v = 1.65 mm/s, sigma_omega =
0.28 rad/s, beta = 3 sigma; arm joints optional; only on the controls of parts commanded to
move, see ``noise_mask``), Euler-integrated every ``dt``, each executed
configuration checked against the TRUE world (environment + objects). Robot bodies are not
part of the ground truth the sensors cast rays against (``sim.raycaster``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation

from explore.core import Array, Param, Pose, pose_error
from explore.motion import (
    BulletCollider,
    BulletRobot,
    Capability,
    Part,
    self_collision_pairs,
)
from explore.sim import p, sphere_mesh

from .robot_parts import (
    COMMON_PARAMS,
    IK_ANGLE_TOL,
    IK_POSITION_TOL,
    SENSOR_PARAMS,
    ArmChain,
    planar_pose,
    pose6,
)

if TYPE_CHECKING:
    from explore.sim import Simulation


class FreeFlyer(BulletRobot):
    """The sensor itself, flying freely (unlimited workspace, as in the thesis benchmark)."""

    name = "free_flyer"
    dof = 6
    capabilities = frozenset({Capability.FREE_FLYER, Capability.POSITIONING_NOISE})
    params = (
        Param("radius", float, 0.03, "m", "collision sphere around the sensor", low=0.0),
        Param("speed", float, 0.1, "m/s", "nominal translation speed for execution", low=1e-4),
        Param("sigma_position", float, 0.0, "m/s", "noise sigma of the translational velocity", low=0.0),
        Param("sigma_rotation", float, 0.0, "rad/s", "noise sigma of the rotational velocity", low=0.0),
        Param(
            "weights", list, [1.0, 1.0, 1.0, 0.1, 0.1, 0.1], "", "Eq. 8 weights (position, rotation vector)", length=6
        ),
        Param("clearance", float, 0.0, "m", "planning margin to the known environment", low=0.0),
        Param("dt", float, 0.05, "s", "control period of execution", low=1e-3),
        Param("truncation", float, 3.0, "", "noise truncated at beta = truncation * sigma", low=0.1),
        Param(
            "on_collision",
            str,
            "continue",
            "",
            "a collision during execution ends the motion or not",
            choices=("stop", "continue"),
        ),
    )
    joint_speed = 0.5
    joint_sigma = 0.0
    point_spacing = 0.03

    def __init__(self, **values: Any) -> None:
        defaults = {param.name: param.default for param in FreeFlyer.params}
        super().__init__(**{**defaults, **values})
        self.pose: Pose = np.eye(4)
        self.lower = np.array([-1e3] * 3 + [-math.pi] * 3)
        self.upper = np.array([1e3] * 3 + [math.pi] * 3)

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        lo, hi = sim.spec.region_min - 2.0, sim.spec.region_max + 2.0
        self.lower[:3], self.upper[:3] = lo, hi
        if self.radius > 0:
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=self.radius, physicsClientId=sim.client)
            self.body = p.createMultiBody(0.0, shape, -1, [0, 0, -100], physicsClientId=sim.client)
            part = Part(self.body, -1, "sensor")
            self.parts = [part]
            self.collider = BulletCollider(sim.client, self.parts)
            self._part_meshes = {part: [sphere_mesh(self.radius)]}
            self._sample_part_points()

    def _set_state(self, q: Array) -> None:
        if self.collider is not None:
            p.resetBasePositionAndOrientation(
                self.body, np.asarray(q[:3]).tolist(), [0, 0, 0, 1], physicsClientId=self.client
            )

    def _speeds(self) -> Array:
        return np.array([self.speed] * 3 + [self.joint_speed] * 3)

    def control_sigma(self) -> Array:
        return np.array([self.sigma_position] * 3 + [self.sigma_rotation] * 3)

    def noise_groups(self) -> list[list[int]]:
        """The translational and the rotational velocity err as vectors."""
        return [[0, 1, 2], [3, 4, 5]]

    def fk(self, q: Array) -> Pose:
        pose = np.eye(4)
        pose[:3, 3] = q[:3]
        pose[:3, :3] = Rotation.from_rotvec(q[3:6]).as_matrix()
        return pose

    def ik(
        self,
        world_T_sensor: Pose,
        rng: np.random.Generator | None = None,
        seed: Array | None = None,
        check_collision: bool = False,
    ) -> Array | None:
        q = np.concatenate([world_T_sensor[:3, 3], Rotation.from_matrix(world_T_sensor[:3, :3]).as_rotvec()])
        if check_collision and self.in_collision(q):
            return None
        return q


class Arm(BulletRobot):
    """Fixed industrial arm (KUKA iiwa, 7 DOF) with an eye-in-hand sensor; IK with restarts."""

    name = "arm"
    dof = 7
    capabilities = frozenset({Capability.ARM, Capability.POSITIONING_NOISE})
    params = (
        Param("urdf", str, "kuka_iiwa/model.urdf", "", "arm URDF (pybullet_data path)"),
        Param("flange_link", str, "lbr_iiwa_link_7", "", "link the sensor is mounted on"),
        *SENSOR_PARAMS,
        Param("home", list, [0.0, 0.4, 0.0, -1.4, 0.0, 1.0, 0.0], "rad", "home configuration", length=7),
        Param("weights", list, [0.05] * 7, "", "Eq. 8 weights of the joints", length=7),
        *COMMON_PARAMS,
    )

    def attach(self, sim: Simulation) -> None:
        """Load the arm at the world's base pose, the sensor housing, collision pairs, points."""
        super().attach(sim)
        x, y, z, yaw = self._world_base()
        self.base_pose = planar_pose(x, y, math.radians(yaw), z)
        self.chain = ArmChain(self, self.urdf, self.flange_link, self.base_pose)
        self.dof = len(self.chain.joints)
        self.lower, self.upper = self.chain.lower.copy(), self.chain.upper.copy()
        self.flange_T_sensor = pose6(self.mount)
        self._housing, housing_mesh = self._sensor_housing()
        body = self.chain.body
        links = [Part(body, link, f"link{link}") for link in range(-1, self.chain.flange + 1)]
        housing = Part(self._housing, -1, "sensor")
        self.parts = links + [housing]
        self._part_meshes = {housing: [housing_mesh.transformed(pose6([0, 0, 0, 0, 0, 0]))]}
        home = np.asarray(self.home[: self.dof], dtype=float)
        self.set_config(home)

        def adjacent(a: Part, b: Part) -> bool:
            if b.body == self._housing or a.body == self._housing:
                other = a if b.body == self._housing else b
                return other.link >= self.chain.flange - 2
            return abs(a.link - b.link) <= 1

        pairs = self_collision_pairs(self.client, self.parts, adjacent)
        # the base link is bolted to whatever it stands on: ignore its contacts at home
        ignore = [(links[0], b) for b in sim.environment_ids()] + [(links[1], b) for b in self._touching(links[1], sim)]
        self.collider = BulletCollider(self.client, self.parts, pairs, ignore)
        self._sample_part_points()
        self.q = home

    def _touching(self, part: Part, sim: Simulation) -> list[int]:
        out = []
        for b in sim.environment_ids():
            pts = p.getClosestPoints(part.body, b, self.clearance, linkIndexA=part.link, physicsClientId=self.client)
            if pts:
                out.append(b)
        return out

    def _set_state(self, q: Array) -> None:
        self.chain.set(q)
        self._place_housing(self.chain.flange_pose() @ self.flange_T_sensor)

    def fk(self, q: Array) -> Pose:
        """world_T_sensor = world_T_flange(q) (pybullet link state) @ flange_T_sensor (mount)."""
        self.set_config(q)
        return self.chain.flange_pose() @ self.flange_T_sensor

    def ik(
        self,
        world_T_sensor: Pose,
        rng: np.random.Generator | None = None,
        seed: Array | None = None,
        check_collision: bool = True,
    ) -> Array | None:
        """A valid configuration reaching the pose within 1 mm / 0.5 deg, or None.

        Restarts (``ik_attempts``) from random configurations; with ``seed`` only a local
        solution from the seed is tried (continuity along scan paths).
        """
        rng = rng or np.random.default_rng(0)
        target = world_T_sensor @ np.linalg.inv(self.flange_T_sensor)
        attempts = 1 if seed is not None else self.ik_attempts
        for attempt in range(attempts):
            q0 = (
                np.asarray(seed, dtype=float)
                if seed is not None
                else (np.asarray(self.home, dtype=float) if attempt == 0 else self.sample_config(rng))
            )
            q = self.chain.ik(target, q0) if seed is None else self.chain.refine(target, q0.copy())
            dp, da = pose_error(self.fk(q), world_T_sensor)
            self._state = None
            if dp > IK_POSITION_TOL or da > IK_ANGLE_TOL:
                continue
            if check_collision and (self.in_collision(q) or not self.within_limits(q)):
                continue
            return q
        return None


PLUGINS = [FreeFlyer, Arm]
