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
working range if ``Scan.no_return_clears`` (from the origin or from min_range, as above); else, with
``Scan.seen_from`` (a striper's camera), the part of it the camera saw (``PVS._seen_misses``).
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

from typing import Any

import numpy as np

from explore.core import Array, Points3
from explore.mapping.pvs_features import PVSFeatures
from explore.mapping.pvs_grid import (
    MODES,
    THRESHOLDS,
    check_grid,
    logit,
)
from explore.mapping.pvs_queries import PVSQueries
from explore.mapping.pvs_updates import update_octomap, update_sensor_model
from explore.sim import Scan

"""State codes returned by :meth:`PVS.state`."""


#: a voxel at least this likely occupied holds surface a scan saw (one return's weak update suffices)
SEEN_SURFACE = 0.55
#: key offsets of a voxel's 27-neighbourhood (itself included) under ``PVS._keys``
NEIGHBOURS = (np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
              @ np.array([1 << 42, 1 << 21, 1], dtype=np.int64))


class PVS(PVSFeatures, PVSQueries):
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
        self.lattice, upper = self.voxel_box(lo, hi)
        self._allocate(lo, hi, upper - self.lattice)
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

    def _allocate(self, lo: Array, hi: Array, extent: np.ndarray) -> None:
        """The storage: a dense zero (unknown) log-odds grid of ``extent`` voxels, refused before it is
        allocated if it would not fit in memory."""
        check_grid(lo, hi, self.resolution)
        self.log_odds = np.zeros(tuple(int(n) for n in extent), dtype=np.float32)

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

    def voxel_box(self, min_corner: Array, max_corner: Array) -> tuple[np.ndarray, np.ndarray]:
        """Lattice keys of the first voxel and one past the last of the whole voxels covering a box
        (OctoMap's lattice: voxel edges at integer multiples of the resolution)."""
        lo = np.floor(np.asarray(min_corner, dtype=float).reshape(3) / self.resolution + 1e-9).astype(np.int64)
        hi = np.ceil(np.asarray(max_corner, dtype=float).reshape(3) / self.resolution - 1e-9).astype(np.int64)
        return lo, hi

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
        order = np.argsort(frames, kind="stable")
        if not np.all(order[1:] > order[:-1]):
            origins, directions, ranges = origins[order], directions[order], ranges[order]
            sigmas, frames = sigmas[order], frames[order]
        _, first = np.unique(frames, return_index=True)
        starts = np.append(first, len(frames)).astype(np.int64)
        if scan.seen_from is not None and not scan.no_return_clears and self.mode == "sensor_model":
            ranges = self._seen_misses(scan, origins, directions, ranges, frames)
        updates = self._apply(scan, origins, directions, ranges, sigmas, starts)
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

    def _seen_misses(self, scan: Scan, origins: Points3, directions: Points3, ranges: Array,
                     frames: np.ndarray) -> Array:
        """``ranges`` with each beam without a return that the sensor's second viewpoint (``scan.seen_from``, the
        camera of a laser striper) saw into set to -t: the beam is free from the working range's start to t.

        A surface in the laser's path where the camera sees it would have returned, so the missing return
        proves free every voxel along the beam up to the first one the camera cannot see (its line of sight
        meets a voxel the PVS holds occupied), or that may hold a surface whose return was lost rather than
        absent: one the map holds as surface (p >= ``SEEN_SURFACE``) or within a voxel of a return of this
        scan (grazing incidence thins a seen surface's returns out). Points a voxel apart along the beam
        inside the box are tested, those in voxels not yet known free.
        """
        miss = np.flatnonzero(np.isnan(ranges))
        if not len(miss):
            return ranges
        o, d = origins[miss], directions[miss]
        t_lo = np.full(len(miss), float(scan.min_range) if not scan.clear_from_origin else 0.0)
        t_hi = np.full(len(miss), float(scan.max_range))
        with np.errstate(divide="ignore", invalid="ignore"):  # the beam's part inside the box (slab test)
            a = (self.min_corner - o) / d
            b = (self.max_corner - o) / d
            t_lo = np.maximum(t_lo, np.nanmax(np.minimum(a, b), axis=1))
            t_hi = np.minimum(t_hi, np.nanmin(np.maximum(a, b), axis=1))
        step = self.resolution
        t_hi = np.minimum(t_hi, self.cast(o, d, t_hi.clip(min=0.0), stop_p=SEEN_SURFACE).hit_distance - step)
        count = (np.floor(np.clip(t_hi - t_lo, 0.0, None) / step)).astype(np.int64)
        beam = np.repeat(np.arange(len(miss)), count)
        if not len(beam):
            return ranges
        k = np.arange(len(beam)) - np.repeat(np.cumsum(count) - count, count)
        t = t_lo[beam] + (k + 0.5) * step
        points = o[beam] + t[:, None] * d[beam]
        # the return of a surface this scan saw elsewhere may have been lost here (grazing incidence): stop there
        hits = np.isfinite(ranges)
        returned = self._keys(origins[hits] + ranges[hits, None] * directions[hits])
        returned = np.unique((returned[:, None] + NEIGHBOURS[None, :]).ravel())  # with the occupied band around
        lost = np.isin(self._keys(points), returned)
        first_lost = np.full(len(miss), np.inf)
        np.minimum.at(first_lost, beam[lost], t[lost])
        free, occupied_from = THRESHOLDS["validation"]
        test = (self.probability(points) >= free) & (t < first_lost[beam])  # known free: no surface, seen or not
        beam, t, points = beam[test], t[test], points[test]
        poses = scan.sensor_poses[frames[miss[beam]]]
        cameras = poses[:, :3, 3] + np.einsum("nij,j->ni", poses[:, :3, :3], np.asarray(scan.seen_from, dtype=float))
        sight = points - cameras
        distance = np.linalg.norm(sight, axis=1)
        reach = (distance - 1.5 * step).clip(min=0.0)
        blocked = np.isfinite(self.cast(cameras, sight / distance[:, None], reach, stop_p=occupied_from).hit_distance)
        first_blocked = np.full(len(miss), np.inf)
        np.minimum.at(first_blocked, beam[blocked], t[blocked])
        t_free = np.minimum(np.minimum(first_blocked, first_lost) - 0.5 * step, t_lo + count * step)
        seen = t_free >= t_lo + step
        out = ranges.copy()
        out[miss[seen]] = -t_free[seen]
        return out

    def _keys(self, points: Points3) -> np.ndarray:
        """One integer per voxel of ``points`` (absolute lattice keys; a neighbour's key differs by ``NEIGHBOURS``)."""
        ijk = np.floor(np.asarray(points) / self.resolution).astype(np.int64) + 2**20
        return (ijk[:, 0] << 42) + (ijk[:, 1] << 21) + ijk[:, 2]

    def _apply(self, scan: Scan, origins: Points3, directions: Points3, ranges: Array, sigmas: Array,
               starts: np.ndarray) -> int:
        """Run the update kernel of the mode over the beams (sorted by frame, ``starts`` delimit the frames);
        returns the number of voxel updates."""
        lat = self.lattice
        if self._mark is None:
            self._mark = np.zeros(self.shape, dtype=np.int32)
        if self._stamp >= 2**30 - len(starts):
            self._mark[:] = 0
            self._stamp = 0
        if self.mode == "sensor_model":
            free_from = -np.inf if scan.clear_from_origin else float(scan.min_range)
            updates, self._stamp = update_sensor_model(
                self.log_odds, self._mark, self._stamp, self.hit_wins, lat, self.resolution,
                origins, directions, ranges, sigmas, starts, bool(scan.no_return_clears), free_from,
                float(scan.max_range), self.k_sigma, self.sigma_floor, logit(self.p_free),
                logit(self.p_occ), self.l_min, self.l_max,
            )
        else:
            updates, self._stamp = update_octomap(
                self.log_odds, self._mark, self._stamp, lat, self.resolution, origins, directions,
                ranges, starts, bool(scan.no_return_clears), float(scan.max_range),
                logit(self.p_occ), logit(self.p_free), self.l_min, self.l_max,
            )
        return updates

    def grow(self, min_corner: Array, max_corner: Array) -> None:
        """Enlarge the box to also cover [min_corner, max_corner], keeping all data."""
        lo, hi = self.voxel_box(min_corner, max_corner)
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
