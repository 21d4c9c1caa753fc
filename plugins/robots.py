"""Robot plugins: free flyer, fixed arm, mobile manipulator and mobile base (pybullet bodies).

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
from explore.sim import frame_pose, p

if TYPE_CHECKING:
    from explore.sim import Simulation

IK_POSITION_TOL = 1e-3  # m, FK/IK round trip
IK_ANGLE_TOL = math.radians(0.5)
SIGMA_V = 1.65e-3  # m/s (Vasquez-Gomez Table 4)
SIGMA_W = 0.28  # rad/s


def _rot_z(theta: float) -> Array:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _planar(x: float, y: float, theta: float, z: float = 0.0) -> Pose:
    pose = np.eye(4)
    pose[:3, :3] = _rot_z(theta)
    pose[:3, 3] = (x, y, z)
    return pose


def _pose6(values: list[float]) -> Pose:
    """[x, y, z (m), roll, pitch, yaw (deg)] -> 4x4."""
    pose = np.eye(4)
    pose[:3, 3] = values[:3]
    pose[:3, :3] = Rotation.from_euler("xyz", values[3:6], degrees=True).as_matrix()
    return pose


def _rotvec(m: Array) -> Array:
    """Rotation vector of a rotation matrix: atan2 form of the log map (stable at small angles).

    Same values as ``Rotation.from_matrix(m).as_rotvec()`` without its per-call overhead,
    which dominated IK (7 calls per Jacobian); angles near pi fall back to scipy.
    """
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    sin2 = math.sqrt(float(w @ w))  # 2 sin(angle)
    cos = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)
    if cos < -0.99:
        return Rotation.from_matrix(m).as_rotvec()
    if sin2 < 1e-12:
        return 0.5 * w
    return w * (math.atan2(0.5 * sin2, cos) / sin2)


_COMMON = (
    Param("clearance", float, 0.01, "m", "planning margin to the known environment", low=0.0),
    Param("dt", float, 0.05, "s", "control period of execution (Euler step)", low=1e-3),
    Param("joint_speed", float, 0.5, "rad/s", "nominal joint speed for execution", low=1e-3),
    Param("joint_sigma", float, 0.0, "rad/s", "noise sigma on joint velocity controls", low=0.0),
    Param("truncation", float, 3.0, "", "noise truncated at beta = truncation * sigma", low=0.1),
    Param(
        "on_collision",
        str,
        "stop",
        "",
        "a collision during execution ends the motion or not",
        choices=("stop", "continue"),
    ),
    Param("point_spacing", float, 0.03, "m", "spacing of surface points tested against the PVS", low=0.005),
    Param("ik_attempts", int, 30, "", "random restarts of IK", low=1),
)
_SENSOR = (
    Param(
        "mount", list, [0.0, 0.0, 0.06, 0.0, 0.0, 0.0], "", "flange_T_sensor [x y z m, roll pitch yaw deg]", length=6
    ),
    Param(
        "sensor_size", list, [0.08, 0.10, 0.06], "m", "collision box of the sensor housing behind its origin", length=3
    ),
)
_BASE = (
    Param("base_speed", float, 0.3, "m/s", "nominal base speed", low=1e-3),
    Param("base_turn_speed", float, 0.5, "rad/s", "nominal base turn rate", low=1e-3),
    Param("sigma_v", float, SIGMA_V, "m/s", "noise sigma of linear velocity (Vasquez-Gomez: 1.65 mm/s)", low=0.0),
    Param("sigma_w", float, SIGMA_W, "rad/s", "noise sigma of angular velocity (Vasquez-Gomez: 0.28 rad/s)", low=0.0),
    Param("laser_height", float, 0.0, "m", "planar 360-degree localisation laser on the base at this height (0: none)",
          low=0.0),
    Param("drive_clearance", float, 0.0, "m", "margin kept while the base drives, away from the drive's ends "
          "(0: the planning clearance only)", low=0.0),
    Param("replan_distance", float, 0.0, "m", "scene exploration: drive in legs of this many metres, each followed "
          "by a short plan back onto the planned path (a base that localises while it drives; 0: open loop)",
          low=0.0),
    Param("laser_range", float, 4.0, "m", "base laser range", low=0.1),
    Param("laser_sigma", float, 0.01, "m", "base laser range noise sigma", low=0.0),
)


class _ArmChain:
    """A serial arm in pybullet (KUKA iiwa by default): joints, FK and DLS-refined IK."""

    def __init__(self, robot: BulletRobot, urdf: str, flange_link: str, base_pose: Pose) -> None:
        self.robot = robot
        client = robot.client
        self.body = p.loadURDF(
            urdf,
            basePosition=base_pose[:3, 3].tolist(),
            baseOrientation=quaternion_xyzw(base_pose[:3, :3]),
            useFixedBase=True,
            physicsClientId=client,
        )
        joints, lower, upper = [], [], []
        self.flange = -1
        for j in range(p.getNumJoints(self.body, physicsClientId=client)):
            info = p.getJointInfo(self.body, j, physicsClientId=client)
            if info[2] == p.JOINT_REVOLUTE and self.flange < 0:
                joints.append(j)
                lower.append(info[8])
                upper.append(info[9])
            if info[12].decode() == flange_link:
                self.flange = j
        if self.flange < 0:
            raise ValueError(f"{urdf} has no link {flange_link!r}")
        self.joints = joints
        self.lower, self.upper = np.array(lower), np.array(upper)
        for j in range(p.getNumJoints(self.body, physicsClientId=client)):
            p.changeVisualShape(self.body, j, rgbaColor=[0.9, 0.5, 0.1, 1.0], physicsClientId=client)

    def set(self, q: Array) -> None:
        """Set the joints (the robot's cached configuration is then unknown)."""
        for j, v in zip(self.joints, q, strict=True):
            p.resetJointState(self.body, j, float(v), physicsClientId=self.robot.client)
        self.robot._state = None

    def flange_pose(self, q: Array | None = None) -> Pose:
        """world_T_flange at joints ``q`` (set first) or at the current joints."""
        if q is not None:
            self.set(q)
        state = p.getLinkState(self.body, self.flange, computeForwardKinematics=True, physicsClientId=self.robot.client)
        return frame_pose(state[4], state[5])

    def ik(self, world_T_flange: Pose, q0: Array, iterations: int = 60) -> Array:
        """pybullet IK from ``q0`` then damped least squares on the full pose error."""
        client = self.robot.client
        self.set(q0)
        span = (self.upper - self.lower).tolist()
        q = np.array(
            p.calculateInverseKinematics(
                self.body,
                self.flange,
                world_T_flange[:3, 3].tolist(),
                quaternion_xyzw(world_T_flange[:3, :3]),
                lowerLimits=self.lower.tolist(),
                upperLimits=self.upper.tolist(),
                jointRanges=span,
                restPoses=np.asarray(q0).tolist(),
                maxNumIterations=100,
                residualThreshold=1e-6,
                physicsClientId=client,
            )[: len(self.joints)]
        )
        q = np.clip(q, self.lower, self.upper)
        return self.refine(world_T_flange, q, iterations)

    def _twist_error(self, target: Pose, pose: Pose) -> Array:
        rot = _rotvec(target[:3, :3] @ pose[:3, :3].T)
        return np.concatenate([target[:3, 3] - pose[:3, 3], rot])

    def refine(self, target: Pose, q: Array, iterations: int = 60, damping: float = 1e-3) -> Array:
        """Damped least squares with a finite-difference Jacobian (FK from pybullet)."""
        h = 1e-6
        for _ in range(iterations):
            pose = self.flange_pose(q)
            err = self._twist_error(target, pose)
            if np.linalg.norm(err[:3]) < 1e-5 and np.linalg.norm(err[3:]) < 1e-5:
                break
            jac = np.empty((6, len(q)))
            for i in range(len(q)):
                dq = q.copy()
                dq[i] += h
                pose_i = self.flange_pose(dq)
                jac[:, i] = (
                    np.concatenate(
                        [
                            pose_i[:3, 3] - pose[:3, 3],
                            _rotvec(pose_i[:3, :3] @ pose[:3, :3].T),
                        ]
                    )
                    / h
                )
            step = jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(6), err)
            q = np.clip(q + step, self.lower, self.upper)
        return q


