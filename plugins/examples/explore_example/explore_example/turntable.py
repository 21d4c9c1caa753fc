"""The classic object-modelling rig: the object turns on a turntable, the sensor rides a rail.

The world stays still in the simulation, so turning the object by theta is the sensor
orbiting the turntable axis by -theta. Configuration q = (theta rad, z m, r m, tilt rad): the
turntable angle, the sensor's height on the vertical rail, its distance from the axis on a
horizontal slide, and its tilt (positive looks down). The camera always faces the axis and
never rolls.
"""

from __future__ import annotations

import math

import numpy as np

from explore.api import (
    Array,
    CollisionEvent,
    Execution,
    MotionPlan,
    Param,
    Points3,
    Pose,
    Robot,
    Simulation,
    look_at,
    wrap_angle,
)


class Turntable(Robot):
    """Turntable + vertical rail + slide + tilt (4 DOF): the object turns, the sensor faces the axis."""

    name = "turntable"
    dof = 4
    params = (
        Param("axis", list, [0.0, 0.0], "m", "the turntable axis (x, y) in the world", length=2),
        Param("z_limits", list, [0.3, 1.2], "m", "travel of the vertical rail", length=2),
        Param("r_limits", list, [0.3, 0.9], "m", "travel of the slide (distance from the axis)", length=2),
        Param("tilt_limits_deg", list, [-30.0, 75.0], "deg", "tilt range (positive looks down)", length=2),
        Param("aim_tolerance_deg", float, 25.0, "deg", "IK accepts a goal whose heading misses the axis by this",
              low=0.0, high=90.0),
        Param("speeds", list, [0.8, 0.1, 0.1, 0.5], "rad/s, m/s", "speed of each joint", length=4),
        Param("clearance", float, 0.03, "m", "the sensor keeps this far from every box", low=0.0),
        Param("dt", float, 0.05, "s", "control period", low=1e-3),
    )

    def __init__(self, **values: object) -> None:
        super().__init__(**values)
        self.lower = np.array([-math.pi, self.z_limits[0], self.r_limits[0], math.radians(self.tilt_limits_deg[0])])
        self.upper = np.array([math.pi, self.z_limits[1], self.r_limits[1], math.radians(self.tilt_limits_deg[1])])
        self.q = np.array([0.0, self.lower[1], self.upper[2], 0.0])

    def attach(self, sim: Simulation) -> None:
        super().attach(sim)
        self.q = np.array([0.0, float(np.clip(sim.spec.region_max[2], *self.z_limits)),
                           float(np.mean(self.r_limits)), math.radians(20.0)])

    # -- kinematics ----------------------------------------------------------------------------
    def fk(self, q: Array) -> Pose:
        theta, z, r, tilt = (float(v) for v in q)
        phi = -theta  # the object turns by theta: the sensor orbits it by -theta
        eye = np.array([self.axis[0] + r * math.cos(phi), self.axis[1] + r * math.sin(phi), z])
        forward = np.array([-math.cos(phi) * math.cos(tilt), -math.sin(phi) * math.cos(tilt), -math.sin(tilt)])
        return look_at(eye, eye + forward)

    def ik(self, world_T_sensor: Pose, rng: np.random.Generator | None = None) -> Array | None:
        """Exact in position; the heading must face the axis within ``aim_tolerance_deg`` (no pan, no roll)."""
        eye, forward = world_T_sensor[:3, 3], world_T_sensor[:3, 2]
        offset = eye[:2] - np.asarray(self.axis, dtype=float)
        r = float(np.linalg.norm(offset))
        horizontal = float(np.linalg.norm(forward[:2]))
        if r < 1e-6 or horizontal < 1e-6:
            return None
        miss = math.acos(float(np.clip(-(offset @ forward[:2]) / (r * horizontal), -1.0, 1.0)))
        if math.degrees(miss) > self.aim_tolerance_deg:
            return None
        q = np.array([wrap_angle(-math.atan2(offset[1], offset[0])), eye[2], r, math.atan2(-forward[2], horizontal)])
        if not self.within_limits(q) or self.in_collision(q):
            return None
        return q

    def distance(self, a: Array, b: Array) -> float:
        """Joint-space distance with the turntable angle wrapped."""
        d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
        d[0] = wrap_angle(d[0])
        return float(np.linalg.norm(d))

    # -- the simulation ------------------------------------------------------------------------
    def set_config(self, q: Array) -> None:
        """The rig has no bodies in the simulation: the sensor is a point kept ``clearance`` from every box."""

    def _hits(self, q: Array, world: str, margin: float) -> list[str]:
        eye = self.fk(q)[:3, 3]
        bodies = [] if self.sim is None else [b for b in self.sim.bodies if world == "true" or not b.is_object]
        return [b.name for b in bodies
                if np.all(eye >= np.asarray(b.mesh.bounds[0]) - margin) and np.all(eye <= np.asarray(b.mesh.bounds[1])
                                                                             + margin)]

    def in_collision(self, q: Array, world: str = "known", margin: float | None = None) -> bool:
        return bool(self._hits(q, world, self.clearance if margin is None else margin))

    def link_points(self, q: Array, within: tuple[Array, Array] | None = None, pad: float = 0.05,
                    spacing: float | None = None) -> Points3:
        eye = self.fk(q)[:3, 3][None]
        if within is not None and not (np.all(eye >= within[0] - pad) and np.all(eye <= within[1] + pad)):
            return np.zeros((0, 3))
        return eye

    # -- execution -----------------------------------------------------------------------------
    def controls_from_path(self, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint velocities held ``dt`` s each, every joint at most its speed; the configurations."""
        path = np.asarray(path, dtype=float)
        speeds = np.asarray(self.speeds, dtype=float)
        controls, configs = [], [path[0]]
        for a, b in zip(path[:-1], path[1:], strict=True):
            delta = b - a
            delta[0] = wrap_angle(delta[0])
            steps = max(1, math.ceil(float(np.max(np.abs(delta) / speeds)) / self.dt - 1e-9))
            for _ in range(steps):
                controls.append(delta / (steps * self.dt))
                configs.append(configs[-1] + delta / steps)
        return np.asarray(controls).reshape(-1, self.dof), np.asarray(configs)

    def execute(self, plan: MotionPlan | np.ndarray, rng: np.random.Generator | None = None, noise: bool = True,
                world: str = "true") -> Execution:
        """Exact execution (a turntable and rails do not drift); collisions against ``world`` end the motion."""
        path = plan.path if isinstance(plan, MotionPlan) else np.asarray(plan, dtype=float)
        controls, configs = self.controls_from_path(path)
        events: list[CollisionEvent] = []
        for step in range(1, len(configs)):
            hits = self._hits(configs[step], world, 0.0) if world != "none" else []
            if hits:
                events.append(CollisionEvent(step, step * self.dt, configs[step].copy(), tuple(hits)))
                configs, controls = configs[: step + 1], controls[:step]
                break
        configs[:, 0] = [wrap_angle(t) for t in configs[:, 0]]
        self.q = configs[-1].copy()
        zeros = np.zeros_like(controls)
        return Execution(configs=configs, times=np.arange(len(configs)) * self.dt, controls=controls, noise=zeros,
                         sigma=np.zeros(self.dof), log_prob=0.0, final=self.q.copy(), sensor_pose=self.fk(self.q),
                         collisions=events, completed=not events)
