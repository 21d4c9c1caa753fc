"""numba kernels of the probabilistic voxel space: ray queries (first occupied voxel, entropy, counts).

Storage choice
--------------
The PVS keeps a **dense float32 log-odds grid** (C order, flat index ``(ix*ny + iy)*nz + iz``)
over the region of interest, lattice-aligned with OctoMap's keys (voxel edges at integer
multiples of the resolution). A voxel visit is one add (or load) at an address that changes
by a constant stride per DDA step, with no hashing, no tree descent and no key sets. Measured
on this 2-core machine (``benchmarks/pvs_vs_octomap.py``, same scans and rays, the grid
covering every sensor origin so both maps traverse identical voxels; full table in
:mod:`explore.mapping.pvs`): the OctoMap-compatible update integrates 1.2-3.7 M beams/s, 7-15x
``pyoctomap`` ``insertPointCloud`` (lazy evaluation, one ``updateInnerOccupancy`` per scan,
0.08-0.5 M beams/s) with 100 % cell-state agreement; the sensor-noise model runs at
0.7-2.9 M beams/s (5-9x OctoMap); entropy ray casting with visited marking reaches
80-180 M voxel visits/s on one core. Memory is small at the resolutions we use: a 0.3 m
object region at 5 mm is 216 k voxels (0.9 MB), a 1 x 1 x 0.5 m scene at 1 cm 0.5 M voxels
(2 MB); even the benchmark's 1.4 x 1.4 x 0.8 m box at 1 cm is 1.5 M voxels (6 MB). Rooms at
object resolution take the block-sparse layout (:mod:`explore.mapping.sparse_pvs`, chosen by
:func:`~explore.mapping.make_pvs` beyond 32 M voxels).

The traversal itself is :mod:`explore.mapping.traversal`, the updates :mod:`explore.mapping.pvs_updates`.

Every kernel here is ``@njit(cache=True, nogil=True)``. Large read-only ray batches run in
parallel over rays (``prange``, :func:`cast_rays`); small ones (one candidate's beams) and the
visited-marking entropy sum run serially, which is deterministic and does not suffer when
other processes hold the cores. Updates run serially: beams of one scan share the voxels near
the sensor, and lost float updates would break the Bayes bookkeeping.
"""

from __future__ import annotations

import math
import os
import types

import numba
import numpy as np
from numba import njit, prange

from explore.mapping.traversal import next_axis, ray_start, step

if "NUMBA_THREADING_LAYER" not in os.environ and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    # the TBB in the wheel set is too old and numba warns when it tries it first
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

LN2 = math.log(2.0)


@njit(cache=True, nogil=True, inline="always")
def _entropy(lo):
    """Entropy in bits of a voxel with log-odds ``lo`` (IROS 2012 Eq. 1)."""
    p = 1.0 / (1.0 + math.exp(-lo))
    if p <= 0.0 or p >= 1.0:
        return 0.0
    return -(p * math.log(p) + (1.0 - p) * math.log(1.0 - p)) / LN2


@njit(cache=True, nogil=True, inline="always")
def tally(lo, last_l, last_h, h_sum, n_occ, n_unk, l_occ_from, l_free_below):
    """Add one voxel a cast ray crosses to its sums, for both layouts: entropy (IROS 2012 Eq. 1-2; a run of
    voxels with the same log-odds reuses the last entropy) and the occupied / unknown counts. Returns the
    updated ``last_l, last_h, h_sum, n_occ, n_unk`` and whether the voxel is unknown."""
    if lo != last_l:
        last_l = lo
        last_h = _entropy(lo)
    h_sum += last_h
    if lo >= l_occ_from:
        return last_l, last_h, h_sum, n_occ + 1, n_unk, False
    if lo >= l_free_below:
        return last_l, last_h, h_sum, n_occ, n_unk + 1, True
    return last_l, last_h, h_sum, n_occ, n_unk, False


@njit(cache=True, nogil=True, inline="always")
def _is_free_neighbour(flat, i0, i1, i2, n0, n1, n2, l_free_below):
    """True if one of the 6 neighbours of voxel (i0, i1, i2) is free."""
    base = (i0 * n1 + i1) * n2 + i2
    if i0 > 0 and flat[base - n1 * n2] < l_free_below:
        return True
    if i0 < n0 - 1 and flat[base + n1 * n2] < l_free_below:
        return True
    if i1 > 0 and flat[base - n2] < l_free_below:
        return True
    if i1 < n1 - 1 and flat[base + n2] < l_free_below:
        return True
    if i2 > 0 and flat[base - 1] < l_free_below:
        return True
    if i2 < n2 - 1 and flat[base + 1] < l_free_below:
        return True
    return False


