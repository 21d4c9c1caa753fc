"""Simulated candidate beams through a voxel grid: the view-evaluation core of the utilities.

One numba kernel walks every beam of every candidate through a dense snapshot of the PVS
(with the PVS's own Amanatides-Woo traversal, ``explore.mapping.traversal``) and accumulates,
per candidate, every quantity the utility plugins need, so that one pass serves all of them:

============  ==========================================================================
index         quantity
============  ==========================================================================
ENTROPY       sum of voxel entropies until the first voxel with p >= p_stop (IROS Eq. 1-2,
              thesis Eq. 4.32 before the 1/N_v normalisation)
UNKNOWN_VOXELS unknown voxels traversed (Wong's unknown-voxel count)
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
``occluders``, axis-aligned boxes of the known environment (a table, a chair, a pedestal), end a
beam where it enters the first of them (a voxel wholly inside a box is never counted): the known
environment hides what lies behind it although the PVS does not hold it (a camera below a table
top does not see the object on the table through it).
With ``visited`` the traversal quantities count every voxel once per candidate (thesis
Sec. 4.5.3 visited marking); the first-hit and rear-side counts are always distinct.

Hierarchical ray tracing (Vasquez-Gomez Sec. HRT, level ``a``) is a speed option: the beams
of a candidate are grouped into bundles of 2^a x 2^a neighbours (along the stripe / image row
and across frames / image columns); the bundle's central beam is cast through a max-pooled
grid 2^a times coarser (dilated by one coarse voxel, so every beam of the bundle lies inside
the cast corridor) up to the first coarse voxel that is not free. A bundle that meets none
is not traced at all; the others are traced at full resolution from one coarse voxel before
that point. What is lost is the entropy of the skipped free voxels (p <= 0.25) and their
share of P_v; ``benchmarks/reproduce_kriegel.py --hierarchy a`` measures speed and cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import get_num_threads, njit, prange

from explore.core import Array, Points3
from explore.mapping.traversal import _slab, next_axis, ray_start

ENTROPY, UNKNOWN_VOXELS, QUAL_LIT, QUAL_NEED, TRAVERSED, OCC_FIRST, UNK_FIRST = range(7)
OCCLUSION, UNOBSERVED, REAR_VOXEL, REAR_ENTROPY, PROXIMITY, HITS = range(7, 13)
N_ACC = 13
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
    entropy: np.ndarray | None = None

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

    def ensure_entropy(self) -> None:
        """H(p) in bits per voxel, computed once per snapshot (the kernel then only looks it up)."""
        if self.entropy is not None:
            return
        p = np.clip(self.prob.astype(np.float64), 1e-9, 1.0 - 1e-9)
        h = -(p * np.log2(p) + (1.0 - p) * np.log2(1.0 - p))
        h[(self.prob <= 1e-9) | (self.prob >= 1.0 - 1e-9)] = 0.0
        self.entropy = h.astype(np.float32)

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

    def coarse(self, level: int, dilate: bool = False) -> VoxelGrid:
        """Grid ``2**level`` times coarser holding the max occupancy of its children (as an
        octree's inner nodes); with ``dilate`` also of the 26 neighbouring coarse voxels."""
        k = 2**level
        nx, ny, nz = self.shape
        pad = [(0, (-n) % k) for n in (nx, ny, nz)]
        p = np.pad(self.prob, pad, constant_values=0.0)
        s = p.shape
        pooled = p.reshape(s[0] // k, k, s[1] // k, k, s[2] // k, k).max(axis=(1, 3, 5))
        if dilate:
            from scipy.ndimage import maximum_filter

            pooled = maximum_filter(pooled, size=3, mode="nearest")
        return VoxelGrid(pooled.astype(np.float32), self.origin.copy(), self.resolution * k)


@njit(cache=True, nogil=True, inline="always")
def _reach(ox, oy, oz, d0, d1, d2, tmax, boxes):  # noqa: ANN001, ANN202
    """How far a beam (world origin, unit direction) goes: ``tmax``, or to its entry into the nearest
    occluder box (the traversal still visits the voxel that holds the entry point)."""
    reach = tmax
    for b in range(boxes.shape[0]):
        ok, t0, t1, _ = _slab(ox, d0, boxes[b, 0, 0], boxes[b, 1, 0], 0.0, reach, -1, 0)
        if ok:
            ok, t0, t1, _ = _slab(oy, d1, boxes[b, 0, 1], boxes[b, 1, 1], t0, t1, -1, 1)
        if ok:
            ok, t0, t1, _ = _slab(oz, d2, boxes[b, 0, 2], boxes[b, 1, 2], t0, t1, -1, 2)
        if ok and t0 <= t1:
            reach = min(reach, t0)
    return reach


@njit(cache=True, nogil=True)
def _trace_range(
    prob, ent, has_feat, border, density, normal, prox, origin, res,
    origins, dirs, tstart, group, r0, r1, tmin, tmax, boxes,
    p_stop, unk_lo, unk_hi, cos_cut, lam, visited, out, stamp_t, stamp_f,
):  # noqa: ANN001, ANN202
    """Beams r0 .. r1-1 (whole candidates); ``stamp_*`` are this worker's visited marks.

    The walk is the PVS's own traversal (``explore.mapping.traversal``) in grid coordinates.
    """
    nx, ny, nz = prob.shape
    inv_res = 1.0 / res
    lat = np.zeros(3, np.int64)
    for r in range(r0, r1):
        g = group[r]
        tag = g + 1
        d0, d1, d2 = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        reach = _reach(origins[r, 0], origins[r, 1], origins[r, 2], d0, d1, d2, tmax, boxes)
        (ok, t0, t1, i, j, k, si, sj, sk, tx, ty, tz, dtx, dty, dtz) = ray_start(
            origins[r, 0] - origin[0], origins[r, 1] - origin[1], origins[r, 2] - origin[2], d0, d1, d2,
            max(tstart[r], 0.0), reach, lat, inv_res, res, nx, ny, nz,  # HRT: free up to tstart
        )
        if not ok:
            continue
        pv = 1.0
        first_done = False
        while True:
            axis = next_axis(tx, ty, tz)
            t_exit = tx if axis == 0 else (ty if axis == 1 else tz)
            p = float(prob[i, j, k])
            if t_exit > tmin:
                h = float(ent[i, j, k])
                fresh = (not visited) or stamp_t[i, j, k] != tag
                if visited:
                    stamp_t[i, j, k] = tag
                unknown = p >= unk_lo and p < unk_hi
                if fresh:
                    out[g, ENTROPY] += h
                    out[g, TRAVERSED] += 1.0
                    out[g, OCCLUSION] += pv * h
                    if unknown:
                        out[g, UNKNOWN_VOXELS] += 1.0
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
                i2 = i + si if axis == 0 else i
                j2 = j + sj if axis == 1 else j
                k2 = k + sk if axis == 2 else k
                if 0 <= i2 < nx and 0 <= j2 < ny and 0 <= k2 < nz:
                    q = float(prob[i2, j2, k2])
                    if q >= unk_lo and q < unk_hi and stamp_f[i2, j2, k2] != -tag:
                        stamp_f[i2, j2, k2] = -tag
                        out[g, REAR_VOXEL] += 1.0
                        out[g, REAR_ENTROPY] += pv * float(ent[i2, j2, k2])
                break
            pv *= 1.0 - p
            if t_exit >= t1:
                break
            if axis == 0:
                i += si
                tx += dtx
            elif axis == 1:
                j += sj
                ty += dty
            else:
                k += sk
                tz += dtz
            if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz:
                break


@njit(cache=True, nogil=True, parallel=True)
def _trace_chunks(
    prob, ent, has_feat, border, density, normal, prox, origin, res,
    origins, dirs, tstart, group, bounds, tmin, tmax, boxes,
    p_stop, unk_lo, unk_hi, cos_cut, lam, visited, out,
):  # noqa: ANN001, ANN202
    """One worker per chunk of whole candidates, each with its own visited marks."""
    for c in prange(len(bounds) - 1):
        stamp_t = np.zeros(prob.shape, dtype=np.int32)
        stamp_f = np.zeros(prob.shape, dtype=np.int32)
        _trace_range(prob, ent, has_feat, border, density, normal, prox, origin, res,
                     origins, dirs, tstart, group, bounds[c], bounds[c + 1], tmin, tmax, boxes,
                     p_stop, unk_lo, unk_hi, cos_cut, lam, visited, out, stamp_t, stamp_f)


@njit(cache=True, nogil=True)
def _first_blocked_kernel(prob, origin, res, origins, dirs, tmax, p_block, out):  # noqa: ANN001, ANN202
    """The PVS traversal of each ray to the entry of its first voxel with p >= p_block."""
    nx, ny, nz = prob.shape
    inv_res = 1.0 / res
    lat = np.zeros(3, np.int64)
    for r in range(origins.shape[0]):
        out[r] = np.inf
        (ok, t_in, t1, i, j, k, si, sj, sk, tx, ty, tz, dtx, dty, dtz) = ray_start(
            origins[r, 0] - origin[0], origins[r, 1] - origin[1], origins[r, 2] - origin[2],
            dirs[r, 0], dirs[r, 1], dirs[r, 2], 0.0, tmax[r], lat, inv_res, res, nx, ny, nz,
        )
        while ok and t_in < t1:
            if prob[i, j, k] >= p_block:
                out[r] = t_in
                break
            axis = next_axis(tx, ty, tz)
            if axis == 0:
                t_in = tx
                i += si
                tx += dtx
            elif axis == 1:
                t_in = ty
                j += sj
                ty += dty
            else:
                t_in = tz
                k += sk
                tz += dtz
            if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz:
                break


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
    beams_per_frame: int | None = None,
    occluders: list[tuple[Array, Array]] | None = None,
) -> np.ndarray:
    """Accumulators (n_groups, N_ACC) of the beams; ``group`` gives each beam's candidate.

    Beams of one candidate must be contiguous, frame after frame with ``beams_per_frame``
    beams each (HRT bundles span 2^a beams and 2^a frames; None: bundles of 4^a consecutive
    beams). ``occluders``: boxes (lo, hi) of the known environment that end the beams.
    """
    grid.ensure_features()
    grid.ensure_entropy()
    if grid.proximity is None:
        grid.ensure_proximity(settings.unknown_high)
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    group = np.ascontiguousarray(group, dtype=np.int64)
    out = np.zeros((n_groups, N_ACC))
    if len(origins) == 0:
        return out
    if settings.hierarchy > 0:
        tstart = hrt_start(grid, origins, directions, group, max_range, settings, beams_per_frame)
    else:
        tstart = np.zeros(len(origins))
    args = (
        grid.prob, grid.entropy, grid.has_feature, grid.border, grid.density, grid.normal, grid.proximity,
        np.asarray(grid.origin, dtype=np.float64), float(grid.resolution), origins, directions, tstart, group,
    )
    boxes = np.array([np.vstack([lo, hi]) for lo, hi in occluders or []], dtype=np.float64).reshape(-1, 2, 3)
    tail = (
        float(min_range), float(max_range), boxes, float(settings.p_stop), float(settings.unknown_low),
        float(settings.unknown_high), float(np.cos(np.deg2rad(settings.incidence_deg))), float(settings.lam),
        bool(settings.visited), out,
    )
    workers = min(get_num_threads(), n_groups)
    if workers <= 1:
        stamp_t = np.zeros(grid.shape, dtype=np.int32)
        stamp_f = np.zeros(grid.shape, dtype=np.int32)
        _trace_range(*args, 0, len(origins), *tail, stamp_t, stamp_f)
    else:
        _trace_chunks(*args, _chunk_bounds(group, workers), *tail)
    return out


def _chunk_bounds(group: np.ndarray, workers: int) -> np.ndarray:
    """Beam indices splitting the (contiguous) candidates into ``workers`` chunks of about equal size."""
    starts = np.concatenate([[0], np.flatnonzero(np.diff(group)) + 1, [len(group)]])
    wanted = np.linspace(0, len(group), workers + 1)
    cut = starts[np.searchsorted(starts, wanted[1:-1])]
    return np.unique(np.concatenate([[0], cut, [len(group)]])).astype(np.int64)


def hrt_start(grid: VoxelGrid, origins: Points3, directions: Points3, group: np.ndarray, max_range: float,
              settings: TraceSettings, beams_per_frame: int | None = None) -> Array:
    """Where each beam's fine traversal starts under HRT (inf: the beam's bundle is all free).

    Vasquez-Gomez HRT with refinement on occupied *and* unknown coarse voxels: the central
    beam of every 2^a x 2^a bundle is cast through the dilated coarse grid up to the first
    voxel with p >= ``unknown_low``; the bundle's beams start one coarse voxel before it.
    """
    level = settings.hierarchy
    k = 2**level
    coarse = grid.coarse(level, dilate=True)
    n = len(origins)
    index = np.arange(n)
    first = np.zeros(n, dtype=np.int64)  # index of the first beam of each beam's candidate
    change = np.flatnonzero(np.diff(group)) + 1
    starts = np.concatenate([[0], change])
    first[starts] = starts
    first = np.maximum.accumulate(first)
    local = index - first
    if beams_per_frame:
        frame, beam = local // beams_per_frame, local % beams_per_frame
        block = (frame // k) * (beams_per_frame // k + 1) + beam // k
    else:
        block = local // (k * k)
    key = group.astype(np.int64) * (int(local.max()) + 1) + block
    order = np.argsort(key, kind="stable")
    uniq, begin, counts = np.unique(key[order], return_index=True, return_counts=True)
    representative = order[begin + counts // 2]
    hit = first_blocked(coarse, origins[representative], directions[representative], max_range,
                        p_block=settings.unknown_low)
    start = np.where(np.isfinite(hit), np.maximum(hit - coarse.resolution, 0.0), np.inf)
    return start[np.searchsorted(uniq, key)]
