"""The PVS's voxel grid: log-odds conversions, the state thresholds, ray-query results and the memory check that
refuses a grid that would not fit before it is allocated."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from explore.core import Array, BadInput

FREE, UNKNOWN, OCCUPIED = 0, 1, 2

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

FORMAT = 1


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
