"""A robot made of pybullet bodies: parts and their collision checks, points on the links (for the PVS
free-space test), velocity controls from paths, and noisy execution (Vasquez-Gomez Sec. A6: velocity controls
with truncated Gaussian errors, Euler-integrated every dt), each executed configuration checked against the TRUE
world. The built-in robot plugins subclass it; so can a third party's."""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, quaternion_xyzw, wrap_angle
from explore.motion.collision import BulletCollider, Part
from explore.motion.noise import STILL, truncated_normal, truncated_normal_logpdf
from explore.motion.records import CollisionEvent, Execution, MotionPlan
from explore.motion.robot import Robot
from explore.sim import body_aabb, box_mesh, cylinder_mesh, frame_pose, p, read_mesh, sphere_mesh


def _surface_samples(vertices: Array, triangles: np.ndarray, spacing: float) -> Points3:
    """Points on a mesh surface about ``spacing`` apart (area sampling, voxel thinning)."""
    if len(triangles) == 0:
        return np.zeros((0, 3))
    tri = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    count = int(min(20000, max(50, 8 * area.sum() / spacing**2)))
    rng = np.random.default_rng(0)
    total = area.sum()
    pick = rng.choice(len(tri), size=count, p=area / total if total > 0 else None)  # a degenerate mesh: uniform
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[pick]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    points = np.vstack([points, vertices])
    _, keep = np.unique(np.floor(points / spacing).astype(np.int64), axis=0, return_index=True)
    return points[np.sort(keep)]


class BulletRobot(Robot):
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
        self.parts: list[Part] = []
        self.collider: BulletCollider | None = None
        self._local_points: list[tuple[Part, Points3]] = []
        self._points_at: dict[float, list[tuple[Part, Points3]]] = {}
        self._com_offset: dict[int, Pose] = {}
        self._state: Array | None = None
        self._sample_gap: float | None = None

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

    @abstractmethod
    def _set_state(self, q: Array) -> None:
        """Move the pybullet bodies to ``q`` (uncached; :meth:`set_config` caches)."""

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
        self._sample_gap = None

    @property
    def sample_gap(self) -> float:
        """Measured once: the largest distance from a dense sampling of each part's surface (a sixth
        of ``point_spacing`` apart) to the part's nearest link point (about 1.1 x ``point_spacing``)."""
        if self._sample_gap is None:
            from scipy.spatial import cKDTree

            dense = self._part_point_sets(self.point_spacing / 6.0)
            gap = 0.0
            for (_, sparse), (_, fine) in zip(self._local_points, dense, strict=True):
                if len(sparse) and len(fine):
                    gap = max(gap, float(cKDTree(sparse).query(fine)[0].max()))
            self._sample_gap = gap
        return self._sample_gap

    def _part_point_sets(self, spacing: float) -> list[tuple[Part, Points3]]:
        """(part, points in its link frame) on every part's visual geometry and extra meshes."""
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

    def distance(self, a: Array, b: Array) -> float:
        """Weighted configuration distance (Vasquez-Gomez Eq. 8): sqrt(sum_j w_j (a_j - b_j)^2)."""
        d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
        return float(np.sqrt(np.sum(np.asarray(self.weights) * d * d)))

    # -- controls and execution --------------------------------------------------------------
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
                u[np.abs(u) < STILL] = 0.0  # round-off, not a command: a part standing still does not err
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
        groups = self.noise_groups()
        member = np.zeros((len(groups), n_controls))  # (groups, controls)
        for g, group in enumerate(groups):
            member[g, group] = 1.0
        moving = np.abs(controls) > STILL
        grouped = member.any(axis=0)
        moving[:, grouped] = ((moving @ member.T) @ member)[:, grouped] > 0.0
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
        boxes = np.array([np.ravel(body_aabb(b, self.client)) for b in ids])
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
        mesh = box_mesh(size)
        return body, mesh

    def _place_housing(self, world_T_sensor: Pose) -> None:
        center = world_T_sensor.copy()
        center[:3, 3] -= world_T_sensor[:3, 2] * (self.sensor_size[2] / 2.0)  # housing centre behind the origin
        p.resetBasePositionAndOrientation(
            self._housing, center[:3, 3].tolist(), quaternion_xyzw(center[:3, :3]), physicsClientId=self.client
        )
