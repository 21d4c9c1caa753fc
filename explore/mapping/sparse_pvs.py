"""The sparse PVS: the same probabilistic voxel space over a region of any size, stored in hashed blocks.

A dense grid's memory grows with the region's volume (a 5 x 5 x 2 m room at 5 mm is 400 M
voxels); the sparse PVS allocates 8 x 8 x 8 voxel blocks only where rays pass (as voxblox and
Open3D's hashed voxel blocks; OctoMap's octree keeps memory proportional to the observed space
the same way), so memory follows the observed free space and surface, and a region may be a
room or kilometres wide. It is a :class:`~explore.mapping.pvs.PVS` with the same Bayes update
(Kriegel thesis Eq. 3.4, Fig. 3.10, or OctoMap's insertPointCloud), point and ray queries,
entropy casting (IROS 2012 Eq. 1-2, thesis Eq. 4.32), ``.bt`` export and ``.npz`` files; the
whole-grid views (``states``, the distance field, per-voxel features, pictures) are taken on a
dense :meth:`SparsePVS.window` of the part one needs. :func:`make_pvs` chooses the layout by size.
Speed and memory against OctoMap at room scale: ``benchmarks/pvs_room.py``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

import explore.mapping.sparse_kernels as S
from explore.core import Array, BadInput, Points3
from explore.mapping.octomap_bt import CENTER, DEPTH, tree_of_blocks, write_tree
from explore.mapping.pvs import PVS
from explore.mapping.pvs_grid import FORMAT, THRESHOLDS, logit
from explore.sim import Scan, TriMesh

DENSE_MAX_VOXELS = 32_000_000  # auto layout: a dense grid up to this size (128 MB of log-odds), else sparse
WINDOW_MAX_VOXELS = 64_000_000  # the largest dense window the sparse PVS hands out
MARKED_MAX_BLOCKS = 256_000_000  # the largest block bitmap of probability_below (256 MB), else hash lookups
KEY_LIMIT = S.KEY_OFFSET  # voxel keys stay within [-2^20, 2^20) per axis


class SparsePVS(PVS):
    """Probabilistic voxel space in hashed 8^3-voxel blocks over the box [min_corner, max_corner].

    Takes the parameters of :class:`~explore.mapping.pvs.PVS`. The box only bounds the rays
    (voxels outside it are never updated) and the counts; it costs no memory, so it may be large:
    every voxel key must lie within +-2^20 voxels of the origin (5.2 km at 5 mm).
    """

    _NO_STAMPS = np.zeros((0, S.BLOCK_VOXELS), np.int32)  # stamps live only while a scan is integrated

    def _allocate(self, lo: Array, hi: Array, extent: np.ndarray) -> None:
        self._check_keys(self.lattice, self.lattice + extent)
        self._extent = np.asarray(extent, dtype=np.int64)
        self._store = self._packed(S.empty_store())

    def _check_keys(self, first: np.ndarray, end: np.ndarray) -> None:
        if first.min() < -KEY_LIMIT or end.max() > KEY_LIMIT or math.prod(int(v) for v in end - first) >= 2**62:
            raise BadInput("region", None, f"a sparse PVS at {1e3 * self.resolution:g} mm reaches only "
                           f"{KEY_LIMIT * self.resolution:.4g} m from the origin on each axis and holds at most "
                           "2^62 voxels (flat voxel ids)")

    # -- geometry and memory -----------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(n) for n in self._extent)  # type: ignore[return-value]

    @property
    def nbytes(self) -> int:
        """Bytes held between scans: the block pool (log-odds) and the hash table. While a scan is integrated,
        the blocks it passes are expanded and get frame stamps (4 bytes per voxel) beside them."""
        return int(sum(array.nbytes for array in self._store))

    @property
    def blocks(self) -> int:
        """Blocks in the map (stored or uniform)."""
        return int(self._store[6][S.BLOCKS])

    @property
    def stored_blocks(self) -> int:
        """Blocks with a pool row (not uniform)."""
        meta = self._store[6]
        return int(meta[S.HIGH] - meta[S.FREE_ROWS])

    def grow(self, min_corner: Array, max_corner: Array) -> None:
        """Enlarge the box to also cover [min_corner, max_corner]; no data moves (keys are absolute)."""
        lo, hi = self.voxel_box(min_corner, max_corner)
        first = np.minimum(self.lattice, lo)
        end = np.maximum(self.lattice + self._extent, hi)
        self._check_keys(first, end)
        self.lattice, self._extent = first, end - first
        self._touch()

    # -- update ------------------------------------------------------------------------
    def _apply(self, scan: Scan, origins: Points3, directions: Points3, ranges: Array, sigmas: Array,
               starts: np.ndarray) -> int:
        keys, rows, fill, values, _, free, meta = self._store
        store = (keys, rows, fill, values, np.zeros(values.shape, np.int32), free, meta)  # frame stamps of this scan
        if self.mode == "sensor_model":
            free_from = -np.inf if scan.clear_from_origin else float(scan.min_range)
            updates, store = S.update_sensor_model(
                store, self.hit_wins, self.lattice, self._extent, self.resolution, origins,
                directions, ranges, sigmas, starts, bool(scan.no_return_clears), free_from, float(scan.max_range),
                self.k_sigma, self.sigma_floor, logit(self.p_free), logit(self.p_occ), self.l_min, self.l_max,
            )
        else:
            updates, store = S.update_octomap(
                store, self.lattice, self._extent, self.resolution, origins, directions, ranges,
                starts, bool(scan.no_return_clears), float(scan.max_range), logit(self.p_occ), logit(self.p_free),
                self.l_min, self.l_max,
            )
        self._store = self._packed(store)
        return updates

    def _packed(self, store: tuple) -> tuple:
        """The store after a scan: uniform blocks folded to one value, the pool cut to the rows in use (when
        a scan's expansions left over an eighth of it free), no frame stamps."""
        S.compact(store)
        keys, rows, fill, values, _, free, meta = store
        if 8 * (meta[S.HIGH] - meta[S.FREE_ROWS]) < 7 * len(values):
            used = S.pack_rows(store)
            values, free = values[:used].copy(), np.zeros(used, np.int32)
        return keys, rows, fill, values, self._NO_STAMPS, free, meta

    # -- voxel access ------------------------------------------------------------------
    def log_odds_at(self, points: Points3) -> np.ndarray:
        ijk, inside = self.index(points)
        lo = np.zeros(len(ijk), dtype=np.float32)
        lo[inside] = S.lookup(self._store, np.ascontiguousarray(ijk[inside] + self.lattice))
        return lo

    def probability_below(self, points: Points3, p: float) -> np.ndarray:
        """As :meth:`PVS.probability_below`, with the hash table asked only for points in blocks that hold a
        voxel of probability p or more (a bitmap of those blocks, built once per map version): a robot
        pose mostly lies in free or unknown space, where this skips the table."""
        marked = self._marked_blocks(p) if p > 0.5 else None
        if marked is None:
            return super().probability_below(points, p)
        pts = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
        lo = S.lookup_marked(self._store, *marked, self.lattice, self._extent, 1.0 / self.resolution, pts)
        below = np.ones(len(pts), dtype=bool)  # log-odds 0: probability 0.5 < p
        looked = np.flatnonzero(lo)
        below[looked] = 1.0 / (1.0 + np.exp(-lo[looked].astype(np.float64))) < p
        return below

    def _marked_blocks(self, p: float) -> tuple[np.ndarray, np.ndarray] | None:
        """(bitmap, first block) of the blocks whose largest probability is p or more (with a margin far
        above rounding, so every other voxel is surely below p); None if the bitmap would be too large."""
        key = f"marked {p!r}"
        cached = self._cache.get(key)
        if cached is None or cached[0] != self.version:
            coords, peak = S.block_peaks(self._store)
            coords = coords[peak >= np.float32(logit(p) - 1e-3)]
            first = coords.min(axis=0) if len(coords) else np.zeros(3, np.int64)
            size = tuple(int(v) for v in coords.max(axis=0) - first + 1) if len(coords) else (0, 0, 0)
            marked = None
            if math.prod(size) <= MARKED_MAX_BLOCKS:
                grid = np.zeros(size, np.bool_)
                grid[tuple((coords - first).T)] = True
                marked = (grid, first)
            self._cache[key] = cached = (self.version, marked)
        return cached[1]

    def _stored(self, lo: np.ndarray | None = None, hi: np.ndarray | None = None,
                at_least: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Absolute voxel keys (m, 3) and log-odds (m,) of every observed voxel (log-odds not 0), of the blocks
        that meet the voxel box [lo, hi) if one is given, whose log-odds reach ``at_least`` if given (a
        room's free space is hundreds of millions of voxels: filter before the keys are made)."""
        coords, rows, fill = S.blocks_of(self._store)
        if lo is not None and hi is not None:
            meet = np.all(((coords + 1) << S.SHIFT > lo) & (coords << S.SHIFT < hi), axis=1)
            coords, rows, fill = coords[meet], rows[meet], fill[meet]
        stored = rows >= 0
        values = self._store[3][rows[stored]]
        floor = -np.inf if at_least is None else np.float32(at_least)
        block, local = np.nonzero((values != 0.0) & (values >= floor))
        uniform = np.flatnonzero(~stored & (fill != 0.0) & (fill >= floor))
        value = np.concatenate([values[block, local], np.repeat(fill[uniform], S.BLOCK_VOXELS)])
        block = np.concatenate([np.flatnonzero(stored)[block], np.repeat(uniform, S.BLOCK_VOXELS)])
        local = np.concatenate([local, np.tile(np.arange(S.BLOCK_VOXELS), len(uniform))])
        offset = np.column_stack([local >> (2 * S.SHIFT), (local >> S.SHIFT) & S.LOCAL, local & S.LOCAL])
        return (coords[block] << S.SHIFT) + offset, value

    def window(self, min_corner: Array, max_corner: Array) -> PVS:
        """A dense :class:`PVS` with the same parameters and log-odds over [min_corner, max_corner] (clipped
        to the box): for the whole-grid views (states, distance field, features, pictures) of one part."""
        lo, hi = self.voxel_box(min_corner, max_corner)
        lo, hi = np.maximum(lo, self.lattice), np.minimum(hi, self.lattice + self._extent)
        hi = np.maximum(hi, lo + 1)
        if float(np.prod(hi - lo)) > WINDOW_MAX_VOXELS:
            raise ValueError(f"a dense window of {' x '.join(str(int(v)) for v in hi - lo)} voxels is more than "
                             f"{WINDOW_MAX_VOXELS / 1e6:g} M: ask for a smaller part")
        dense = PVS(lo * self.resolution, hi * self.resolution, self.resolution, clamp=self.clamp,
                    **{k: v for k, v in self._params().items() if k not in ("format", "resolution", "clamp")})
        keys, values = self._stored(lo, hi)
        inside = np.all((keys >= lo) & (keys < hi), axis=1)
        ijk = keys[inside] - dense.lattice
        dense.log_odds[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = values[inside]
        dense._touch()
        return dense

    def _occupied_box(self, p_min: float) -> tuple[Array, Array] | None:
        keys, _ = self._stored(at_least=logit(p_min))
        if not len(keys):
            return None
        return keys.min(axis=0) * self.resolution, (keys.max(axis=0) + 1) * self.resolution

    # -- queries -----------------------------------------------------------------------
    def _ray_kernels(self):  # noqa: ANN202
        return S

    def _ray_storage(self) -> tuple:
        return self._store, self.lattice, self._extent, self.resolution

    def _entropy_visited(self, o: Points3, d: Points3, r: Array, min_range: float, l_stop: float) -> tuple:
        return S.entropy_visited(*self._ray_storage(), o, d, r, min_range, l_stop)

    def counts(self, thresholds: str = "validation") -> dict[str, int]:
        """Voxel counts {unknown, free, occupied} in the box; never-observed space is unknown."""
        _, rows, fill = S.blocks_of(self._store)
        values = self._store[3][rows[rows >= 0]]
        values = values[values != 0.0]
        fill = fill[(rows < 0) & (fill != 0.0)]
        counts = np.bincount(self._classify(values, thresholds), minlength=3)
        counts += S.BLOCK_VOXELS * np.bincount(self._classify(fill, thresholds), minlength=3)
        unobserved = self._classify(np.zeros(1, np.float32), thresholds)[0]  # "planning" calls it an obstacle
        counts[unobserved] += math.prod(self.shape) - len(values) - S.BLOCK_VOXELS * len(fill)
        return {"unknown": int(counts[1]), "free": int(counts[0]), "occupied": int(counts[2])}

    def count(self, state: int, thresholds: str = "validation") -> int:
        return self.counts(thresholds)[("free", "unknown", "occupied")[state]]

    def non_free_count(self) -> int:
        """N_v of thesis Eq. 4.32 over the box: every voxel that is not free (p >= 0.05)."""
        cached = self._cache.get("n_v")
        if cached is None or cached[0] != self.version:
            free = self.counts("planning")["free"]
            self._cache["n_v"] = cached = (self.version, math.prod(self.shape) - free)
        return cached[1]

    def states(self, thresholds: str = "validation") -> np.ndarray:
        raise ValueError("a sparse PVS has no whole-grid state array: take window(lo, hi).states() of a part")

    def obstacle_grid(self, free_below: float = THRESHOLDS["planning"][0]) -> np.ndarray:
        raise ValueError("a sparse PVS has no whole-grid obstacle array: take window(lo, hi).obstacle_grid()")

    def distance_field(self) -> np.ndarray:
        raise ValueError("a sparse PVS has no whole-grid distance field: take window(lo, hi).distance_field()")

    def is_free(self, points: Points3, clearance: float = 0.0, outside_free: bool = True) -> np.ndarray:
        """As :meth:`PVS.is_free`, on a dense window around the points wide enough for the clearance."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if not len(pts):
            return np.zeros(0, dtype=bool)
        margin = clearance + 2.0 * self.resolution
        _, inside = self.index(pts)
        out = np.full(len(pts), bool(outside_free))
        if inside.any():
            part = self.window(pts[inside].min(axis=0) - margin, pts[inside].max(axis=0) + margin)
            out[inside] = part.is_free(pts[inside], clearance, outside_free=False)
        return out

    def occupied_points(self, p_min: float = 0.75) -> Points3:
        keys, _ = self._stored(at_least=logit(p_min))
        return (keys + 0.5) * self.resolution

    def voxel_mesh(self, p_min: float = 0.75) -> TriMesh:
        box = self._occupied_box(p_min)
        if box is None:
            return TriMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32))
        return self.window(box[0] - self.resolution, box[1] + self.resolution).voxel_mesh(p_min)

    # -- features and pictures live on dense windows -----------------------------------
    def set_features(self, *args: Any, **kwargs: Any) -> None:
        raise ValueError("surface features are stored on a dense PVS: take window(lo, hi) of the object's region")

    def save_png(self, path: str | Path, axis: int = 2, index: int | None = None, title: str = "") -> None:
        """Picture of the dense window around the occupied voxels (see :meth:`PVS.save_png`)."""
        box = self._occupied_box(0.75)
        lo, hi = (self.min_corner, self.max_corner) if box is None else box
        self.window(lo, hi).save_png(path, axis, index, title or f"sparse PVS, {self.blocks} blocks")

    # -- files -------------------------------------------------------------------------
    def save_octomap(self, path: str | Path) -> int:
        coords, rows, fill = S.blocks_of(self._store)
        coords = coords + (CENTER >> S.SHIFT)
        if len(coords) and (coords.min() < 0 or coords.max() >= 1 << (DEPTH - S.SHIFT)):
            raise ValueError(f"{path}: the PVS reaches beyond OctoMap's key range (+-{CENTER} voxels from the origin)")
        stored = rows >= 0
        return write_tree(path, *tree_of_blocks(coords[stored], self._store[3][rows[stored]], coords[~stored],
                                                fill[~stored]), self.resolution)

    def save(self, path: str | Path) -> None:
        """Write the blocks, the box and the parameters to a ``.npz`` file (:meth:`load` reads it back)."""
        coords, rows, fill = S.blocks_of(self._store)
        stored = rows >= 0
        with open(path, "wb") as handle:
            np.savez_compressed(handle, layout=np.array("sparse"), block_coords=coords[stored],
                                block_log_odds=self._store[3][rows[stored]], uniform_coords=coords[~stored],
                                uniform_log_odds=fill[~stored], lattice=self.lattice,
                                extent=self._extent, beam_keys=self._beam_keys,
                                params=np.array(json.dumps(self._params())))

    @classmethod
    def load(cls, path: str | Path) -> SparsePVS:
        with np.load(path, allow_pickle=False) as data:
            if "layout" not in data.files or str(data["layout"]) != "sparse":
                raise ValueError(f"{path}: not a sparse PVS file")
            params = json.loads(str(data["params"]))
            if params.pop("format", None) != FORMAT:
                raise ValueError(f"{path}: not a PVS file of format {FORMAT}")
            resolution = params.pop("resolution")
            lattice, extent = data["lattice"].astype(np.int64), data["extent"].astype(np.int64)
            pvs = cls(lattice * resolution, (lattice + extent) * resolution, resolution,
                      clamp=tuple(params.pop("clamp")), **params)
            pvs.lattice, pvs._extent = lattice, extent
            uniform = np.repeat(data["uniform_log_odds"].astype(np.float32)[:, None], S.BLOCK_VOXELS, axis=1)
            keys, rows, fill, values, _, free, meta = pvs._store
            store = S.insert_blocks(
                (keys, rows, fill, values, np.zeros(values.shape, np.int32), free, meta),
                np.concatenate([data["block_coords"], data["uniform_coords"]]).astype(np.int64),
                np.concatenate([data["block_log_odds"].astype(np.float32), uniform]))
            pvs._store = pvs._packed(store)
            pvs._beam_keys = data["beam_keys"].astype(np.int64)
        return pvs


def make_pvs(min_corner: Array, max_corner: Array, resolution: float, layout: str = "auto",
             margin: float | None = None, **kwargs: Any) -> PVS:
    """A PVS over a region plus ``margin`` (default two voxels): ``layout`` "dense", "sparse", or "auto"
    (dense up to :data:`DENSE_MAX_VOXELS` voxels, where a flat array is fastest, sparse beyond)."""
    if layout not in ("auto", "dense", "sparse"):
        raise ValueError(f"unknown PVS layout {layout!r} (valid: auto, dense, sparse)")
    margin = 2.0 * resolution if margin is None else float(margin)
    lo = np.asarray(min_corner, dtype=float) - margin
    hi = np.asarray(max_corner, dtype=float) + margin
    if layout == "auto":
        voxels = float(np.prod(np.ceil((hi - lo) / resolution) + 1))
        layout = "dense" if voxels <= DENSE_MAX_VOXELS else "sparse"
    return (PVS if layout == "dense" else SparsePVS)(lo, hi, resolution, **kwargs)
