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

from explore.core import Array, Param, Points3, Pose, pose_error, wrap_angle
from explore.motion import (
    BulletCollider,
    CollisionEvent,
    Execution,
    MotionPlan,
    Part,
    Robot,
    self_collision_pairs,
    truncated_normal,
    truncated_normal_logpdf,
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


def _quat(m: Array) -> list[float]:
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


def _surface_samples(vertices: Array, triangles: np.ndarray, spacing: float) -> Points3:
    """Points on a mesh surface about ``spacing`` apart (area sampling, voxel thinning)."""
    if len(triangles) == 0:
        return np.zeros((0, 3))
    tri = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    count = int(min(20000, max(50, 8 * area.sum() / spacing**2)))
    rng = np.random.default_rng(0)
    pick = rng.choice(len(tri), size=count, p=area / max(area.sum(), 1e-12))
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[pick]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    points = np.vstack([points, vertices])
    _, keep = np.unique(np.floor(points / spacing).astype(np.int64), axis=0, return_index=True)
    return points[np.sort(keep)]


class _BulletRobot(Robot):
    """Shared machinery: pybullet parts, collision, link points, controls and noisy execution.

    Subclasses define ``dof``, ``lower``/``upper``, ``weights``, ``base_dofs`` (x, y, theta
    indices or empty), ``drive`` and ``_set_state(q)`` / ``fk(q)``.
    """

    base_dofs: tuple[int, ...] = ()
    drive: str = "none"
    dt: float = 0.05
    clearance: float = 0.01
    on_collision: str = "stop"
    point_spacing: float = 0.03

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.lower = np.full(self.dof, -np.inf)
        self.upper = np.full(self.dof, np.inf)
        self.parts: list[Part] = []
        self.collider: BulletCollider | None = None
        self._local_points: list[tuple[Part, Points3]] = []
        self._points_at: dict[float, list[tuple[Part, Points3]]] = {}
        self._com_offset: dict[int, Pose] = {}
        self._state: Array | None = None

    # -- geometry ----------------------------------------------------------------------------
    @property
    def client(self) -> int:
        if self.sim is None:
            raise RuntimeError(f"{self.name}: attach(sim) first")
        return self.sim.client

    def set_config(self, q: Array) -> None:
        """Put the pybullet bodies in configuration ``q`` (cached)."""
        q = np.asarray(q, dtype=float)
        if self._state is not None and np.array_equal(self._state, q):
            return
        self._set_state(q)
        self._state = q.copy()

    def _set_state(self, q: Array) -> None:
        raise NotImplementedError

    def part_pose(self, part: Part) -> Pose:
        """world_T_link of a part in the current pybullet state."""
        if part.link == -1:
            pos, orn = p.getBasePositionAndOrientation(part.body, physicsClientId=self.client)
            if part.body not in self._com_offset:
                info = p.getDynamicsInfo(part.body, -1, physicsClientId=self.client)
                self._com_offset[part.body] = np.linalg.inv(frame_pose(info[3], info[4]))
            return frame_pose(pos, orn) @ self._com_offset[part.body]
        state = p.getLinkState(part.body, part.link, computeForwardKinematics=True, physicsClientId=self.client)
        return frame_pose(state[4], state[5])

    def _sample_part_points(self) -> None:
        """Points on every part's geometry (``point_spacing`` apart), in the part's link frame."""
        self._local_points = self._part_point_sets(self.point_spacing)
        self._points_at = {float(self.point_spacing): self._local_points}

    def _part_point_sets(self, spacing: float) -> list[tuple[Part, Points3]]:
        """(part, points in its link frame) on every part's visual geometry and extra meshes."""
        from explore.sim import box_mesh, cylinder_mesh, read_mesh, sphere_mesh

        sets = []
        for part in self.parts:
            meshes = []
            for shape in p.getVisualShapeData(part.body, physicsClientId=self.client):
                if shape[1] != part.link:
                    continue
                geom, dims, filename = shape[2], shape[3], shape[4]
                link_T_visual = frame_pose(shape[5], shape[6])
                if geom == p.GEOM_MESH:
                    name = filename.decode() if isinstance(filename, bytes) else filename
                    meshes.append(read_mesh(name).transformed(link_T_visual, np.asarray(dims)))
                elif geom == p.GEOM_BOX:
                    meshes.append(box_mesh(np.asarray(dims)).transformed(link_T_visual))
                elif geom == p.GEOM_SPHERE:
                    meshes.append(sphere_mesh(dims[0]).transformed(link_T_visual))
                elif geom in (p.GEOM_CYLINDER, p.GEOM_CAPSULE):
                    meshes.append(cylinder_mesh(dims[1], dims[0]).transformed(link_T_visual))
            meshes.extend(self._extra_meshes(part))
            points = [_surface_samples(m.vertices, m.triangles, spacing) for m in meshes]
            sets.append((part, np.vstack(points) if points else np.zeros((0, 3))))
        return sets

    def _extra_meshes(self, part: Part) -> list:
        """Meshes of parts built without visual shapes (boxes of bases, sensor housing)."""
        return getattr(self, "_part_meshes", {}).get(part, [])

    def link_points(
        self, q: Array, within: tuple[Array, Array] | None = None, pad: float = 0.05, spacing: float | None = None
    ) -> Points3:
        """(n, 3) points sampled on the robot's surface at ``q`` (for PVS free-space tests).

        With ``within`` = (lo, hi) only the parts whose pybullet AABB, grown by ``pad``
        (visual and collision shapes differ slightly), overlaps that box contribute: a
        free-space test of a box (the PVS grid) skips the parts far from it. ``spacing``
        other than ``point_spacing`` samples (and caches) another point set.
        """
        if self.sim is None:
            return np.zeros((0, 3))
        self.set_config(q)
        sets = self._local_points
        if spacing is not None and float(spacing) != float(self.point_spacing):
            if float(spacing) not in self._points_at:
                self._points_at[float(spacing)] = self._part_point_sets(float(spacing))
            sets = self._points_at[float(spacing)]
        out = []
        for part, local in sets:
            if not len(local):
                continue
            if within is not None:
                lo, hi = p.getAABB(part.body, part.link, physicsClientId=self.client)
                if any(lo[i] - pad > within[1][i] or hi[i] + pad < within[0][i] for i in range(3)):
                    continue
            pose = self.part_pose(part)
            out.append(local @ pose[:3, :3].T + pose[:3, 3])
        return np.vstack(out) if out else np.zeros((0, 3))

    def obstacle_ids(self, world: str) -> list[int]:
        """Known environment (what a planner may use) or the true world (+ unknown objects)."""
        assert self.sim is not None
        ids = list(self.sim.environment_ids())
        if world == "true":
            ids += list(self.sim.object_ids())
        elif world != "known":
            raise ValueError(f"world must be 'known' or 'true', got {world!r}")
        return ids

    def collisions(self, q: Array, world: str = "known", margin: float = 0.0) -> list[str]:
        """Names of the bodies the robot at ``q`` is within ``margin`` of ("self" for itself)."""
        if self.sim is None or self.collider is None:
            return []
        self.set_config(q)
        hits = self.collider.collides(self.obstacle_ids(world), margin)
        names = {b.body_id: b.name for b in self.sim.bodies}
        return [names.get(h, "self") if h >= 0 else "self" for h in hits]

    def in_collision(self, q: Array, world: str = "known", margin: float | None = None) -> bool:
        """True if the robot at ``q`` collides (or is closer than ``margin``) with ``world``."""
        return bool(self.collisions(q, world, self.clearance if margin is None else margin))

    def within_limits(self, q: Array) -> bool:
        q = np.asarray(q)
        return bool(np.all(q >= self.lower - 1e-9) and np.all(q <= self.upper + 1e-9))

    def distance(self, a: Array, b: Array) -> float:
        """Weighted configuration distance (Vasquez-Gomez Eq. 8): sqrt(sum_j w_j (a_j - b_j)^2)."""
        d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
        return float(np.sqrt(np.sum(np.asarray(self.weights) * d * d)))

    def sample_config(self, rng: np.random.Generator) -> Array:
        """A uniform configuration within the limits (not checked for collisions)."""
        return rng.uniform(self.lower, self.upper)

    # -- controls and execution --------------------------------------------------------------
    @property
    def joint_dofs(self) -> list[int]:
        return [i for i in range(self.dof) if i not in self.base_dofs]

    def base_control_limits(self) -> Array:
        """Max |u| of the base controls: (v, omega) differential, (vx, vy, omega) omni."""
        if self.drive == "differential":
            return np.array([self.base_speed, self.base_turn_speed])
        return np.array([self.base_speed, self.base_speed, self.base_turn_speed])

    @property
    def n_base_controls(self) -> int:
        return 0 if not self.base_dofs else (2 if self.drive == "differential" else 3)

    def control_sigma(self) -> Array:
        """Per-control noise sigma (Vasquez-Gomez Table 4; joints ``joint_sigma``)."""
        base = []
        if self.base_dofs:
            base = (
                [self.sigma_v, self.sigma_w]
                if self.drive == "differential"
                else [self.sigma_v, self.sigma_v, self.sigma_w]
            )
        return np.array(base + [self.joint_sigma] * len(self.joint_dofs), dtype=float)

    def propagate_base(self, qb: Array, u: Array, dt: float) -> Array:
        """Euler step of the base (Vasquez-Gomez Sec. A6): unicycle or omnidirectional."""
        x, y, th = qb
        if self.drive == "differential":
            v, w = u[0], u[1]
            return np.array([x + v * math.cos(th) * dt, y + v * math.sin(th) * dt, th + w * dt])
        vx, vy, w = u[0], u[1], u[2]
        c, s = math.cos(th), math.sin(th)
        return np.array([x + (c * vx - s * vy) * dt, y + (s * vx + c * vy) * dt, th + w * dt])

    def propagate(self, q: Array, u: Array, dt: float) -> Array:
        """One Euler step of the whole configuration under controls ``u``."""
        out = np.asarray(q, dtype=float).copy()
        nb = self.n_base_controls
        if self.base_dofs:
            out[list(self.base_dofs)] = self.propagate_base(out[list(self.base_dofs)], u[:nb], dt)
        out[self.joint_dofs] += np.asarray(u[nb:]) * dt
        return out

    def base_to_full_controls(self, base_controls: np.ndarray) -> np.ndarray:
        zeros = np.zeros((len(base_controls), len(self.joint_dofs)))
        return np.hstack([np.asarray(base_controls).reshape(len(base_controls), -1), zeros])

    def _speeds(self) -> Array:
        speeds = np.full(self.dof, float(self.joint_speed))
        if self.base_dofs:
            x, y, th = self.base_dofs
            speeds[[x, y]] = self.base_speed
            speeds[th] = self.base_turn_speed
        return speeds

    def _expand_differential(self, path: np.ndarray) -> np.ndarray:
        """Turn-drive-turn waypoints so a differential base can follow a geometric path.

        Each segment a -> b becomes: turn in place to the drive heading, drive straight,
        turn to b's heading. The drive heading (forwards or backwards) minimises the total
        turning and takes the value closest to the mean of both headings, and the other
        joints move in proportion to the time of the three pieces, so the expansion of b -> a
        is that of a -> b reversed (a symmetric local planner, as OMPL's bidirectional
        planners assume).
        """
        x, y, th = self.base_dofs
        out = [np.asarray(path[0], dtype=float)]
        for a, b in zip(path[:-1], path[1:], strict=True):
            a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
            d = b[[x, y]] - a[[x, y]]
            drive = float(np.hypot(d[0], d[1]))
            if drive <= 1e-6:
                out.append(b)
                continue
            heading = math.atan2(d[1], d[0])
            mid = 0.5 * (a[th] + b[th])
            # drive forwards or backwards, at the driving heading's unwrapped value nearest the turns' middle
            options = [mid + wrap_angle(o - mid) for o in (heading, heading + math.pi)]
            h = min(options, key=lambda o: abs(o - a[th]) + abs(b[th] - o))
            pieces = np.array([abs(h - a[th]) / self.base_turn_speed, drive / self.base_speed,
                               abs(b[th] - h) / self.base_turn_speed])
            s1, s2 = np.cumsum(pieces)[:2] / max(float(pieces.sum()), 1e-12)
            q1, q2 = a + s1 * (b - a), a + s2 * (b - a)
            q1[[x, y]], q1[th] = a[[x, y]], h
            q2[[x, y]], q2[th] = b[[x, y]], h
            out.extend([q1, q2, b])
        return np.asarray(out)

    def execution_path(self, path: np.ndarray) -> np.ndarray:
        """The piecewise-linear configuration path that ``controls_from_path`` executes.

        A differential base cannot move sideways: its segments become turn-drive-turn
        (:meth:`_expand_differential`); every other robot follows the path as it is.
        """
        path = np.asarray(path, dtype=float)
        if self.drive == "differential" and self.base_dofs:
            return self._expand_differential(path)
        return path

    def controls_from_path(self, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nominal per-``dt`` velocity controls following ``path``, and the nominal rollout."""
        path = self.execution_path(path)
        speeds = self._speeds()
        nb = self.n_base_controls
        controls = []
        configs = [path[0].copy()]
        for b in path[1:]:
            a = configs[-1]
            delta = b - a
            steps = max(1, int(math.ceil(float(np.max(np.abs(delta) / speeds)) / self.dt - 1e-9)))
            if not np.any(np.abs(delta) > 1e-12):
                continue
            for k in range(steps):
                q = configs[-1]
                target = a + (k + 1) / steps * delta
                u = np.zeros(nb + len(self.joint_dofs))
                if self.base_dofs:
                    ix, iy, ith = self.base_dofs
                    step_xy = (target[[ix, iy]] - q[[ix, iy]]) / self.dt
                    w = (target[ith] - q[ith]) / self.dt
                    if self.drive == "differential":
                        heading = np.array([math.cos(q[ith]), math.sin(q[ith])])
                        u[:2] = (float(step_xy @ heading), w)
                    else:
                        c, s = math.cos(q[ith]), math.sin(q[ith])
                        u[:3] = (c * step_xy[0] + s * step_xy[1], -s * step_xy[0] + c * step_xy[1], w)
                u[nb:] = (target[self.joint_dofs] - q[self.joint_dofs]) / self.dt
                controls.append(u)
                configs.append(self.propagate(q, u, self.dt))
        nc = nb + len(self.joint_dofs)
        return np.asarray(controls).reshape(-1, nc), np.asarray(configs)

    def rollout(
        self, start: Array, controls: np.ndarray, rng: np.random.Generator | None, noise: bool = True
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Configurations under ``controls`` + truncated noise; (configs, eps, log p(eps))."""
        sigma = self.control_sigma()
        k = len(controls)
        active = self.noise_mask(controls)
        if noise and rng is not None and np.any(sigma > 0):
            eps = truncated_normal(rng, sigma, k, self.truncation) * active
        else:
            eps = np.zeros((k, len(sigma)))
        configs = np.empty((k + 1, self.dof))
        configs[0] = start
        for t in range(k):
            q = self.propagate(configs[t], controls[t] + eps[t], self.dt)
            joints = self.joint_dofs
            q[joints] = np.clip(q[joints], self.lower[joints], self.upper[joints])
            configs[t + 1] = q
        return configs, eps, truncated_normal_logpdf(eps, sigma, self.truncation, active)

    def noise_groups(self) -> list[list[int]]:
        """Controls that err together: the base's (v, omega or vx, vy, omega), each joint alone."""
        nb = self.n_base_controls
        groups = [list(range(nb))] if nb else []
        return groups + [[nb + i] for i in range(len(self.joint_dofs))]

    def noise_mask(self, controls: np.ndarray) -> np.ndarray:
        """(k, nc) True where a control error is sampled: every control of a group (the base, a
        joint) at the steps that command that group to move. A part commanded to stand still
        does not drift (Vasquez-Gomez fitted sigma on executed rotations and translations)."""
        n_controls = self.n_base_controls + len(self.joint_dofs)
        controls = np.asarray(controls, dtype=float).reshape(len(controls), n_controls)  # (0, n) for a plan in place
        moving = np.abs(controls) > 1e-12
        for group in self.noise_groups():
            moving[:, group] = moving[:, group].any(axis=1, keepdims=True)
        return moving

    def execute(
        self,
        plan: MotionPlan | np.ndarray,
        rng: np.random.Generator | None = None,
        noise: bool = True,
        world: str = "true",
    ) -> Execution:
        """Execute a plan with positioning noise; collisions are checked against ``world``.

        Geometric paths are converted to velocity controls (``controls_from_path``); a
        collision is recorded as an event and ends the motion if ``on_collision`` is "stop".
        """
        if isinstance(plan, MotionPlan) and plan.controls is not None:
            start, controls = np.asarray(plan.path[0], dtype=float), plan.controls
        else:
            path = plan.path if isinstance(plan, MotionPlan) else np.asarray(plan, dtype=float)
            start = np.asarray(path[0], dtype=float)
            controls, _ = self.controls_from_path(path)
        configs, eps, log_prob = self.rollout(start, controls, rng, noise)
        events: list[CollisionEvent] = []
        completed = True
        if self.sim is not None and world != "none":
            for step in range(1, len(configs)):
                hits = self.collisions(configs[step], world, 0.0)
                if hits:
                    events.append(CollisionEvent(step, step * self.dt, configs[step].copy(), tuple(hits)))
                    if self.on_collision == "stop":
                        configs, controls, eps = configs[: step + 1], controls[:step], eps[:step]
                        completed = False
                        break
        final = configs[-1].copy()
        self.q = final
        if self.sim is not None:
            self.set_config(final)
        return Execution(
            configs=configs,
            times=np.arange(len(configs)) * self.dt,
            controls=np.asarray(controls),
            noise=eps,
            sigma=self.control_sigma(),
            log_prob=log_prob,
            final=final,
            sensor_pose=self.fk(final),
            collisions=events,
            completed=completed,
        )

    # -- helpers for subclasses --------------------------------------------------------------
    def _world_base(self) -> Array:
        base = getattr(getattr(getattr(self.sim, "spec", None), "robot", None), "base", None)
        return np.zeros(4) if base is None else np.asarray(base, dtype=float)

    def _floor_bounds(self, pad: float = 0.0) -> tuple[Array, Array]:
        """x, y extent of the known environment (bounds of a mobile base)."""
        assert self.sim is not None
        ids = self.sim.environment_ids()
        boxes = np.array([np.ravel(p.getAABB(b, physicsClientId=self.client)) for b in ids])
        lo, hi = boxes[:, :2].min(axis=0) - pad, boxes[:, 3:5].max(axis=0) + pad
        return lo, hi

    def _box_body(self, size: Array, extra: list[tuple[int, list[float], list[float]]] | None = None) -> int:
        """A collision-only multibody (no visual, so cameras never see it) made of boxes etc."""
        shapes = [(p.GEOM_BOX, [s / 2.0 for s in size], [0.0, 0.0, size[2] / 2.0])] + (extra or [])
        kwargs: dict[str, Any] = {
            "shapeTypes": [s[0] for s in shapes],
            "collisionFramePositions": [s[2] for s in shapes],
            "physicsClientId": self.client,
        }
        half, radii, lengths = [], [], []
        for kind, dims, _ in shapes:
            half.append(dims if kind == p.GEOM_BOX else [0.0, 0.0, 0.0])
            radii.append(dims[0] if kind != p.GEOM_BOX else 0.0)
            lengths.append(dims[1] if kind == p.GEOM_CYLINDER else 0.0)
        shape = p.createCollisionShapeArray(halfExtents=half, radii=radii, lengths=lengths, **kwargs)
        return p.createMultiBody(0.0, shape, -1, physicsClientId=self.client)

    def _sensor_housing(self) -> tuple[int, Any]:
        """A collision-only box behind the sensor origin (the sensor's housing)."""
        size = np.asarray(self.sensor_size, dtype=float)
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=(size / 2).tolist(), physicsClientId=self.client)
        body = p.createMultiBody(0.0, shape, -1, physicsClientId=self.client)
        from explore.sim import box_mesh

        mesh = box_mesh(size)
        return body, mesh

    def _place_housing(self, world_T_sensor: Pose) -> None:
        center = world_T_sensor.copy()
        center[:3, 3] -= world_T_sensor[:3, 2] * (self.sensor_size[2] / 2.0)  # housing centre behind the origin
        p.resetBasePositionAndOrientation(
            self._housing, center[:3, 3].tolist(), _quat(center[:3, :3]), physicsClientId=self.client
        )


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

    def __init__(self, robot: _BulletRobot, urdf: str, flange_link: str, base_pose: Pose) -> None:
        self.robot = robot
        client = robot.client
        self.body = p.loadURDF(
            urdf,
            basePosition=base_pose[:3, 3].tolist(),
            baseOrientation=_quat(base_pose[:3, :3]),
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
                _quat(world_T_flange[:3, :3]),
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


class Arm(_BulletRobot):
    """Fixed industrial arm (KUKA iiwa, 7 DOF) with an eye-in-hand sensor; IK with restarts."""

    name = "arm"
    dof = 7
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


class MobileManipulator(_BulletRobot):
    """Planar base (x, y, theta; differential drive) carrying an arm with an eye-in-hand sensor."""

    name = "mobile_manipulator"
    dof = 10
    base_dofs = (0, 1, 2)
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
            _quat(world_T_base[:3, :3]),
            physicsClientId=self.client,
        )
        arm = world_T_base @ self.base_T_arm
        p.resetBasePositionAndOrientation(
            self.chain.body, arm[:3, 3].tolist(), _quat(arm[:3, :3]), physicsClientId=self.client
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


class MobileBase(_BulletRobot):
    """Mobile base with a camera on a mast, optional pan-tilt head (Goerner, Kriegel's omniRob)."""

    name = "mobile_base"
    dof = 5
    base_dofs = (0, 1, 2)
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
            self.body, [q[0], q[1], self.ground_clearance], _quat(pose[:3, :3]), physicsClientId=self.client
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


class FreeFlyer(_BulletRobot):
    """The sensor itself, flying freely (unlimited workspace, as in the thesis benchmark)."""

    name = "free_flyer"
    dof = 6
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
