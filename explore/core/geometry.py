"""Rigid transforms (SE(3)), angles and camera frames: the one home of these helpers.

Sensor frames follow the OpenCV convention: z looks forward, x to the right, y down.
Poses are 4x4 homogeneous matrices named ``world_T_frame``. Angles are radians everywhere;
degrees appear only in names that say so (``rpy_deg``, ``*_deg`` metrics).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from explore.core.typed import Array, Points3, Pose

WORLD_UP = np.array([0.0, 0.0, 1.0])


def pose_from(position: Array, rotation: Array | None = None) -> Pose:
    """Homogeneous matrix from a position and a 3x3 rotation (identity if omitted)."""
    pose = np.eye(4)
    pose[:3, 3] = position
    if rotation is not None:
        pose[:3, :3] = rotation
    return pose


def rpy_deg_to_matrix(rpy_deg: Array) -> Array:
    """Rotation from roll, pitch, yaw in degrees (fixed axes x, y, z, as URDF)."""
    return Rotation.from_euler("xyz", rpy_deg, degrees=True).as_matrix()


def look_at(eye: Array, target: Array, up: Array = WORLD_UP) -> Pose:
    """world_T_sensor for a sensor at ``eye`` whose optical axis (z) points at ``target``."""
    eye = np.asarray(eye, dtype=float)
    forward = np.asarray(target, dtype=float) - eye
    norm = np.linalg.norm(forward)
    if norm < 1e-9:
        raise ValueError("look_at: eye and target coincide")
    z = forward / norm
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:  # looking straight up or down: pick any right vector
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(x) < 1e-6:
            x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return pose_from(eye, np.column_stack([x, y, z]))


def transform_points(pose: Pose, points: Points3) -> Points3:
    """Apply a 4x4 transform to (n, 3) points."""
    return points @ pose[:3, :3].T + pose[:3, 3]


def invert(pose: Pose) -> Pose:
    """Inverse of a rigid transform."""
    out = np.eye(4)
    out[:3, :3] = pose[:3, :3].T
    out[:3, 3] = -pose[:3, :3].T @ pose[:3, 3]
    return out


def rotation_angle(a: Pose, b: Pose) -> float:
    """Angle in radians of the rotation between two poses."""
    r = a[:3, :3].T @ b[:3, :3]
    return float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """The same angle in [-pi, pi) (element-wise for an array)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def pose_error(estimate: Pose, truth: Pose) -> tuple[float, float]:
    """(translation error in m, rotation error in rad) between two poses."""
    return float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3])), rotation_angle(estimate, truth)


def project_rotation(m: Array) -> Array:
    """Closest rotation (Frobenius norm) to a 3x3 matrix: SVD with det = +1."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def mean_rotation(rotations: np.ndarray, weights: Array | None = None) -> Array:
    """Weighted mean of rotations (n, 3, 3): the rotation closest to them all in the chordal (Frobenius) sense.

    Markley et al. 2007: the eigenvector of the largest eigenvalue of sum w q q^T (quaternions
    q) minimises the weighted sum of squared Frobenius distances (the chordal L2 mean, Hartley
    2013); the sign of each quaternion does not matter.
    """
    w = np.ones(len(rotations)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    quats = Rotation.from_matrix(np.asarray(rotations)).as_quat()
    _, vectors = np.linalg.eigh((quats * w[:, None]).T @ quats)
    return Rotation.from_quat(vectors[:, -1]).as_matrix()


def mean_pose(poses: np.ndarray, weights: Array | None = None) -> Pose:
    """Weighted mean of poses (n, 4, 4): mean translation and :func:`mean_rotation`."""
    poses = np.asarray(poses, dtype=float)
    w = np.ones(len(poses)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    out = np.eye(4)
    out[:3, :3] = mean_rotation(poses[:, :3, :3], w)
    out[:3, 3] = w @ poses[:, :3, 3]
    return out


def kabsch(source: Points3, target: Points3, weights: Array | None = None) -> Pose:
    """Least-squares rigid transform with ``target ~ R source + t`` (Arun / Umeyama, SVD)."""
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    mu_s, mu_t = w @ source, w @ target
    h = ((source - mu_s) * w[:, None]).T @ (target - mu_t)
    r = project_rotation(h.T)
    out = np.eye(4)
    out[:3, :3] = r
    out[:3, 3] = mu_t - r @ mu_s
    return out


def rotate_about_axis(pose: Pose, axis_local: Array, angle: float) -> Pose:
    """Rotate a pose about one of its own axes through its origin."""
    out = pose.copy()
    out[:3, :3] = pose[:3, :3] @ Rotation.from_rotvec(np.asarray(axis_local) * angle).as_matrix()
    return out


def fibonacci_sphere(n: int) -> Points3:
    """``n`` nearly uniform unit vectors (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / n)
    theta = np.pi * (1.0 + 5.0**0.5) * i
    return np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])


def parse_vector(text: str, n: int = 3) -> Array:
    """Parse ``"x,y,z"`` into a finite float vector of length ``n`` (ValueError otherwise)."""
    parts = [p for p in text.replace(" ", "").split(",") if p]
    if len(parts) != n:
        raise ValueError(f"expected {n} comma-separated numbers, got {text!r}")
    values = np.array([float(p) for p in parts])
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{text!r} contains NaN or inf")
    return values


def quaternion_xyzw(m: Array) -> list[float]:
    """Quaternion (x, y, z, w, as pybullet) of a rotation matrix (Shepperd's method)."""
    t = m[0, 0] + m[1, 1] + m[2, 2]
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        return [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
    q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
    q[i], q[j], q[k] = 0.25 * s, (m[j, i] + m[i, j]) / s, (m[k, i] + m[i, k]) / s
    return q
