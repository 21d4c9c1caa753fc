"""Pieces the built-in robots share: parameter sets, pose helpers, the serial arm chain (FK and
damped-least-squares IK on a pybullet arm) and the planar-laser capability."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from explore.core import Array, Param, Pose, quaternion_xyzw
from explore.motion import BulletRobot, Capability
from explore.sim import frame_pose, p

IK_POSITION_TOL = 1e-3  # m, FK/IK round trip
IK_ANGLE_TOL = math.radians(0.5)
SIGMA_V = 1.65e-3  # m/s (Vasquez-Gomez Table 4)
SIGMA_W = 0.28  # rad/s


def rot_z(theta: float) -> Array:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def planar_pose(x: float, y: float, theta: float, z: float = 0.0) -> Pose:
    pose = np.eye(4)
    pose[:3, :3] = rot_z(theta)
    pose[:3, 3] = (x, y, z)
    return pose


def pose6(values: list[float]) -> Pose:
    """[x, y, z (m), roll, pitch, yaw (deg)] -> 4x4."""
    pose = np.eye(4)
    pose[:3, 3] = values[:3]
    pose[:3, :3] = Rotation.from_euler("xyz", values[3:6], degrees=True).as_matrix()
    return pose


def rotvec(m: Array) -> Array:
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


COMMON_PARAMS = (
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
    Param("ik_attempts", int, 30, "", "random restarts of IK", low=1, high=10000),
)
SENSOR_PARAMS = (
    Param(
        "mount", list, [0.0, 0.0, 0.06, 0.0, 0.0, 0.0], "", "flange_T_sensor [x y z m, roll pitch yaw deg]", length=6
    ),
    Param(
        "sensor_size", list, [0.08, 0.10, 0.06], "m", "collision box of the sensor housing behind its origin", length=3
    ),
)
BASE_PARAMS = (
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


class ArmChain:
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
        if len(q) != len(self.joints):
            raise ValueError(f"{len(q)} joint values for {len(self.joints)} joints")
        p.resetJointStatesMultiDof(self.body, self.joints, [[float(v)] for v in q], physicsClientId=self.robot.client)
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
        rot = rotvec(target[:3, :3] @ pose[:3, :3].T)
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
                            rotvec(pose_i[:3, :3] @ pose[:3, :3].T),
                        ]
                    )
                    / h
                )
            step = jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(6), err)
            q = np.clip(q + step, self.lower, self.upper)
        return q


def declare_laser(robot: BulletRobot) -> None:
    """A base with ``laser_height`` > 0 carries the planar localisation laser; the base box must
    have a size (ValueError, reported as one line naming the robot)."""
    if min(robot.base_size) <= 0:
        raise ValueError(f"base_size {list(robot.base_size)}: every side must be positive")
    if robot.laser_height > 0:
        robot.capabilities = robot.capabilities | {Capability.PLANAR_LASER}
