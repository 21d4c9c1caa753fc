"""Robot plugins on a planar base: the mobile manipulator (base + arm) and the mobile base with a
camera mast (Vasquez-Gomez's and Goerner's platforms); velocity controls with truncated Gaussian
noise on the base (Vasquez-Gomez Sec. A6), see :mod:`explore_plugins.robots` for the common model."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation

from explore.core import Array, Param, Pose, pose_error, quaternion_xyzw, wrap_angle
from explore.motion import (
    BulletCollider,
    BulletRobot,
    Capability,
    Part,
    self_collision_pairs,
)
from explore.sim import box_mesh, cylinder_mesh, p, sphere_mesh

from .robot_parts import (
    BASE_PARAMS,
    COMMON_PARAMS,
    IK_ANGLE_TOL,
    IK_POSITION_TOL,
    SENSOR_PARAMS,
    ArmChain,
    declare_laser,
    planar_pose,
    pose6,
    rot_z,
)

if TYPE_CHECKING:
    from explore.sim import Simulation

HEAD_HEIGHT = 0.08  # the pan-tilt head above the mast's top (m)


class MobileManipulator(BulletRobot):
    """Planar base (x, y, theta; differential drive) carrying an arm with an eye-in-hand sensor."""

    name = "mobile_manipulator"
    dof = 10
    base_dofs = (0, 1, 2)
    capabilities = frozenset({Capability.ARM, Capability.MOBILE_BASE, Capability.TRAVEL_POSE,
                              Capability.POSITIONING_NOISE})
    default_planner = "tuck_and_drive"  # no geometric planner finds its way among furniture in 10-D
    params = (
        Param("urdf", str, "kuka_iiwa/model.urdf", "", "arm URDF (pybullet_data path)"),
        Param("flange_link", str, "lbr_iiwa_link_7", "", "link the sensor is mounted on"),
        *SENSOR_PARAMS,
        Param("base_size", list, [0.6, 0.5, 0.35], "m", "base box (length, width, height)", length=3),
        Param("ground_clearance", float, 0.02, "m", "gap below the base box", low=0.0),
        Param("arm_mount", list, [0.1, 0.0], "m", "arm position on top of the base (x, y)", length=2),
        Param("drive", str, "differential", "", "base kinematics", choices=("differential", "omni")),
        Param("home", list, [0.0, -0.3, 0.0, -1.9, 0.0, 1.0, 0.0], "rad", "arm travel configuration", length=7),
        Param("weights", list, [10.0, 10.0, 0.5] + [0.05] * 7, "", "Eq. 8 weights (Vasquez-Gomez)", length=10),
        Param("reach", list, [0.35, 0.9], "m", "IK samples the base this far from the sensor (xy)", length=2),
        Param("keep_base", bool, False, "", "IK tries the current base pose first, then sampled ones nearest first "
              "(else sampled ones in the order drawn)"),
        *BASE_PARAMS,
        *COMMON_PARAMS,
    )

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        declare_laser(self)

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        x, y, _, yaw = self._world_base()
        size = np.asarray(self.base_size, dtype=float)
        self.base_T_arm = pose6([self.arm_mount[0], self.arm_mount[1], self.ground_clearance + size[2], 0, 0, 0])
        self.chain = ArmChain(self, self.urdf, self.flange_link, planar_pose(x, y, math.radians(yaw)) @ self.base_T_arm)
        self.dof = 3 + len(self.chain.joints)
        self.base_body = self._box_body(size)
        self.flange_T_sensor = pose6(self.mount)
        self._housing, housing_mesh = self._sensor_housing()
        base_part = Part(self.base_body, -1, "base")
        links = [Part(self.chain.body, link, f"link{link}") for link in range(-1, self.chain.flange + 1)]
        housing = Part(self._housing, -1, "sensor")
        self.parts = [base_part] + links + [housing]
        self._part_meshes = {
            base_part: [box_mesh(size).transformed(pose6([0, 0, size[2] / 2, 0, 0, 0]))],
            housing: [housing_mesh],
        }
        lo, hi = self._floor_bounds()
        self.lower = np.concatenate([lo, [-2 * math.pi], self.chain.lower])
        self.upper = np.concatenate([hi, [2 * math.pi], self.chain.upper])
        home = np.concatenate([[x, y, math.radians(yaw)], np.asarray(self.home, dtype=float)])
        self.set_config(home)

        def adjacent(a: Part, b: Part) -> bool:
            ends = {a.body, b.body}
            if self._housing in ends:
                other = a if b.body == self._housing else b
                return other.body == self.chain.body and other.link >= self.chain.flange - 2
            if self.base_body in ends:
                other = a if b.body == self.base_body else b
                return other.link <= 0
            return abs(a.link - b.link) <= 1

        self.collider = BulletCollider(self.client, self.parts, self_collision_pairs(self.client, self.parts, adjacent))
        self._sample_part_points()
        self.q = home

    @property
    def travel_joints(self) -> Array:
        """Arm configuration for driving (the ``home`` parameter): the base planners tuck to it."""
        return np.asarray(self.home, dtype=float)

    def _set_state(self, q: Array) -> None:
        world_T_base = planar_pose(q[0], q[1], q[2])
        p.resetBasePositionAndOrientation(
            self.base_body,
            [q[0], q[1], self.ground_clearance],
            quaternion_xyzw(world_T_base[:3, :3]),
            physicsClientId=self.client,
        )
        arm = world_T_base @ self.base_T_arm
        p.resetBasePositionAndOrientation(
            self.chain.body, arm[:3, 3].tolist(), quaternion_xyzw(arm[:3, :3]), physicsClientId=self.client
        )
        self.chain.set(q[3:])
        self._place_housing(self.chain.flange_pose() @ self.flange_T_sensor)

    def fk(self, q: Array) -> Pose:
        """world_T_sensor: planar base pose, arm mount, pybullet arm FK, sensor mount."""
        self.set_config(q)
        return self.chain.flange_pose() @ self.flange_T_sensor

    def ik(
        self,
        world_T_sensor: Pose,
        rng: np.random.Generator | None = None,
        seed: Array | None = None,
        check_collision: bool = True,
    ) -> Array | None:
        """Arm IK from base poses sampled facing the target (``reach``; with ``keep_base`` the
        current base first, then the nearest: a base that stays put keeps its odometry); None
        if unreachable."""
        rng = rng or np.random.default_rng(0)
        target = world_T_sensor @ np.linalg.inv(self.flange_T_sensor)
        if seed is not None:
            starts = [(np.asarray(seed[:3], dtype=float), np.asarray(seed[3:], dtype=float))]
        else:
            starts = self._ik_starts(world_T_sensor, rng)
        for base, q0 in starts:
            self.set_config(np.concatenate([base, q0]))
            self._state = None
            arm = self.chain.ik(target, q0) if seed is None else self.chain.refine(target, q0.copy())
            q = np.concatenate([base, arm])
            dp, da = pose_error(self.fk(q), world_T_sensor)
            if dp > IK_POSITION_TOL or da > IK_ANGLE_TOL:
                continue
            if check_collision and (not self.within_limits(q) or self.in_collision(q)):
                continue
            return q
        return None

    def _drawn_starts(self, world_T_sensor: Pose, away: float, home: Array,
                      rng: np.random.Generator) -> Iterator[tuple[Array, Array]]:
        for _ in range(self.ik_attempts):
            angle = away + rng.uniform(-1.0, 1.0)
            r = rng.uniform(*self.reach)
            bx, by = world_T_sensor[0, 3] + r * math.cos(angle), world_T_sensor[1, 3] + r * math.sin(angle)
            heading = math.atan2(world_T_sensor[1, 3] - by, world_T_sensor[0, 3] - bx) + rng.uniform(-0.3, 0.3)
            yield np.array([bx, by, heading]), home if rng.random() < 0.5 else rng.uniform(self.chain.lower,
                                                                                          self.chain.upper)

    def _ik_starts(self, world_T_sensor: Pose, rng: np.random.Generator) -> Iterable[tuple[Array, Array]]:
        """(base, arm seed) pairs for IK: ``ik_attempts`` bases ``reach`` from the sensor on its
        far side, facing it; with ``keep_base`` the current base (travel arm) first and the
        sampled ones ordered by the Eq. 8 weighted distance from it (a base that stays put
        keeps its odometry), else in the order drawn."""
        home = np.asarray(self.home, dtype=float)
        view = world_T_sensor[:2, 2]
        away = math.atan2(-view[1], -view[0]) if np.linalg.norm(view) > 1e-6 else rng.uniform(-math.pi, math.pi)
        if not self.keep_base:  # drawn one by one: IK stops drawing at the first success
            return self._drawn_starts(world_T_sensor, away, home, rng)
        here = np.asarray(self.q[:3], dtype=float)
        n = self.ik_attempts
        angle = away + rng.uniform(-1.0, 1.0, n)
        r = rng.uniform(*self.reach, n)
        bx = world_T_sensor[0, 3] + r * np.cos(angle)
        by = world_T_sensor[1, 3] + r * np.sin(angle)
        heading = np.arctan2(world_T_sensor[1, 3] - by, world_T_sensor[0, 3] - bx) + rng.uniform(-0.3, 0.3, n)
        seeds = [home if rng.random() < 0.5 else rng.uniform(self.chain.lower, self.chain.upper) for _ in range(n)]
        turn = np.angle(np.exp(1j * (heading - here[2])))
        w = np.asarray(self.weights[:3], dtype=float)
        cost = w[0] * np.abs(bx - here[0]) + w[1] * np.abs(by - here[1]) + w[2] * np.abs(turn)
        order = np.argsort(cost, kind="stable")
        return [(here, home)] + [(np.array([bx[i], by[i], heading[i]]), seeds[i]) for i in order]


class MobileBase(BulletRobot):
    """Mobile base with a camera on a mast, optional pan-tilt head (Goerner, Kriegel's omniRob)."""

    name = "mobile_base"
    dof = 5
    base_dofs = (0, 1, 2)
    capabilities = frozenset({Capability.MOBILE_BASE, Capability.POSITIONING_NOISE})
    params = (
        Param("base_size", list, [0.5, 0.5, 0.3], "m", "base box (length, width, height)", length=3),
        Param("ground_clearance", float, 0.02, "m", "gap below the base box", low=0.0),
        Param("camera_height", float, 1.3, "m", "height of the pan-tilt axes (= camera origin)", low=0.3),
        Param("mast_offset", float, 0.0, "m", "mast position along the base's x axis"),
        Param("pan_tilt", bool, True, "", "pan-tilt head (5 DOF) or a fixed camera (3 DOF)"),
        Param("tilt_deg", float, 35.0, "deg", "camera tilt (down) without a pan-tilt head", low=-90, high=90),
        Param("pan_limits", list, [-170.0, 170.0], "deg", "pan joint limits", length=2),
        Param("tilt_limits", list, [-30.0, 80.0], "deg", "tilt joint limits (positive looks down)", length=2),
        Param("drive", str, "omni", "", "base kinematics", choices=("differential", "omni")),
        Param("weights", list, [10.0, 10.0, 0.5, 0.05, 0.05], "", "Eq. 8 weights (first dof entries used)", length=5),
        *BASE_PARAMS,
        *COMMON_PARAMS,
    )

    def __init__(self, **values: Any) -> None:
        self.dof = 5 if values.get("pan_tilt", True) else 3
        super().__init__(**values)
        self.weights = list(self.weights)[: self.dof]
        declare_laser(self)
        lowest = self.ground_clearance + self.base_size[2] + HEAD_HEIGHT
        if self.camera_height <= lowest:
            raise ValueError(f"camera_height {self.camera_height:g} m leaves no mast: at least the base's "
                             f"{lowest:.2f} m (ground clearance, base height and the {HEAD_HEIGHT} m head)")

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        size = np.asarray(self.base_size, dtype=float)
        mast_len = self.camera_height - self.ground_clearance - size[2] - HEAD_HEIGHT
        mast_center = [self.mast_offset, 0.0, size[2] + mast_len / 2.0]
        head = [self.mast_offset, 0.0, self.camera_height - self.ground_clearance]
        extra = [(p.GEOM_CYLINDER, [0.03, mast_len], mast_center), (p.GEOM_SPHERE, [0.09], head)]
        self.body = self._box_body(size, extra)
        part = Part(self.body, -1, "base")
        self.parts = [part]
        self._part_meshes = {
            part: [
                box_mesh(size).transformed(pose6([0, 0, size[2] / 2, 0, 0, 0])),
                cylinder_mesh(0.03, mast_len).transformed(pose6([*mast_center, 0, 0, 0])),
                sphere_mesh(0.09).transformed(pose6([*head, 0, 0, 0])),
            ]
        }
        lo, hi = self._floor_bounds()
        lower, upper = [lo[0], lo[1], -2 * math.pi], [hi[0], hi[1], 2 * math.pi]
        if self.pan_tilt:
            lower += [math.radians(self.pan_limits[0]), math.radians(self.tilt_limits[0])]
            upper += [math.radians(self.pan_limits[1]), math.radians(self.tilt_limits[1])]
        self.lower, self.upper = np.array(lower), np.array(upper)
        x, y, _, yaw = self._world_base()
        home = np.zeros(self.dof)
        home[:3] = (x, y, math.radians(yaw))
        if self.pan_tilt:
            home[4] = math.radians(self.tilt_deg)
        self.collider = BulletCollider(self.client, self.parts)
        self.set_config(home)
        self._sample_part_points()
        self.q = home

    def _set_state(self, q: Array) -> None:
        pose = planar_pose(q[0], q[1], q[2])
        p.resetBasePositionAndOrientation(
            self.body, [q[0], q[1], self.ground_clearance], quaternion_xyzw(pose[:3, :3]), physicsClientId=self.client
        )

    def _pan_tilt(self, q: Array) -> tuple[float, float]:
        return (float(q[3]), float(q[4])) if self.pan_tilt else (0.0, math.radians(self.tilt_deg))

    def fk(self, q: Array) -> Pose:
        """world_T_base(x, y, theta) @ mast top @ Rz(pan) @ Ry(tilt) @ head_T_camera (OpenCV)."""
        q = np.asarray(q, dtype=float)
        pan, tilt = self._pan_tilt(q)
        world_T_head = planar_pose(q[0], q[1], q[2]) @ pose6([self.mast_offset, 0.0, self.camera_height, 0, 0, 0])
        rot = rot_z(pan) @ Rotation.from_euler("y", tilt).as_matrix()
        head_T_camera = np.column_stack([[0, -1, 0], [0, 0, -1], [1, 0, 0]]).astype(float)  # x=-y, y=-z, z=x
        pose = world_T_head.copy()
        pose[:3, :3] = world_T_head[:3, :3] @ rot @ head_T_camera
        return pose

    def ik(
        self,
        world_T_sensor: Pose,
        rng: np.random.Generator | None = None,
        seed: Array | None = None,
        check_collision: bool = True,
    ) -> Array | None:
        """Exact for poses at ``camera_height`` without roll: yaw = theta + pan, tilt from pitch."""
        rng = rng or np.random.default_rng(0)
        forward = world_T_sensor[:3, 2]
        yaw = math.atan2(forward[1], forward[0])
        tilt = math.asin(float(np.clip(-forward[2], -1.0, 1.0)))
        attempts = 1 if seed is not None else self.ik_attempts
        for attempt in range(attempts):
            if self.pan_tilt:
                pan = (
                    float(seed[3])
                    if seed is not None
                    else (0.0 if attempt == 0 else rng.uniform(*self.lower[3:4], *self.upper[3:4]))
                )
            else:
                pan = 0.0
            theta = yaw - pan
            if seed is not None:  # keep theta continuous with the seed
                theta = seed[2] + wrap_angle(theta - seed[2])
            xy = world_T_sensor[:2, 3] - rot_z(theta)[:2, 0] * self.mast_offset
            q = np.array([xy[0], xy[1], theta] + ([pan, tilt] if self.pan_tilt else []))
            dp, da = pose_error(self.fk(q), world_T_sensor)
            if dp > IK_POSITION_TOL or da > IK_ANGLE_TOL or not self.within_limits(q):
                if not self.pan_tilt or seed is not None:
                    return None
                continue
            if check_collision and self.in_collision(q):
                continue
            return q
        return None


PLUGINS = [MobileManipulator, MobileBase]
