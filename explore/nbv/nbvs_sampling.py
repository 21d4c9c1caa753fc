"""Sampling and filtering view/states (Vasquez-Gomez Sec. A8): states whose sensor ray hits the region, then the
filter pipeline in the paper's order, cheapest first (collision, visibility, registration overlap h (Eq. 5), surface
factor (Eq. 6), top k), and the next round when none is feasible."""

from __future__ import annotations

import math

import numpy as np

from explore.core import FAILURE, Array, Pose
from explore.motion import (
    box_distance,
)
from explore.nbv.candidates import Candidate
from explore.nbv.view_states import ViewState


class StateSampling:
    """Part of :class:`NBVSSession`: the first view, state sampling and the filter pipeline."""

    # -- steps -------------------------------------------------------------------------------
    def _sees_region(self, eye: Array) -> bool:
        """Lines of sight from ``eye`` to the region's centre and (5 % inset) corners miss the known
        environment (sampled every 1 cm against its boxes)."""
        lo, hi = self.region_min, self.region_max
        a, b = lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo)
        corners = np.array([[x, y, z] for x in (a[0], b[0]) for y in (a[1], b[1]) for z in (a[2], b[2])])
        for target in np.vstack([0.5 * (lo + hi), corners]):
            ray = target - eye
            steps = np.linspace(0.0, 1.0, int(np.linalg.norm(ray) / 0.01) + 2)[:, None]
            if np.any(box_distance(eye + steps * ray, self.obstacles.lo, self.obstacles.hi) <= 0.0):
                return False
        return True

    def first_view(self, attempts: int = 3000) -> Pose:
        """The first, exactly known state (Sec. A2 step 1): no motion; its sensor pose.

        The start base is kept; arm configurations are sampled and the one whose optical axis
        points most directly at the region centre from 0.4-1.2 m, with lines of sight to the
        region's centre and corners past the known environment (a view from below the table
        top sees the table) and collision-free in the known environment and the all-unknown
        PVS, is taken; one from above the region's top first, if any: a camera level with the
        table top sees the object's lower side and the table at grazing incidence, and then no
        sampled state overlaps what it saw (a teddy: 310 occupied voxels, no state passed the
        registration overlap h and the run ended after its first view).
        """
        robot, q0 = self.robot, self.q.copy()
        centre = 0.5 * (self.region_min + self.region_max)
        joints = robot.joint_dofs
        best, best_q = (False, -np.inf), q0  # (from above the region's top, alignment with the centre)
        for _ in range(attempts):
            q = q0.copy()
            q[joints] = self.rng_sample.uniform(robot.lower[joints], robot.upper[joints])
            pose = robot.fk(q)
            ray = centre - pose[:3, 3]
            dist = float(np.linalg.norm(ray))
            if not 0.4 <= dist <= 1.2:
                continue
            value = (bool(pose[2, 3] >= self.region_max[2]), float(ray @ pose[:3, 2]) / dist)
            if value <= best:
                continue
            if not self._sees_region(pose[:3, 3]):
                continue
            if not robot.in_collision(q, "known") and np.all(self.obstacles.clearance(robot.link_points(q)) >= 0.0):
                best, best_q = value, q
        if best[1] == -np.inf:
            self.status, self.reason, self.outcome = "failed", \
                f"no first view sees the region ({attempts} arm samples tried)", FAILURE
        self.q = best_q
        robot.q = best_q.copy()
        robot.set_config(best_q)
        self.stand()
        return robot.fk(best_q)

    def _ray_hits(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Director rays (origins, directions (n, 3)) hit the region box within range (slab test)."""
        o, d = origins, directions
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / np.where(np.abs(d) < 1e-12, 1e-12, d)
            t1, t2 = (self.region_min - o) * inv, (self.region_max - o) * inv
        near = np.minimum(t1, t2).max(axis=1)
        far = np.maximum(t1, t2).min(axis=1)
        return (far >= np.maximum(near, 0.0)) & (near <= float(self.sensor.max_range))

    def _may_hit_slab(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Rays that reach the region's height band [z_min, z_max] within range: a base pose
        (planar) never changes that, so other arm samples need no base samples at all."""
        oz, dz = origins[:, 2], directions[:, 2]
        zlo, zhi = self.region_min[2], self.region_max[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (zlo - oz) / dz, (zhi - oz) / dz
        flat = np.abs(dz) < 1e-12
        t_in = np.where(flat, 0.0, np.maximum(np.minimum(ta, tb), 0.0))
        t_out = np.where(flat, np.where((oz >= zlo) & (oz <= zhi), np.inf, -np.inf), np.maximum(ta, tb))
        return (t_out >= t_in) & (t_in <= float(self.sensor.max_range))

    def sample(self) -> list[ViewState]:
        """Uniform states until ``n_samples`` of them aim the director ray at the region (Sec. A8.1).

        States are drawn uniformly in the state space (joint limits, heading in [-pi, pi));
        a state is kept if the sensor's optical axis hits the region box within range, until
        ``n_samples`` are kept or ``max_draws`` were drawn (``stages['sampled']`` counts the
        draws, ``stages['ray_hits']`` the kept). For a planar base the sensor pose is
        world_T_base(x, y, theta) @ fk(0, 0, 0, arm), so each FK call of an arm sample serves
        ``bases_per_arm`` uniform base samples (every state is still uniform in the state
        space; a group shares its arm joints), and an arm whose ray never reaches the region's
        height band within range is rejected with all its base samples (counted as drawn).
        """
        robot = self.robot
        lo, hi = np.asarray(robot.lower, dtype=float).copy(), np.asarray(robot.upper, dtype=float).copy()
        base = list(robot.base_dofs)
        if base:
            lo[base[2]], hi[base[2]] = -math.pi, math.pi
        rng = self.rng_sample
        kept_q: list[np.ndarray] = []
        kept_pose: list[np.ndarray] = []
        drawn, kept = 0, 0
        while kept < self.n_samples and drawn < self.max_draws:
            self.progress(f"sampling states: {kept} of {self.n_samples} aim at the region ({drawn} drawn)")
            if base:
                group, arms = self.bases_per_arm, 64
                qs = rng.uniform(lo, hi, size=(arms, len(lo)))
                refs = qs.copy()
                refs[:, base] = 0.0
                local = np.array([robot.fk(q) for q in refs])  # base_T_sensor of each arm sample
                drawn += arms * group
                alive = np.flatnonzero(self._may_hit_slab(local[:, :3, 3], local[:, :3, 2]))
                if len(alive) == 0:
                    continue
                arm = np.repeat(alive, group)
                states = qs[arm]
                states[:, base] = rng.uniform(lo[base], hi[base], size=(len(arm), 3))
                x, y, th = states[:, base[0]], states[:, base[1]], states[:, base[2]]
                c, s = np.cos(th)[:, None], np.sin(th)[:, None]
                o_b, d_b = local[arm, :3, 3], local[arm, :3, 2]
                origins = np.column_stack([c[:, 0] * o_b[:, 0] - s[:, 0] * o_b[:, 1] + x,
                                           s[:, 0] * o_b[:, 0] + c[:, 0] * o_b[:, 1] + y, o_b[:, 2]])
                directions = np.column_stack([c[:, 0] * d_b[:, 0] - s[:, 0] * d_b[:, 1],
                                              s[:, 0] * d_b[:, 0] + c[:, 0] * d_b[:, 1], d_b[:, 2]])
                hit = np.flatnonzero(self._ray_hits(origins, directions))
                for index in hit:
                    world_T_base = np.eye(4)
                    world_T_base[:2, :2] = [[c[index, 0], -s[index, 0]], [s[index, 0], c[index, 0]]]
                    world_T_base[:2, 3] = x[index], y[index]
                    kept_q.append(states[index])
                    kept_pose.append(world_T_base @ local[arm[index]])
            else:
                batch = 256
                qs = rng.uniform(lo, hi, size=(batch, len(lo)))
                poses = np.array([robot.fk(q) for q in qs])
                drawn += batch
                for index in np.flatnonzero(self._ray_hits(poses[:, :3, 3], poses[:, :3, 2])):
                    kept_q.append(qs[index])
                    kept_pose.append(poses[index])
            kept = len(kept_q)
        kept_q, kept_pose = kept_q[: self.n_samples], kept_pose[: self.n_samples]
        self.stages = {"sampled": drawn, "ray_hits": len(kept_q)}
        return [ViewState(q, pose) for q, pose in zip(kept_q, kept_pose, strict=True)]

    def filter(self, states: list[ViewState]) -> list[ViewState]:
        """Collision -> visibility -> registration (h) -> surface -> top ``top`` by sur.

        The surface stage keeps candidates that see at least ``min_unknown`` unknown voxels
        (the paper's stop criterion "surface factor below a threshold", 30 voxels on the
        real robot, applied as a filter: the run stops when no candidate passes).
        """
        self.progress(f"collision check of {len(states)} states")
        free = [s for s in states if self.problem.is_valid(s.q)]
        self.stages["collision_free"] = len(free)
        if free:
            self.progress(f"visibility of {len(free)} collision-free states")
            cands = [Candidate(s.pose, "nbvs") for s in free]
            self.visibility.score(cands, self.ctx)
            for s, c in zip(free, cands, strict=True):
                s.occ, s.unk = c.diagnostics["occupied_first"], c.diagnostics["unknown_first"]
                s.reg, s.sur, s.pos = c.diagnostics["reg"], c.diagnostics["sur"], c.diagnostics["pos"]
        visible = [s for s in free if s.occ + s.unk > 0 and s.pos > 0]
        self.stages["visible"] = len(visible)
        registered = [s for s in visible if s.reg > 0]
        self.stages["registration"] = len(registered)
        surface = [s for s in registered if s.sur > 0 and s.unk >= self.min_unknown]
        self.stages["surface"] = len(surface)
        self.ranked, self.tried = sorted(surface, key=lambda s: -s.sur), 0
        self.stages["planned"] = self.stages["feasible"] = self.stages["rounds"] = 0
        return self.next_round()

    def next_round(self) -> list[ViewState]:
        """The next ``top`` candidates by sur (Sec. A8.7: the paper plans the top 25 once).

        When none of a round is feasible (EU rejects the close views whose noisy reach hits
        the unknown region), the next ``top`` are tried, up to ``rounds`` rounds; an empty list
        when they are used up.
        """
        if self.stages.get("rounds", 0) >= self.rounds:
            return []
        chosen = self.ranked[self.tried : self.tried + self.top]
        self.tried += len(chosen)
        if chosen:
            self.stages["rounds"] = self.stages.get("rounds", 0) + 1
            self.stages["top"] = self.tried
        return chosen
