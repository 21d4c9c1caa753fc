"""Probabilistic voxel space (PVS): Bayes occupancy grid with sensor noise and ray queries.

The PVS of Kriegel's thesis (Sec. 3.3.2, after Suppa 2008) re-created as a dense log-odds grid
over the region of interest. Every voxel starts unknown (p = 0.5, log-odds 0) and is updated
per beam with Bayes' rule in log-odds form (thesis Eq. 3.4): l <- clamp(l + log(p/(1-p))).

Inverse sensor model (``mode="sensor_model"``, thesis Fig. 3.10): for a beam with measured
range d and range noise sigma(d) from the sensor plugin (floored to ``sigma_floor``, by default
half a voxel, so a thin surface still gets a full hit), voxels before d - k*sigma get a free
update, voxels whose ray segment comes within k*sigma of d get an occupied update weighted by
exp(-delta^2 / 2 sigma^2), and voxels behind get nothing. The free part starts at the beam
origin only if the sensor says so (``Scan.clear_from_origin``); for a triangulation laser
striper a return only proves [min_range, d - k*sigma] free. A beam without a return frees the
working range if ``Scan.no_return_clears`` (from the origin or from min_range, as above).
``mode="octomap"`` instead reproduces OctoMap's ``insertPointCloud`` cell by cell (constant
hit 0.7 / miss 0.4, clamping 0.12-0.97, one update per cell and cloud, occupied wins).

Queries follow the thesis' named thresholds (``THRESHOLDS``), and the information gain of a
candidate is the entropy along its simulated beams until the first voxel with p >= 0.95
(Kriegel IROS 2012 Eq. 1-2; thesis Eq. 4.32 with visited marking and optional normalisation).

Benchmark (``benchmarks/pvs_vs_octomap.py``, 2-core AMD EPYC shared with other jobs, load
about 3; 6 views per scene; the grid covers the region and every sensor origin so both maps
traverse the same voxels; beams per second, best of 3; "om" = OctoMap-compatible mode,
"sm" = sensor-noise model; IG = entropy casting with visited marking, voxel visits/s)::

    scene                         res    OctoMap  PVS om  PVS sm  ratio  agreement     IG
    bunny_pedestal laser_striper  5 mm   0.19 M   1.47 M  1.53 M   7.9   100 % (275 k)  84 M
    bunny_pedestal laser_striper  10 mm  0.52 M   3.73 M  2.88 M   7.1   100 % (38 k)  132 M
    tabletop depth_camera         10 mm  0.08 M   1.16 M  0.67 M  15.2   100 % (955 k)  81 M

Agreement is the share of cells either map observed with the same free / occupied /
unknown state (cells compared in brackets); log-odds agree exactly except for a handful of cells
(e.g. 2 of 226 k at 5 mm) that differ by one miss: a ray through a voxel edge, where OctoMap's
float32 coordinates and our float64 ones break the tie differently.
On an idle machine the speeds are about 1.5x higher; the ratios stay at 5-15.

Storage: see :mod:`explore.mapping.pvs_kernels` for why the grid is dense float32.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import explore.mapping.pvs_kernels as K
from explore.core import Array, BadInput, Points3
from explore.sim import Scan, TriMesh

FREE, UNKNOWN, OCCUPIED = 0, 1, 2
"""State codes returned by :meth:`PVS.state`."""

THRESHOLDS: dict[str, tuple[float, float]] = {
    # name: (free below, occupied from); unknown in between
    "planning": (0.05, 0.05),  # thesis Sec. 3.3.2: p < 0.05 free, everything else an obstacle
    "feature": (0.05, 0.95),  # surface features / occlusion: occupied if p >= 0.95
    "validation": (0.25, 0.75),  # pose validation, thesis Eq. 3.11
    "vasquez": (0.45, 0.55),  # Vasquez-Gomez et al.: free / unknown / occupied classes
    "octomap": (0.5, 0.5),  # OctoMap: occupied if l > 0, free if observed and l <= 0
}
STOP_P = 0.95  # rays stop at the first voxel with p >= 0.95 (IROS 2012, thesis Eq. 4.32)
MODES = ("sensor_model", "octomap")
PARALLEL_MIN_RAYS = 20000  # smaller ray batches run serially (thread start-up, shared cores)
_FORMAT = 1


def logit(p: float | Array) -> float | Array:
    """Log-odds log(p / (1 - p)) (natural log, as OctoMap)."""
    p = np.asarray(p, dtype=float)
    out = np.log(p / (1.0 - p))
    return float(out) if out.ndim == 0 else out


def entropy_bits(p: float | Array) -> float | Array:
    """Voxel entropy H(p) = -p log2 p - (1 - p) log2 (1 - p) (IROS 2012 Eq. 1), 0 at p in {0, 1}."""
    p = np.asarray(p, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(p * np.log2(p) + (1.0 - p) * np.log2(1.0 - p))
    h = np.where((p <= 0.0) | (p >= 1.0), 0.0, h)
    return float(h) if h.ndim == 0 else h


@dataclass(frozen=True)
class RayResult:
    """Per-ray results of :meth:`PVS.cast`.

    Attributes
    ----------
    hit_distance : (n,) float
        Ray parameter where the first voxel with p >= ``stop_p`` starts (inf if none).
    hit_voxel : (n, 3) int
        Grid index of that voxel (-1 if none).
    entropy : (n,) float
        Entropy sum in bits over the voxels crossed up to and including the hit voxel
        (IROS 2012 Eq. 2 for one beam).
    unknown, occupied, frontier : (n,) int
        Counts of unknown / occupied voxels crossed, and of unknown voxels with a free
        6-neighbour ("frontier"), under the chosen thresholds.
    visits : (n,) int
        Voxels traversed per ray.
    voxel_offsets : (n + 1,) int or None
        With ``return_voxels``: ray i traversed ``voxel_ids[voxel_offsets[i]:voxel_offsets[i+1]]``.
    voxel_ids : (m,) int or None
        Flat voxel indices (C order of the grid) in traversal order.
    """

    hit_distance: Array
    hit_voxel: np.ndarray
    entropy: Array
    unknown: np.ndarray
    occupied: np.ndarray
    frontier: np.ndarray
    visits: np.ndarray
    shape: tuple[int, int, int]
    voxel_offsets: np.ndarray | None = None
    voxel_ids: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        """Mask of rays that reached a voxel with p >= ``stop_p``."""
        return np.isfinite(self.hit_distance)

    def voxels(self, i: int) -> np.ndarray:
        """Grid indices (k, 3) traversed by ray ``i`` (needs ``return_voxels=True``)."""
        if self.voxel_offsets is None or self.voxel_ids is None:
            raise ValueError("cast(..., return_voxels=True) to get the traversed voxels")
        flat = self.voxel_ids[self.voxel_offsets[i] : self.voxel_offsets[i + 1]]
        return np.column_stack(np.unravel_index(flat, self.shape))


BYTES_PER_VOXEL = 16  # float32 log-odds, int32 frame and visit stamps, the planners' float32 snapshot
MEMORY_SHARE = 0.5  # a grid may take at most this share of the machine's memory


def _human(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g}"


def memory_limit() -> float:
    """Bytes a voxel grid may take: :data:`MEMORY_SHARE` of the physical memory."""
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Linux
        total = 8 * 2**30
    return MEMORY_SHARE * float(total)


def check_grid(min_corner: Array, max_corner: Array, resolution: float, source: str = "region",
               field: str | None = None) -> None:
    """Reject a dense voxel grid that is ill-defined or would not fit in memory, before allocating it.

    Raises :class:`BadInput` naming the grid's shape and the memory it would need.
    """
    lo = np.asarray(min_corner, dtype=float).reshape(3)
    hi = np.asarray(max_corner, dtype=float).reshape(3)
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise BadInput(source, field or "resolution", f"{resolution} is not a positive finite voxel size")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise BadInput(source, field, "needs finite corners with max > min on every axis")
    shape = np.ceil((hi - lo) / resolution) + 1
    need = float(np.prod(shape)) * BYTES_PER_VOXEL
    if need > memory_limit():
        dims = " x ".join(f"{v:.3g}" for v in shape)
        raise BadInput(source, field, f"a {dims} voxel grid at {1e3 * resolution:g} mm would need {_human(need)}, "
                       f"more than the {_human(memory_limit())} allowed (half this machine's memory): choose a "
                       "coarser resolution or a smaller region")


class PVS:
    """Probabilistic voxel space over an axis-aligned box (thesis Sec. 3.3.2).

    Parameters
    ----------
    min_corner, max_corner : (3,) float
        Box to cover; it is widened to whole voxels on OctoMap's lattice (voxel edges at
        integer multiples of ``resolution``), so cells compare one to one with OctoMap.
    resolution : float
        Voxel edge length l_v in metres (thesis: 5 mm objects, 10-20 mm scenes).
    mode : "sensor_model" or "octomap"
        Inverse sensor model with range noise (default), or OctoMap's insertPointCloud.
    p_free, p_occ : float
        Miss / hit probabilities of the inverse model (OctoMap's 0.4 / 0.7; the
        DLR values are not published, thesis [UNSPEC]).
    clamp : (float, float) or None
        Probability clamping bounds. Default (0.12, 0.97) in octomap mode (OctoMap's) and
        (0.02, 0.98) in sensor-model mode, which must go below the planning threshold
        p < 0.05 for any voxel to become free for the motion planner.
    k_sigma : float
        Half-width of the occupied band in range standard deviations.
    sigma_floor : float or None
        Smallest range sigma used (default half a voxel).
    independence_filter : bool
        Reject beams whose (origin cell, direction bin) was already integrated (thesis
        Sec. 3.3.2, "measurement independence"; thresholds [UNSPEC], see the next two).
    independence_cell : float or None
        Edge of the origin cells of the filter (default: the resolution).
    independence_angle_deg : float
        Direction bin size of the filter (polar / azimuth bins).
    hit_wins : bool
        Sensor-model mode: a voxel inside the occupied band of a return gets no free update
        from the same frame (OctoMap's "occupied wins" per cloud). Without it, beams grazing a
        surface erode it: on the bunny (6 striper views, 5 mm) 25 % of the ground-truth
        surface ended up in voxels with p < 0.25 (octomap mode: 12 %).
    """

    THRESHOLDS = THRESHOLDS

    def __init__(
        self,
        min_corner: Array,
        max_corner: Array,
        resolution: float,
        mode: str = "sensor_model",
        p_free: float = 0.4,
        p_occ: float = 0.7,
        clamp: tuple[float, float] | None = None,
        k_sigma: float = 2.0,
        independence_filter: bool = False,
        sigma_floor: float | None = None,
        independence_cell: float | None = None,
        independence_angle_deg: float = 0.5,
        hit_wins: bool = True,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"unknown PVS mode {mode!r} (valid: {', '.join(MODES)})")
        if not resolution > 0.0:
            raise ValueError("resolution must be positive")
        if not (0.0 < p_free < 0.5 < p_occ < 1.0):
            raise ValueError("need 0 < p_free < 0.5 < p_occ < 1")
        lo = np.asarray(min_corner, dtype=float).reshape(3)
        hi = np.asarray(max_corner, dtype=float).reshape(3)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ValueError("need finite corners with max_corner > min_corner")
        self.resolution = float(resolution)
        self.mode = mode
        self.p_free = float(p_free)
        self.p_occ = float(p_occ)
        if clamp is None:
            clamp = (0.12, 0.97) if mode == "octomap" else (0.02, 0.98)
        if not (0.0 < clamp[0] < 0.5 < clamp[1] < 1.0):
            raise ValueError("need 0 < clamp[0] < 0.5 < clamp[1] < 1")
        self.clamp = (float(clamp[0]), float(clamp[1]))
        self.k_sigma = float(k_sigma)
        self.sigma_floor = 0.5 * self.resolution if sigma_floor is None else float(sigma_floor)
        self.independence_filter = bool(independence_filter)
        self.independence_cell = self.resolution if independence_cell is None else float(independence_cell)
        self.independence_angle_deg = float(independence_angle_deg)
        self.hit_wins = bool(hit_wins)
        check_grid(lo, hi, self.resolution)
        self.lattice = np.floor(lo / self.resolution + 1e-9).astype(np.int64)
        upper = np.ceil(hi / self.resolution - 1e-9).astype(np.int64)
        self.log_odds = np.zeros(tuple(int(n) for n in upper - self.lattice), dtype=np.float32)
        self.features: dict[str, np.ndarray] = {}
        self._beam_keys = np.zeros(0, dtype=np.int64)
        self._mark: np.ndarray | None = None  # per-frame stamps of the update kernels
        self._stamp = 0
        self._visited: np.ndarray | None = None  # entropy_gain visited marking
        self._visit_stamp = 0
        self.version = 0
        self._cache: dict[str, tuple[int, Any]] = {}

    # -- construction ------------------------------------------------------------------
    @classmethod
    def for_region(
        cls, min_corner: Array, max_corner: Array, resolution: float, margin: float | None = None,
        **kwargs: Any,
    ) -> PVS:
        """A PVS over a region of interest plus ``margin`` (default two voxels) on every side."""
        margin = 2.0 * resolution if margin is None else float(margin)
        lo = np.asarray(min_corner, dtype=float) - margin
        hi = np.asarray(max_corner, dtype=float) + margin
        return cls(lo, hi, resolution, **kwargs)

    # -- geometry ----------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        return self.log_odds.shape  # type: ignore[return-value]

    @property
    def origin(self) -> Array:
        """Corner of voxel (0, 0, 0) in metres."""
        return self.lattice * self.resolution

    @property
    def min_corner(self) -> Array:
        return self.origin

    @property
    def max_corner(self) -> Array:
        return (self.lattice + np.asarray(self.shape)) * self.resolution

    @property
    def l_min(self) -> float:
        return float(np.float32(logit(self.clamp[0])))

    @property
    def l_max(self) -> float:
        return float(np.float32(logit(self.clamp[1])))

    def index(self, points: Points3) -> tuple[np.ndarray, np.ndarray]:
        """Grid indices (n, 3) of the voxels containing ``points`` and the inside mask (n,)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        ijk = np.floor(pts * (1.0 / self.resolution)).astype(np.int64) - self.lattice
        inside = np.all((ijk >= 0) & (ijk < np.asarray(self.shape)), axis=1)
        return ijk, inside

    def centers(self, ijk: np.ndarray) -> Points3:
        """Centres (n, 3) of the voxels with grid indices ``ijk``."""
        return (np.asarray(ijk) + self.lattice + 0.5) * self.resolution

    def _touch(self) -> None:
        self.version += 1

    # -- update ------------------------------------------------------------------------
    def _beam_keys_of(self, origins: Points3, directions: Points3) -> np.ndarray:
        """Independence-filter keys: 15 bits per origin-cell axis, 18 bits of direction bin."""
        cell = np.floor(origins / self.independence_cell).astype(np.int64) & 0x7FFF
        step = np.deg2rad(self.independence_angle_deg)
        polar = np.arccos(np.clip(directions[:, 2], -1.0, 1.0))
        azimuth = np.arctan2(directions[:, 1], directions[:, 0]) + np.pi
        n_az = int(np.ceil(2.0 * np.pi / step))
        dbin = (np.floor(polar / step).astype(np.int64) * n_az + np.floor(azimuth / step).astype(np.int64))
        dbin &= 0x3FFFF
        return (cell[:, 0] << 48) | (cell[:, 1] << 33) | (cell[:, 2] << 18) | dbin

    def integrate(self, scan: Scan) -> dict[str, int]:
        """Bayes update with every beam of ``scan`` (thesis Eq. 3.4, Fig. 3.10).

        Returns
        -------
        dict
            beams, used, rejected (by the independence filter), hits, no_returns and
            voxel_updates (voxel log-odds changes applied).
        """
        origins = np.ascontiguousarray(scan.origins, dtype=np.float64).reshape(-1, 3)
        directions = np.ascontiguousarray(scan.directions, dtype=np.float64).reshape(-1, 3)
        ranges = np.ascontiguousarray(scan.ranges, dtype=np.float64).reshape(-1)
        sigmas = np.ascontiguousarray(scan.sigmas, dtype=np.float64).reshape(-1)
        frames = np.asarray(scan.frame_of_beam).reshape(-1)
        n = len(ranges)
        keep = np.ones(n, dtype=bool)
        if self.independence_filter and n:
            keys = self._beam_keys_of(origins, directions)
            first = np.zeros(n, dtype=bool)
            first[np.unique(keys, return_index=True)[1]] = True
            keep = first & ~np.isin(keys, self._beam_keys, assume_unique=False)
            self._beam_keys = np.union1d(self._beam_keys, keys[keep])
        if not keep.all():
            origins, directions = origins[keep], directions[keep]
            ranges, sigmas, frames = ranges[keep], sigmas[keep], frames[keep]
        lat = self.lattice
        order = np.argsort(frames, kind="stable")
        if not np.all(order[1:] > order[:-1]):
            origins, directions, ranges = origins[order], directions[order], ranges[order]
            sigmas, frames = sigmas[order], frames[order]
        _, first = np.unique(frames, return_index=True)
        starts = np.append(first, len(frames)).astype(np.int64)
        if self._mark is None:
            self._mark = np.zeros(self.shape, dtype=np.int32)
        if self._stamp >= 2**30 - len(starts):
            self._mark[:] = 0
            self._stamp = 0
        if self.mode == "sensor_model":
            free_from = -np.inf if scan.clear_from_origin else float(scan.min_range)
            updates, self._stamp = K.update_sensor_model(
                self.log_odds, self._mark, self._stamp, self.hit_wins, lat, self.resolution,
                origins, directions, ranges, sigmas, starts, bool(scan.no_return_clears), free_from,
                float(scan.max_range), self.k_sigma, self.sigma_floor, logit(self.p_free),
                logit(self.p_occ), self.l_min, self.l_max,
            )
        else:
            updates, self._stamp = K.update_octomap(
                self.log_odds, self._mark, self._stamp, lat, self.resolution, origins, directions,
                ranges, starts, bool(scan.no_return_clears), float(scan.max_range),
                logit(self.p_occ), logit(self.p_free), self.l_min, self.l_max,
            )
        self._touch()
        hits = int(np.isfinite(ranges).sum())
        return {
            "beams": n,
            "used": int(keep.sum()),
            "rejected": int(n - keep.sum()),
            "hits": hits,
            "no_returns": int(len(ranges) - hits),
            "voxel_updates": int(updates),
        }

    def grow(self, min_corner: Array, max_corner: Array) -> None:
        """Enlarge the box to also cover [min_corner, max_corner], keeping all data."""
        lo = np.floor(np.asarray(min_corner, dtype=float) / self.resolution + 1e-9).astype(np.int64)
        hi = np.ceil(np.asarray(max_corner, dtype=float) / self.resolution - 1e-9).astype(np.int64)
        new_lo = np.minimum(self.lattice, lo)
        new_hi = np.maximum(self.lattice + np.asarray(self.shape), hi)
        if np.all(new_lo == self.lattice) and np.all(new_hi == self.lattice + np.asarray(self.shape)):
            return
        shape = tuple(int(v) for v in new_hi - new_lo)
        at = self.lattice - new_lo
        window = tuple(slice(int(a), int(a) + s) for a, s in zip(at, self.shape, strict=True))

        def moved(old: np.ndarray, fill: float) -> np.ndarray:
            new = np.full(shape + old.shape[3:], fill, dtype=old.dtype)
            new[window] = old
            return new

        self.log_odds = moved(self.log_odds, 0.0)
        self.features = {name: moved(values, np.nan) for name, values in self.features.items()}
        if self._mark is not None:
            self._mark = moved(self._mark, 0)
        self._visited = None
        self.lattice = new_lo
        self._touch()

    # -- point queries -----------------------------------------------------------------
    def probability(self, points: Points3) -> Array:
        """Occupancy probability (n,) of the voxels containing ``points``; 0.5 outside."""
        ijk, inside = self.index(points)
        lo = np.zeros(len(ijk), dtype=np.float64)
        lo[inside] = self.log_odds[tuple(ijk[inside].T)]
        return 1.0 / (1.0 + np.exp(-lo))

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
        ijk, inside = self.index(points)
        lo = np.zeros(len(ijk), dtype=np.float32)
        lo[inside] = self.log_odds[tuple(ijk[inside].T)]
        return self._classify(lo, thresholds)

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
        kernel = K.cast_rays if parallel else K.cast_rays_serial
        free_below, occ_from = THRESHOLDS[thresholds]
        args = (
            self.log_odds, self.lattice, self.resolution, o, d, r, float(min_range),
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
            if self._visited is None or self._visited.shape != self.shape or self._visit_stamp >= 2**31 - 2:
                self._visited = np.zeros(self.shape, dtype=np.int32)
                self._visit_stamp = 0
            self._visit_stamp += 1
            total, voxels, visits = K.entropy_visited(
                self.log_odds, self._visited, self._visit_stamp, self.lattice, self.resolution,
                o, d, r, float(min_range), l_stop,
            )
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
        from scipy.ndimage import distance_transform_edt

        obstacle = self.obstacle_grid()
        if not obstacle.any():
            field = np.full(self.shape, np.inf)
        else:
            field = distance_transform_edt(~obstacle, sampling=self.resolution)
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

    def save_png(self, path: str | Path, axis: int = 2, index: int | None = None, title: str = "") -> None:
        """Picture: a probability slice (black free, grey unknown, white occupied) and a 3-D view."""
        from explore.core import equal_axes, plt  # pictures selects the Agg backend

        prob = 1.0 / (1.0 + np.exp(-self.log_odds.astype(np.float64)))
        occ = self.log_odds >= np.float32(logit(0.75))
        if index is None:
            per_slice = occ.sum(axis=tuple(a for a in range(3) if a != axis))
            index = int(np.argmax(per_slice)) if per_slice.any() else self.shape[axis] // 2
        index = int(np.clip(index, 0, self.shape[axis] - 1))
        plane = np.take(prob, index, axis=axis)
        other = [a for a in range(3) if a != axis]
        lo, hi = self.min_corner, self.max_corner
        fig = plt.figure(figsize=(11, 5), dpi=100)
        ax = fig.add_subplot(1, 2, 1)
        ax.imshow(
            plane.T, origin="lower", cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest",
            extent=(lo[other[0]], hi[other[0]], lo[other[1]], hi[other[1]]),
        )
        names = "xyz"
        ax.set_xlabel(f"{names[other[0]]} [m]")
        ax.set_ylabel(f"{names[other[1]]} [m]")
        coord = (self.lattice[axis] + index + 0.5) * self.resolution
        ax.set_title(f"p at {names[axis]} = {coord:.3f} m")
        ax3 = fig.add_subplot(1, 2, 2, projection="3d")
        pts = self.occupied_points()
        if len(pts):
            pick = np.random.default_rng(0).permutation(len(pts))[:30000]
            shown = pts[pick]
            ax3.scatter(shown[:, 0], shown[:, 1], shown[:, 2], c=shown[:, 2], s=1.0, cmap="viridis")
            equal_axes(ax3, shown)
        c = self.counts()
        ax3.set_title(f"occupied {c['occupied']}, unknown {c['unknown']}, free {c['free']}")
        fig.suptitle(title or f"PVS {self.shape} @ {self.resolution * 1000:.0f} mm ({self.mode})")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)

    # -- surface features (thesis Sec. 4.5.1) -------------------------------------------
    def _feature(self, name: str, channels: int = 0) -> np.ndarray:
        if name not in self.features:
            shape = self.shape + ((channels,) if channels else ())
            self.features[name] = np.full(shape, np.nan, dtype=np.float32)
        return self.features[name]

    def set_features(
        self,
        points: Points3,
        density: Array | None = None,
        normals: Points3 | None = None,
        border: Array | None = None,
    ) -> int:
        """Write surface features at the voxels containing ``points`` (thesis Eqs. 4.24-4.28).

        Per voxel the values of the points inside it are averaged: density d̄_i (4.26),
        normal n̄_i (4.27, not re-normalised), border-edge ratio b_i (4.28). Voxels touched
        are overwritten; others keep their values (NaN where never set). Returns the number
        of voxels written.
        """
        ijk, inside = self.index(points)
        if not inside.any():
            return 0
        flat = np.ravel_multi_index(tuple(ijk[inside].T), self.shape)
        cells, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)

        def mean(values: np.ndarray) -> np.ndarray:
            values = np.asarray(values, dtype=np.float64)[inside]
            if values.ndim == 1:
                return np.bincount(inverse, values, len(cells)) / counts
            return np.column_stack(
                [np.bincount(inverse, values[:, c], len(cells)) for c in range(values.shape[1])]
            ) / counts[:, None]

        where = np.unravel_index(cells, self.shape)
        if density is not None:
            self._feature("density")[where] = mean(density)
        if border is not None:
            self._feature("border")[where] = mean(border)
        if normals is not None:
            self._feature("normal", 3)[where] = mean(np.asarray(normals).reshape(-1, 3))
        self._touch()
        return len(cells)

    def feature(self, name: str, points: Points3) -> np.ndarray:
        """Feature values at the voxels containing ``points`` (NaN where unset or outside)."""
        if name not in self.features:
            return np.full((len(np.asarray(points).reshape(-1, 3)),) + ((3,) if name == "normal" else ()), np.nan)
        values = self.features[name]
        ijk, inside = self.index(points)
        out = np.full((len(ijk),) + values.shape[3:], np.nan)
        out[inside] = values[tuple(ijk[inside].T)]
        return out

    # -- persistence -------------------------------------------------------------------
    def _params(self) -> dict[str, Any]:
        return {
            "format": _FORMAT,
            "resolution": self.resolution,
            "mode": self.mode,
            "p_free": self.p_free,
            "p_occ": self.p_occ,
            "clamp": list(self.clamp),
            "k_sigma": self.k_sigma,
            "sigma_floor": self.sigma_floor,
            "independence_filter": self.independence_filter,
            "independence_cell": self.independence_cell,
            "independence_angle_deg": self.independence_angle_deg,
            "hit_wins": self.hit_wins,
        }

    def save(self, path: str | Path) -> None:
        """Write the PVS (log-odds, parameters, features, filter state) to a ``.npz`` file."""
        arrays = {
            "log_odds": self.log_odds,
            "lattice": self.lattice,
            "beam_keys": self._beam_keys,
            "params": np.array(json.dumps(self._params())),
        }
        for name, values in self.features.items():
            arrays[f"feature_{name}"] = values
        with open(path, "wb") as handle:
            np.savez_compressed(handle, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> PVS:
        """Read a PVS written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as data:
            params = json.loads(str(data["params"]))
            if params.pop("format", None) != _FORMAT:
                raise ValueError(f"{path}: not a PVS file of format {_FORMAT}")
            lattice = data["lattice"].astype(np.int64)
            log_odds = data["log_odds"].astype(np.float32)
            resolution = params.pop("resolution")
            lo = lattice * resolution
            hi = (lattice + np.asarray(log_odds.shape)) * resolution
            pvs = cls(lo, hi, resolution, clamp=tuple(params.pop("clamp")), **params)
            if pvs.shape != log_odds.shape:  # guard the lattice rounding
                raise ValueError(f"{path}: grid shape mismatch")
            pvs.lattice = lattice
            pvs.log_odds = log_odds
            pvs._beam_keys = data["beam_keys"].astype(np.int64)
            for key in data.files:
                if key.startswith("feature_"):
                    pvs.features[key[len("feature_") :]] = data[key].astype(np.float32)
        return pvs