def _declare_laser(robot: BulletRobot) -> None:
    """A base with ``laser_height`` > 0 carries the planar localisation laser."""
    if robot.laser_height > 0:
        robot.capabilities = robot.capabilities | {Capability.PLANAR_LASER}


class Arm(BulletRobot):
    """Fixed industrial arm (KUKA iiwa, 7 DOF) with an eye-in-hand sensor; IK with restarts."""

    name = "arm"
    dof = 7
    capabilities = frozenset({Capability.ARM, Capability.POSITIONING_NOISE})
    params = (
        Param("urdf", str, "kuka_iiwa/model.urdf", "", "arm URDF (pybullet_data path)"),
        Param("flange_link", str, "lbr_iiwa_link_7", "", "link the sensor is mounted on"),
        *_SENSOR,
        Param("home", list, [0.0, 0.4, 0.0, -1.4, 0.0, 1.0, 0.0], "rad", "home configuration", length=7),
        Param("weights", list, [0.05] * 7, "", "Eq. 8 weights of the joints", length=7),
        *_COMMON,
    )

    def attach(self, sim: Simulation) -> None:
        """Load the arm at the world's base pose, the sensor housing, collision pairs, points."""
        super().attach(sim)
        x, y, z, yaw = self._world_base()
        self.base_pose = _planar(x, y, math.radians(yaw), z)
        self.chain = _ArmChain(self, self.urdf, self.flange_link, self.base_pose)
        self.dof = len(self.chain.joints)
        self.lower, self.upper = self.chain.lower.copy(), self.chain.upper.copy()
        self.flange_T_sensor = _pose6(self.mount)
        self._housing, housing_mesh = self._sensor_housing()
        body = self.chain.body
        links = [Part(body, link, f"link{link}") for link in range(-1, self.chain.flange + 1)]
        housing = Part(self._housing, -1, "sensor")
        self.parts = links + [housing]
        self._part_meshes = {housing: [housing_mesh.transformed(_pose6([0, 0, 0, 0, 0, 0]))]}
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
        *_SENSOR,
        Param("base_size", list, [0.6, 0.5, 0.35], "m", "base box (length, width, height)", length=3),
        Param("ground_clearance", float, 0.02, "m", "gap below the base box", low=0.0),
        Param("arm_mount", list, [0.1, 0.0], "m", "arm position on top of the base (x, y)", length=2),
        Param("drive", str, "differential", "", "base kinematics", choices=("differential", "omni")),
        Param("home", list, [0.0, -0.3, 0.0, -1.9, 0.0, 1.0, 0.0], "rad", "arm travel configuration", length=7),
        Param("weights", list, [10.0, 10.0, 0.5] + [0.05] * 7, "", "Eq. 8 weights (Vasquez-Gomez)", length=10),
        Param("reach", list, [0.35, 0.9], "m", "IK samples the base this far from the sensor (xy)", length=2),
        Param("keep_base", bool, False, "", "IK tries the current base pose first, then sampled ones nearest first "
              "(else sampled ones in the order drawn)"),
        *_BASE,
        *_COMMON,
    )

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        _declare_laser(self)

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        x, y, _, yaw = self._world_base()
        size = np.asarray(self.base_size, dtype=float)
        self.base_T_arm = _pose6([self.arm_mount[0], self.arm_mount[1], self.ground_clearance + size[2], 0, 0, 0])
        self.chain = _ArmChain(self, self.urdf, self.flange_link, _planar(x, y, math.radians(yaw)) @ self.base_T_arm)
        self.dof = 3 + len(self.chain.joints)
        self.base_body = self._box_body(size)
        from explore.sim import box_mesh

        self.flange_T_sensor = _pose6(self.mount)
        self._housing, housing_mesh = self._sensor_housing()
        base_part = Part(self.base_body, -1, "base")
        links = [Part(self.chain.body, link, f"link{link}") for link in range(-1, self.chain.flange + 1)]
        housing = Part(self._housing, -1, "sensor")
        self.parts = [base_part] + links + [housing]
        self._part_meshes = {
            base_part: [box_mesh(size).transformed(_pose6([0, 0, size[2] / 2, 0, 0, 0]))],
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
        world_T_base = _planar(q[0], q[1], q[2])
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
        *_BASE,
        *_COMMON,
    )

    def __init__(self, **values: Any) -> None:
        self.dof = 5 if values.get("pan_tilt", True) else 3
        super().__init__(**values)
        self.weights = list(self.weights)[: self.dof]
        _declare_laser(self)

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        from explore.sim import box_mesh, cylinder_mesh, sphere_mesh

        size = np.asarray(self.base_size, dtype=float)
        mast_len = self.camera_height - self.ground_clearance - size[2] - 0.08
        mast_center = [self.mast_offset, 0.0, size[2] + mast_len / 2.0]
        head = [self.mast_offset, 0.0, self.camera_height - self.ground_clearance]
        extra = [(p.GEOM_CYLINDER, [0.03, mast_len], mast_center), (p.GEOM_SPHERE, [0.09], head)]
        self.body = self._box_body(size, extra)
        part = Part(self.body, -1, "base")
        self.parts = [part]
        self._part_meshes = {
            part: [
                box_mesh(size).transformed(_pose6([0, 0, size[2] / 2, 0, 0, 0])),
                cylinder_mesh(0.03, mast_len).transformed(_pose6([*mast_center, 0, 0, 0])),
                sphere_mesh(0.09).transformed(_pose6([*head, 0, 0, 0])),
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
        pose = _planar(q[0], q[1], q[2])
        p.resetBasePositionAndOrientation(
            self.body, [q[0], q[1], self.ground_clearance], quaternion_xyzw(pose[:3, :3]), physicsClientId=self.client
        )

    def _pan_tilt(self, q: Array) -> tuple[float, float]:
        return (float(q[3]), float(q[4])) if self.pan_tilt else (0.0, math.radians(self.tilt_deg))

    def fk(self, q: Array) -> Pose:
        """world_T_base(x, y, theta) @ mast top @ Rz(pan) @ Ry(tilt) @ head_T_camera (OpenCV)."""
        q = np.asarray(q, dtype=float)
        pan, tilt = self._pan_tilt(q)
        world_T_head = _planar(q[0], q[1], q[2]) @ _pose6([self.mast_offset, 0.0, self.camera_height, 0, 0, 0])
        rot = _rot_z(pan) @ Rotation.from_euler("y", tilt).as_matrix()
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
            xy = world_T_sensor[:2, 3] - _rot_z(theta)[:2, 0] * self.mast_offset
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
            from explore.sim import sphere_mesh

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


PLUGINS = [FreeFlyer, Arm, MobileManipulator, MobileBase]
