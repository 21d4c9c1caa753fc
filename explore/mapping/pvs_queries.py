"""Queries of the PVS: probabilities and states of points, ray casting through the grid (first occupied voxel,
entropy, unknown / occupied / frontier counts; IROS 2012 Eq. 1-2), the entropy gain with visited marking (thesis Eq.
4.32), the obstacle grid and distance field the motion planner tests robot points against (thesis Sec. 3.2.2), and the
occupied voxels as points or a mesh."""

from __future__ import annotations

import math

import numpy as np

import explore.mapping.pvs_kernels as K
from explore.core import Array, Points3
from explore.mapping.pvs_grid import (
    FREE,
    OCCUPIED,
    PARALLEL_MIN_RAYS,
    STOP_P,
    THRESHOLDS,
    UNKNOWN,
    RayResult,
    logit,
)
from explore.sim import TriMesh


class PVSQueries:
    """Part of :class:`PVS`: point, ray and free-space queries."""

    # -- point queries -----------------------------------------------------------------
    def probability(self, points: Points3) -> Array:
        """Occupancy probability (n,) of the voxels containing ``points``; 0.5 outside."""
        lo = self.log_odds_at(points).astype(np.float64)
        return 1.0 / (1.0 + np.exp(-lo))

    def probability_below(self, points: Points3, p: float) -> np.ndarray:
        """``probability(points) < p`` (n,) bool: the free-space test motion planning makes for every
        robot pose it samples."""
        return self.probability(points) < p

    def log_odds_at(self, points: Points3) -> np.ndarray:
        """Log-odds (n,) float32 of the voxels containing ``points``; 0 (unknown) outside the grid."""
        ijk, inside = self.index(points)
        lo = np.zeros(len(ijk), dtype=np.float32)
        lo[inside] = self.log_odds[tuple(ijk[inside].T)]
        return lo

    def _classify(self, lo: np.ndarray, thresholds: str) -> np.ndarray:
        if thresholds not in THRESHOLDS:
            raise ValueError(f"unknown thresholds {thresholds!r} (valid: {', '.join(THRESHOLDS)})")
        codes = np.full(lo.shape, UNKNOWN, dtype=np.int8)
        if thresholds == "octomap":
            codes[lo > 0.0] = OCCUPIED
            codes[lo < 0.0] = FREE
            return codes
        free_below, occ_from = THRESHOLDS[thresholds]
        codes[lo >= np.float32(logit(occ_from))] = OCCUPIED
        codes[lo < np.float32(logit(free_below))] = FREE
        return codes

    def state(self, points: Points3, thresholds: str = "planning") -> np.ndarray:
        """State codes (n,) FREE=0 / UNKNOWN=1 / OCCUPIED=2 of the voxels containing ``points``.

        ``thresholds`` names a pair in :data:`THRESHOLDS` (free if p < first, occupied if
        p >= second); "planning" has no unknown class (everything not free is an obstacle),
        "octomap" calls never-updated voxels unknown. Points outside the grid are unknown
        (an obstacle for "planning").
        """
        return self._classify(self.log_odds_at(points), thresholds)

    def states(self, thresholds: str = "validation") -> np.ndarray:
        """State codes of every voxel (grid shape, int8)."""
        return self._classify(self.log_odds, thresholds)

    def count(self, state: int, thresholds: str = "validation") -> int:
        """Number of voxels in the region with the given state code."""
        return int(np.count_nonzero(self.states(thresholds) == state))

    def counts(self, thresholds: str = "validation") -> dict[str, int]:
        """Voxel counts {unknown, free, occupied} in the region (thesis termination, Sec. 3.3.2)."""
        codes = self.states(thresholds)
        return {
            "unknown": int(np.count_nonzero(codes == UNKNOWN)),
            "free": int(np.count_nonzero(codes == FREE)),
            "occupied": int(np.count_nonzero(codes == OCCUPIED)),
        }

    # -- ray queries -------------------------------------------------------------------
    @staticmethod
    def _rays(origins: Points3, directions: Points3, max_range: float | Array) -> tuple:
        d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        o = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64).reshape(-1, 3), d.shape))
        norms = np.linalg.norm(d, axis=1, keepdims=True)
        if np.any(norms == 0.0):
            raise ValueError("ray directions must be non-zero")
        d = np.ascontiguousarray(d / norms)
        r = np.ascontiguousarray(np.broadcast_to(np.asarray(max_range, dtype=np.float64), (len(d),)))
        return o, d, r

    def cast(
        self,
        origins: Points3,
        directions: Points3,
        max_range: float | Array,
        min_range: float = 0.0,
        stop_p: float = STOP_P,
        thresholds: str = "vasquez",
        return_voxels: bool = False,
        parallel: bool | None = None,
    ) -> RayResult:
        """Cast many rays at once (parallel numba DDA).

        Each ray runs from its origin to ``max_range`` and stops after the first voxel with
        p >= ``stop_p``. Entropies (IROS 2012 Eq. 1-2) and counts include only voxels that
        end beyond ``min_range``; counts use ``thresholds`` (see :data:`THRESHOLDS`).
        ``parallel`` (default: batches of at least ``PARALLEL_MIN_RAYS`` rays) runs the rays
        on all cores; results do not depend on it.
        """
        o, d, r = self._rays(origins, directions, max_range)
        if parallel is None:
            parallel = len(d) >= PARALLEL_MIN_RAYS
        kernels = self._ray_kernels()
        kernel = kernels.cast_rays if parallel else kernels.cast_rays_serial
        free_below, occ_from = THRESHOLDS[thresholds]
        args = (
            *self._ray_storage(), o, d, r, float(min_range),
            float(np.float32(logit(stop_p))), float(np.float32(logit(free_below))),
            float(np.float32(logit(occ_from))),
        )
        empty = np.zeros(len(d) + 1, dtype=np.int64)
        hit_t, hit_v, ent, unk, occ, fr, visits = kernel(*args, empty, empty[:0], False)
        offsets = ids = None
        if return_voxels:
            offsets = np.concatenate([[0], np.cumsum(visits)]).astype(np.int64)
            ids = np.empty(int(offsets[-1]), dtype=np.int64)
            kernel(*args, offsets, ids, True)
        hit_voxel = np.full((len(d), 3), -1, dtype=np.int64)
        hit = hit_v >= 0
        if hit.any():
            hit_voxel[hit] = np.column_stack(np.unravel_index(hit_v[hit], self.shape))
        return RayResult(hit_t, hit_voxel, ent, unk, occ, fr, visits, self.shape, offsets, ids)

    def _ray_kernels(self):  # noqa: ANN202 - the kernel module
        """The module with the ray kernels of this storage (``cast_rays``, ``cast_rays_serial``)."""
        return K

    def _ray_storage(self) -> tuple:
        """The leading arguments of the ray kernels: the storage and the grid's geometry."""
        return self.log_odds, self.lattice, self.resolution

    def non_free_count(self) -> int:
        """N_v of thesis Eq. 4.32: voxels that are not free (p >= 0.05)."""
        cached = self._cache.get("n_v")
        if cached is None or cached[0] != self.version:
            value = int(np.count_nonzero(self.log_odds >= np.float32(logit(THRESHOLDS["planning"][0]))))
            self._cache["n_v"] = (self.version, value)
            return value
        return cached[1]

    def entropy_gain(
        self,
        origins: Points3,
        directions: Points3,
        max_range: float | Array,
        visited: bool = True,
        normalize: bool = False,
        min_range: float = 0.0,
        stop_p: float = STOP_P,
        return_stats: bool = False,
    ) -> float | tuple[float, dict[str, int]]:
        """Information gain of one candidate: entropy along its beams (IROS 2012 Eq. 1-2).

        IG = sum over beams, sum over voxels crossed until the first voxel with
        p >= ``stop_p`` (included), of H(p) in bits. With ``visited`` a voxel counts once per
        candidate however many beams cross it (thesis Sec. 4.5.3); with ``normalize`` the
        sum is divided by the number of non-free voxels N_v (thesis Eq. 4.32, e_v).
        ``return_stats`` adds {"visits", "voxels"} (voxel visits, voxels counted). The
        visited marks live in the PVS: do not call this from several threads at once.
        """
        o, d, r = self._rays(origins, directions, max_range)
        l_stop = float(np.float32(logit(stop_p)))
        if visited:
            total, voxels, visits = self._entropy_visited(o, d, r, float(min_range), l_stop)
        else:
            result = self.cast(o, d, r, min_range=min_range, stop_p=stop_p)
            total = float(result.entropy.sum())
            visits = int(result.visits.sum())
            voxels = visits
        value = float(total)
        if normalize:
            value /= max(self.non_free_count(), 1)
        if return_stats:
            return value, {"visits": int(visits), "voxels": int(voxels)}
        return value

    def _entropy_visited(self, o: Points3, d: Points3, r: Array, min_range: float, l_stop: float) -> tuple:
        """(entropy sum, voxels counted, voxel visits) of one candidate's beams, each voxel counted once."""
        if self._visited is None or self._visited.shape != self.shape or self._visit_stamp >= 2**31 - 2:
            self._visited = np.zeros(self.shape, dtype=np.int32)
            self._visit_stamp = 0
        self._visit_stamp += 1
        return K.entropy_visited(self.log_odds, self._visited, self._visit_stamp, self.lattice, self.resolution,
                                 o, d, r, min_range, l_stop)

    # -- planning support --------------------------------------------------------------
    def obstacle_grid(self, free_below: float = THRESHOLDS["planning"][0]) -> np.ndarray:
        """Boolean grid: True where p >= ``free_below`` (unknown counts as an obstacle)."""
        return self.log_odds >= np.float32(logit(free_below))

    def distance_field(self) -> np.ndarray:
        """Metres from each voxel centre to the nearest non-free voxel centre (0 on obstacles).

        Unknown is an obstacle (planning threshold p < 0.05 free). Cells outside the grid do
        not count as obstacles. Cached until the next update.
        """
        cached = self._cache.get("edt")
        if cached is not None and cached[0] == self.version:
            return cached[1]
        field = obstacle_distance(self.obstacle_grid(), self.resolution)
        self._cache["edt"] = (self.version, field)
        return field

    def is_free(self, points: Points3, clearance: float = 0.0, outside_free: bool = True) -> np.ndarray:
        """True for points whose voxel is free and at least ``clearance`` from any obstacle voxel.

        The clearance test is d_field(voxel) - (sqrt(3)/2) l_v >= clearance: the distance
        field is measured between voxel centres, and the point may sit anywhere in its
        voxel. Points outside the grid are free if ``outside_free`` (the PVS only covers
        the region of interest; the known environment is checked elsewhere).
        """
        ijk, inside = self.index(points)
        out = np.full(len(ijk), bool(outside_free))
        field = self.distance_field()
        dist = field[tuple(ijk[inside].T)]
        out[inside] = (dist > 0.0) & (dist - 0.5 * math.sqrt(3.0) * self.resolution >= clearance)
        return out

    # -- export ------------------------------------------------------------------------
    def occupied_points(self, p_min: float = 0.75) -> Points3:
        """Centres (n, 3) of the voxels with p >= ``p_min``."""
        ijk = np.argwhere(self.log_odds >= np.float32(logit(p_min)))
        return self.centers(ijk)

    def voxel_mesh(self, p_min: float = 0.75) -> TriMesh:
        """Closed surface of the voxels with p >= ``p_min`` (only faces between occupied and not)."""
        occ = np.pad(self.log_odds >= np.float32(logit(p_min)), 1)
        corners_of_face = {
            0: np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]),
            1: np.array([[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]),
            2: np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
        }
        quads = []
        for axis in range(3):
            for sign in (-1, 1):
                neighbour = np.roll(occ, -sign, axis=axis)
                ijk = np.argwhere(occ & ~neighbour)
                if not len(ijk):
                    continue
                base = ijk.copy()
                if sign > 0:
                    base[:, axis] += 1
                quad = base[:, None, :] + corners_of_face[axis][None]
                if sign < 0:
                    quad = quad[:, ::-1]  # outward orientation
                quads.append(quad)
        if not quads:
            return TriMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32))
        corners = np.concatenate(quads).reshape(-1, 3)
        unique, inverse = np.unique(corners, axis=0, return_inverse=True)
        q = inverse.reshape(-1, 4)
        triangles = np.vstack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]).astype(np.int32)
        vertices = (unique - 1 + self.lattice) * self.resolution
        return TriMesh(vertices.astype(np.float64), triangles)


def obstacle_distance(obstacle: np.ndarray, resolution: float) -> np.ndarray:
    """Metres from each voxel centre of a boolean obstacle grid to the nearest obstacle voxel centre
    (0 on obstacles, inf everywhere without any)."""
    if not obstacle.any():
        return np.full(obstacle.shape, np.inf)
    from scipy.ndimage import distance_transform_edt

    return distance_transform_edt(~obstacle, sampling=resolution)
