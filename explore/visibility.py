"""Simulated candidate beams through a voxel grid: the view-evaluation core of the utilities.

One numba kernel walks every beam of every candidate through a dense snapshot of the PVS
(Amanatides-Woo traversal) and accumulates, per candidate, every quantity the utility
plugins need, so that one pass serves all of them:

============  ==========================================================================
index         quantity
============  ==========================================================================
ENTROPY       sum of voxel entropies until the first voxel with p >= p_stop (IROS Eq. 1-2,
              thesis Eq. 4.32 before the 1/N_v normalisation)
UNKNOWN       unknown voxels traversed (Wong's unknown-voxel count)
QUAL_LIT      sum of q_i = lambda b_i + (1 - lambda) d_i over feature voxels seen at an
              incidence below the cut-off (thesis Eq. 4.33, literal sign)
QUAL_NEED     sum of lambda b_i + (1 - lambda)(1 - d_i) (the "need" variant of Eq. 4.33)
TRAVERSED     voxels traversed (denominator of the average entropy)
OCC_FIRST     distinct occupied voxels hit first by a beam (Vasquez-Gomez oc_o)
UNK_FIRST     distinct unknown voxels hit first by a beam (Vasquez-Gomez un_o)
OCCLUSION     sum of P_v(x) H(x) (Isler et al. 2016 occlusion-aware)
UNOBSERVED    sum of P_v(x) [x unknown] (unobserved voxel)
REAR_VOXEL    unknown voxels directly behind the first occupied voxel (rear side voxel)
REAR_ENTROPY  sum of P_v H of those rear-side voxels (rear side entropy)
PROXIMITY     sum of P_v [x unknown] w(x), w = exp(-distance to occupied / sigma)
HITS          beams that end on an occupied voxel
============  ==========================================================================

P_v(x) = prod of (1 - p) over the voxels in front of x (Isler's visibility probability).
With ``visited`` the traversal quantities count every voxel once per candidate (thesis
Sec. 4.5.3 visited marking); the first-hit and rear-side counts are always distinct.

Hierarchical ray tracing (Vasquez-Gomez Sec. HRT) is offered as a speed option: beams are
grouped into bundles of ``2**a`` neighbours; the bundle's central beam is traced through a
max-pooled grid ``2**a`` times coarser, and only bundles that touch a non-free coarse voxel
are traced at full resolution (free voxels carry almost no information).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .typed import Array, Points3

ENTROPY, UNKNOWN, QUAL_LIT, QUAL_NEED, TRAVERSED, OCC_FIRST, UNK_FIRST = range(7)
OCCLUSION, UNOBSERVED, REAR_VOXEL, REAR_ENTROPY, PROXIMITY, HITS = range(7, 13)
N_ACC = 13
LN2 = math.log(2.0)
ACC_NAMES = (
    "entropy", "unknown", "quality_literal", "quality_need", "traversed", "occupied_first",
    "unknown_first", "occlusion_aware", "unobserved", "rear_voxel", "rear_entropy", "proximity", "hits",
)


@dataclass
class VoxelGrid:
    """Dense snapshot of the PVS and of the surface features stored in it.

    ``prob`` (nx, ny, nz) float32 occupancy; feature arrays have the same shape
    (``normal`` has a trailing 3); ``origin`` is the min corner, ``resolution`` the edge.
    """

    prob: np.ndarray
    origin: Array
    resolution: float
    has_feature: np.ndarray | None = None
    border: np.ndarray | None = None
    density: np.ndarray | None = None
    normal: np.ndarray | None = None
    proximity: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.prob.shape)  # type: ignore[return-value]

    def centres(self) -> Points3:
        """World coordinates of every voxel centre, C order (n, 3)."""
        idx = np.indices(self.shape).reshape(3, -1).T
        return self.origin + (idx + 0.5) * self.resolution

    def index_of(self, points: Points3) -> tuple[np.ndarray, np.ndarray]:
        """Integer voxel indices (n, 3) of ``points`` and a mask of those inside the grid."""
        ijk = np.floor((np.asarray(points) - self.origin) / self.resolution).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < np.asarray(self.shape)), axis=1)
        return ijk, inside

    def lookup(self, points: Points3, outside: float = 0.0) -> Array:
        """Occupancy at ``points`` (``outside`` for points outside the grid)."""
        ijk, inside = self.index_of(points)
        out = np.full(len(ijk), outside, dtype=np.float64)
        out[inside] = self.prob[ijk[inside, 0], ijk[inside, 1], ijk[inside, 2]]
        return out

    def ensure_features(self) -> None:
        """Fill missing feature arrays with 'no feature'."""
        if self.has_feature is None:
            self.has_feature = np.zeros(self.shape, dtype=np.bool_)
            self.border = np.zeros(self.shape, dtype=np.float32)
            self.density = np.zeros(self.shape, dtype=np.float32)
            self.normal = np.zeros(self.shape + (3,), dtype=np.float32)

    def ensure_proximity(self, p_occupied: float = 0.75, sigma: float = 0.01) -> None:
        """w(x) = exp(-d(x)/sigma), d = distance to the nearest occupied voxel (proximity count)."""
        if self.proximity is not None:
            return
        from scipy.ndimage import distance_transform_edt

        occupied = self.prob >= p_occupied
        if not occupied.any():
            self.proximity = np.zeros(self.shape, dtype=np.float32)
            return
        dist = distance_transform_edt(~occupied) * self.resolution
        self.proximity = np.exp(-dist / sigma).astype(np.float32)

    def coarse(self, level: int) -> VoxelGrid:
        """Grid ``2**level`` times coarser holding the max 'non-freeness' of its children."""
        k = 2**level
        nx, ny, nz = self.shape
        pad = [(0, (-n) % k) for n in (nx, ny, nz)]
        p = np.pad(self.prob, pad, constant_values=0.0)
        s = p.shape
        pooled = p.reshape(s[0] // k, k, s[1] // k, k, s[2] // k, k).max(axis=(1, 3, 5))
        return VoxelGrid(pooled.astype(np.float32), self.origin.copy(), self.resolution * k)


@njit(cache=True)
def _entropy(p: float) -> float:
    if p <= 1e-9 or p >= 1.0 - 1e-9:
        return 0.0
    x = float(p)
    return -(x * math.log(x) + (1.0 - x) * math.log(1.0 - x)) / LN2


@njit(cache=True)
def _box_interval(o0, o1, o2, d0, d1, d2, lo0, lo1, lo2, hi0, hi1, hi2):  # noqa: ANN001, ANN202
    t0 = -1e30
    t1 = 1e30
    for o, d, lo, hi in ((o0, d0, lo0, hi0), (o1, d1, lo1, hi1), (o2, d2, lo2, hi2)):
        if abs(d) < 1e-12:
            if o < lo or o > hi:
                return 1.0, 0.0
        else:
            a = (lo - o) / d
            b = (hi - o) / d
            if a > b:
                a, b = b, a
            if a > t0:
                t0 = a
            if b < t1:
                t1 = b
    return t0, t1


@njit(cache=True)
def _trace_kernel(
    prob, has_feat, border, density, normal, prox, origin, res,
    origins, dirs, group, n_groups, tmin, tmax,
    p_stop, unk_lo, unk_hi, cos_cut, lam, visited, out,
):  # noqa: ANN001, ANN202
    nx, ny, nz = prob.shape
    stamp_t = np.zeros((nx, ny, nz), dtype=np.int32)
    stamp_f = np.zeros((nx, ny, nz), dtype=np.int32)
    hi0 = origin[0] + nx * res
    hi1 = origin[1] + ny * res
    hi2 = origin[2] + nz * res
    for r in range(origins.shape[0]):
        g = group[r]
        tag = g + 1
        o0, o1, o2 = origins[r, 0], origins[r, 1], origins[r, 2]
        d0, d1, d2 = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        t0, t1 = _box_interval(o0, o1, o2, d0, d1, d2, origin[0], origin[1], origin[2], hi0, hi1, hi2)
        if t0 < 0.0:
            t0 = 0.0
        if t1 > tmax:
            t1 = tmax
        if t0 >= t1:
            continue
        # start voxel
        t = t0 + 1e-9
        px = o0 + d0 * t
        py = o1 + d1 * t
        pz = o2 + d2 * t
        i = min(max(int(np.floor((px - origin[0]) / res)), 0), nx - 1)
        j = min(max(int(np.floor((py - origin[1]) / res)), 0), ny - 1)
        k = min(max(int(np.floor((pz - origin[2]) / res)), 0), nz - 1)
        si = 1 if d0 > 0 else -1
        sj = 1 if d1 > 0 else -1
        sk = 1 if d2 > 0 else -1
        big = 1e30
        if abs(d0) > 1e-12:
            nbx = origin[0] + (i + (1 if si > 0 else 0)) * res
            tx = (nbx - o0) / d0
            dtx = res / abs(d0)
        else:
            tx = big
            dtx = big
        if abs(d1) > 1e-12:
            nby = origin[1] + (j + (1 if sj > 0 else 0)) * res
            ty = (nby - o1) / d1
            dty = res / abs(d1)
        else:
            ty = big
            dty = big
        if abs(d2) > 1e-12:
            nbz = origin[2] + (k + (1 if sk > 0 else 0)) * res
            tz = (nbz - o2) / d2
            dtz = res / abs(d2)
        else:
            tz = big
            dtz = big
        pv = 1.0
        first_done = False
        t_enter = t0
        while True:
            t_exit = min(tx, ty, tz)
            p = float(prob[i, j, k])
            counted = t_exit > tmin
            if counted:
                h = _entropy(p)
                fresh = (not visited) or stamp_t[i, j, k] != tag
                if visited:
                    stamp_t[i, j, k] = tag
                unknown = p >= unk_lo and p < unk_hi
                if fresh:
                    out[g, ENTROPY] += h
                    out[g, TRAVERSED] += 1.0
                    out[g, OCCLUSION] += pv * h
                    if unknown:
                        out[g, UNKNOWN] += 1.0
                        out[g, UNOBSERVED] += pv
                        out[g, PROXIMITY] += pv * prox[i, j, k]
                    if has_feat[i, j, k]:
                        c = -(d0 * normal[i, j, k, 0] + d1 * normal[i, j, k, 1] + d2 * normal[i, j, k, 2])
                        if c > cos_cut:
                            b = border[i, j, k]
                            dn = density[i, j, k]
                            out[g, QUAL_LIT] += lam * b + (1.0 - lam) * dn
                            out[g, QUAL_NEED] += lam * b + (1.0 - lam) * (1.0 - dn)
                if not first_done and p >= unk_lo:
                    first_done = True
                    if stamp_f[i, j, k] != tag:
                        stamp_f[i, j, k] = tag
                        if p >= unk_hi:
                            out[g, OCC_FIRST] += 1.0
                        else:
                            out[g, UNK_FIRST] += 1.0
            if p >= p_stop:
                out[g, HITS] += 1.0
                # peek at the voxel behind the surface (rear side)
                if tx <= ty and tx <= tz:
                    i2, j2, k2 = i + si, j, k
                elif ty <= tz:
                    i2, j2, k2 = i, j + sj, k
                else:
                    i2, j2, k2 = i, j, k + sk
                if 0 <= i2 < nx and 0 <= j2 < ny and 0 <= k2 < nz:
                    q = float(prob[i2, j2, k2])
                    if q >= unk_lo and q < unk_hi and stamp_f[i2, j2, k2] != -tag:
                        stamp_f[i2, j2, k2] = -tag
                        out[g, REAR_VOXEL] += 1.0
                        out[g, REAR_ENTROPY] += pv * _entropy(q)
                break
            pv *= 1.0 - p
            if t_exit >= t1:
                break
            t_enter = t_exit
            if tx <= ty and tx <= tz:
                i += si
                tx += dtx
            elif ty <= tz:
                j += sj
                ty += dty
            else:
                k += sk
                tz += dtz
            if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz:
                break
        _ = t_enter


@njit(cache=True)
def _first_blocked_kernel(prob, origin, res, origins, dirs, tmax, p_block, out):  # noqa: ANN001, ANN202
    nx, ny, nz = prob.shape
    hi0 = origin[0] + nx * res
    hi1 = origin[1] + ny * res
    hi2 = origin[2] + nz * res
    for r in range(origins.shape[0]):
        out[r] = np.inf
        o0, o1, o2 = origins[r, 0], origins[r, 1], origins[r, 2]
        d0, d1, d2 = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        t0, t1 = _box_interval(o0, o1, o2, d0, d1, d2, origin[0], origin[1], origin[2], hi0, hi1, hi2)
        if t0 < 0.0:
            t0 = 0.0
        if t1 > tmax[r]:
            t1 = tmax[r]
        if t0 >= t1:
            continue
        # sample at a quarter voxel: simple and robust for short occlusion tests
        step = 0.25 * res
        t = t0
        while t < t1:
            i = int(np.floor((o0 + d0 * t - origin[0]) / res))
            j = int(np.floor((o1 + d1 * t - origin[1]) / res))
            k = int(np.floor((o2 + d2 * t - origin[2]) / res))
            if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz:
                if prob[i, j, k] >= p_block:
                    out[r] = t
                    break
            t += step


def first_blocked(grid: VoxelGrid, origins: Points3, directions: Points3, max_range: Array | float,
                  p_block: float = 0.95) -> Array:
    """Distance along each ray to the first voxel with p >= ``p_block`` (inf if none before max_range)."""
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    tmax = np.broadcast_to(np.asarray(max_range, dtype=np.float64), (len(origins),)).copy()
    out = np.empty(len(origins))
    if len(origins):
        _first_blocked_kernel(grid.prob, np.asarray(grid.origin, dtype=np.float64), float(grid.resolution),
                              origins, directions, tmax, float(p_block), out)
    return out


@dataclass(frozen=True)
class TraceSettings:
    """Thresholds of the simulated beams (see the module docstring)."""

    p_stop: float = 0.95  # IROS: rays stop at the first voxel with p >= 0.95
    unknown_low: float = 0.25  # thesis pose-validation classes: free < 0.25 <= unknown < 0.75
    unknown_high: float = 0.75
    incidence_deg: float = 70.0  # thesis Eq. 4.33 cut-off
    lam: float = 0.7  # thesis lambda
    visited: bool = True  # count each voxel once per candidate
    hierarchy: int = 0  # HRT level a (0 = uniform ray tracing)


def trace(
    grid: VoxelGrid,
    origins: Points3,
    directions: Points3,
    group: np.ndarray,
    n_groups: int,
    min_range: float,
    max_range: float,
    settings: TraceSettings = TraceSettings(),
    bundle: int = 1,
) -> np.ndarray:
    """Accumulators (n_groups, N_ACC) of the beams; ``group`` gives each beam's candidate.

    Beams of one candidate must be contiguous. ``bundle`` is the number of neighbouring beams
    that HRT treats as one bundle (when ``settings.hierarchy`` > 0).
    """
    grid.ensure_features()
    if grid.proximity is None:
        grid.ensure_proximity(settings.unknown_high)
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    group = np.ascontiguousarray(group, dtype=np.int64)
    if settings.hierarchy > 0 and len(origins):
        keep = _hrt_mask(grid, origins, directions, max_range, settings, bundle)
        origins, directions, group = origins[keep], directions[keep], group[keep]
    out = np.zeros((n_groups, N_ACC))
    if len(origins) == 0:
        return out
    _trace_kernel(
        grid.prob, grid.has_feature, grid.border, grid.density, grid.normal, grid.proximity,
        np.asarray(grid.origin, dtype=np.float64), float(grid.resolution),
        origins, directions, group, int(n_groups), float(min_range), float(max_range),
        float(settings.p_stop), float(settings.unknown_low), float(settings.unknown_high),
        float(np.cos(np.deg2rad(settings.incidence_deg))), float(settings.lam), bool(settings.visited), out,
    )
    return out


def _hrt_mask(grid: VoxelGrid, origins: Points3, directions: Points3, max_range: float,
              settings: TraceSettings, bundle: int) -> np.ndarray:
    """Beams worth tracing finely: bundles whose central beam touches a non-free coarse voxel."""
    k = max(1, 2**settings.hierarchy)
    coarse = grid.coarse(settings.hierarchy)
    n = len(origins)
    size = max(1, k * bundle)
    centres = np.minimum(np.arange(n) // size * size + size // 2, n - 1)
    representatives = np.unique(centres)
    blocked = first_blocked(coarse, origins[representatives], directions[representatives], max_range,
                            p_block=settings.unknown_low)
    interesting = np.zeros(n, dtype=bool)
    interesting[representatives] = np.isfinite(blocked)
    return interesting[centres]