@njit(cache=True, nogil=True, parallel=True)
def cast_rays(
    grid, lat, res, origins, directions, max_ranges, min_range, l_stop, l_free_below,
    l_occ_from, offsets, out_voxels, want_voxels,
):
    """Ray queries for many rays at once (parallel over rays, read-only).

    Each ray runs from its origin to ``max_ranges[i]`` and stops after the first voxel with
    log-odds >= ``l_stop`` (p >= 0.95: occupied / occluding). Per ray: distance to that
    voxel (``t_in``, inf if none), its flat index (-1), the entropy sum in bits of the
    voxels crossed up to and including it that lie beyond ``min_range`` (IROS 2012 Eq. 1-2),
    and counts of unknown, occupied and frontier voxels (unknown = between the thresholds;
    frontier = unknown with a free 6-neighbour), and the number of voxels traversed. With
    ``want_voxels`` the flat indices are written to ``out_voxels[offsets[i]:]``.
    """
    n0, n1, n2 = grid.shape
    flat = grid.reshape(-1)
    inv_res = 1.0 / res
    n = origins.shape[0]
    hit_t = np.full(n, np.inf)
    hit_v = np.full(n, -1, np.int64)
    entropy = np.zeros(n)
    unknown = np.zeros(n, np.int64)
    occupied = np.zeros(n, np.int64)
    frontier = np.zeros(n, np.int64)
    visits = np.zeros(n, np.int64)
    for r in prange(n):
        (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
            origins[r, 0], origins[r, 1], origins[r, 2],
            directions[r, 0], directions[r, 1], directions[r, 2],
            0.0, max_ranges[r], lat, inv_res, res, n0, n1, n2,
        )
        if not ok:
            continue
        idx = (i0 * n1 + i1) * n2 + i2
        t_in = t0
        h_sum = 0.0
        last_l = np.float32(np.nan)
        last_h = 0.0
        k = 0
        n_unk = 0
        n_occ = 0
        n_fr = 0
        while True:
            dd = next_axis(tm0, tm1, tm2)
            t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
            lo = flat[idx]
            if want_voxels:
                out_voxels[offsets[r] + k] = idx
            k += 1
            if t_exit > min_range:
                last_l, last_h, h_sum, n_occ, n_unk, is_unknown = tally(
                    lo, last_l, last_h, h_sum, n_occ, n_unk, l_occ_from, l_free_below)
                if is_unknown and _is_free_neighbour(flat, i0, i1, i2, n0, n1, n2, l_free_below):
                    n_fr += 1
            if lo >= l_stop:
                hit_t[r] = t_in
                hit_v[r] = idx
                break
            if t_exit >= t1:
                break
            t_in = t_exit
            i0, i1, i2, tm0, tm1, tm2, inside = step(
                dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, n0, n1, n2)
            if not inside:
                break
            idx = (i0 * n1 + i1) * n2 + i2
        entropy[r] = h_sum
        unknown[r] = n_unk
        occupied[r] = n_occ
        frontier[r] = n_fr
        visits[r] = k
    return hit_t, hit_v, entropy, unknown, occupied, frontier, visits


def serial_build(kernel):  # noqa: ANN001, ANN201 - a numba dispatcher in, one out
    """A serial, cached build of a ``parallel=True`` kernel (``prange`` runs as ``range``).

    It compiles a copy of the kernel's Python function under its own name: numba's cache keys an
    entry by the function's name, bytecode and signature, not by ``parallel``, so a build of the same
    function would load whichever of the two was compiled first (a "parallel" kernel running on one
    thread, or the other way round).
    """
    func = kernel.py_func
    copy = types.FunctionType(func.__code__.replace(co_name=func.__name__ + "_serial"), func.__globals__,
                              func.__name__ + "_serial", func.__defaults__, func.__closure__)
    copy.__qualname__ = func.__qualname__ + "_serial"
    copy.__doc__ = func.__doc__
    return njit(cache=True, nogil=True)(copy)


cast_rays_serial = serial_build(cast_rays)
"""Serial build of :func:`cast_rays`: no thread start-up, no slow-down when other processes hold the
cores; used for small batches."""


@njit(cache=True, nogil=True)
def entropy_visited(grid, visited, stamp, lat, res, origins, directions, max_ranges, min_range, l_stop):
    """Entropy sum (bits) over the beams of one candidate, each voxel counted once.

    Thesis Eq. 4.32 numerator with visited marking (Sec. 4.5.3): beams stop after the first
    voxel with log-odds >= ``l_stop``; a voxel already counted by an earlier beam of the
    candidate adds nothing (``visited[v] == stamp``). Serial, so the result is deterministic.
    Returns (entropy sum, distinct voxels counted, voxel visits).
    """
    n0, n1, n2 = grid.shape
    flat = grid.reshape(-1)
    vflat = visited.reshape(-1)
    inv_res = 1.0 / res
    total = 0.0
    distinct = 0
    visits = 0
    last_l = np.float32(np.nan)
    last_h = 0.0
    for r in range(origins.shape[0]):
        (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
            origins[r, 0], origins[r, 1], origins[r, 2],
            directions[r, 0], directions[r, 1], directions[r, 2],
            0.0, max_ranges[r], lat, inv_res, res, n0, n1, n2,
        )
        if not ok:
            continue
        idx = (i0 * n1 + i1) * n2 + i2
        while True:
            dd = next_axis(tm0, tm1, tm2)
            t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
            lo = flat[idx]
            visits += 1
            if t_exit > min_range and vflat[idx] != stamp:
                vflat[idx] = stamp
                if lo != last_l:
                    last_l = lo
                    last_h = _entropy(lo)
                total += last_h
                distinct += 1
            if lo >= l_stop or t_exit >= t1:
                break
            i0, i1, i2, tm0, tm1, tm2, inside = step(
                dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, n0, n1, n2)
            if not inside:
                break
            idx = (i0 * n1 + i1) * n2 + i2
    return total, distinct, visits
