"""numba kernels of the sparse PVS: a hashed grid of 8 x 8 x 8 voxel blocks.

Storage (as voxblox's and Open3D's hashed blocks): a block is allocated the first time a ray
passes through it; an open-addressing hash table (linear probing, load at most one half) maps a
block's packed coordinates to its row in a pool of 512 float32 log-odds and 512 int32 frame
stamps. A block whose 512 voxels all hold one value is kept as that value alone and its row goes
back to a free list (:func:`compact`, run after every scan): OctoMap prunes eight equal children
into their parent the same way, and most free space a depth camera sees once or twice is uniform.
A voxel never allocated reads as log-odds 0 (unknown). The traversal is the dense PVS's own
(:mod:`explore.mapping.traversal`, OctoMap's conventions) over the map's bounds, so both layouts
visit the same voxels and apply the same Bayes updates (Kriegel thesis Eq. 3.4, Fig. 3.10) and
OctoMap's insertPointCloud semantics. Within a ray, the hash is probed only when the ray enters
another block.

The store is one tuple ``(keys, rows, fill, values, marks, free, meta)``: per table slot the
block key, its pool row (-1: uniform) and its uniform value; per pool row the log-odds and the
stamps; the free rows; and ``meta`` = [rows used (high-water mark), free rows, blocks]. Kernels
that may allocate return the store (re-allocated when it had to grow: the pool by half its size,
the table to twice).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from explore.mapping.pvs_kernels import _entropy, serial_build, tally
from explore.mapping.pvs_updates import FREE, OCCUPIED, STAMP, beam_segment, voxel_update
from explore.mapping.traversal import next_axis, ray_start, step, voxel_entry

SHIFT = 3  # blocks of 2^3 = 8 voxels per edge
BLOCK = 1 << SHIFT
BLOCK_VOXELS = BLOCK**3
LOCAL = BLOCK - 1
KEY_OFFSET = 1 << 20  # packed coordinates: 21 bits per axis, [-2^20, 2^20) voxels or blocks
EMPTY = -1
HIGH, FREE_ROWS, BLOCKS = 0, 1, 2  # fields of ``meta``


def empty_store(rows: int = 64, slots: int = 256) -> tuple:
    """A store without blocks."""
    return (np.full(slots, EMPTY, np.int64), np.full(slots, -1, np.int32), np.zeros(slots, np.float32),
            np.zeros((rows, BLOCK_VOXELS), np.float32), np.zeros((rows, BLOCK_VOXELS), np.int32),
            np.zeros(rows, np.int32), np.zeros(3, np.int64))


@njit(cache=True, nogil=True, inline="always")
def pack(a0, a1, a2):
    """One int64 key of three coordinates in [-2^20, 2^20) (21 bits each)."""
    return ((a0 + KEY_OFFSET) << 42) | ((a1 + KEY_OFFSET) << 21) | (a2 + KEY_OFFSET)


@njit(cache=True, nogil=True, inline="always")
def _home(key, mask):
    h = (key ^ (key >> 31)) * 0x7FB5D329728EA185
    return (h ^ (h >> 29)) & mask


@njit(cache=True, nogil=True, inline="always")
def find(store, key):
    """(pool row, value) of the block with ``key``: row -1 for a uniform block (its value) or a missing
    one (value 0, unknown)."""
    keys, rows, fill = store[0], store[1], store[2]
    mask = keys.shape[0] - 1
    i = _home(key, mask)
    while True:
        k = keys[i]
        if k == key:
            return rows[i], fill[i]
        if k == EMPTY:
            return -1, np.float32(0.0)
        i = (i + 1) & mask


@njit(cache=True, nogil=True, inline="always")
def _new_row(store):
    free, meta = store[5], store[6]
    if meta[FREE_ROWS] > 0:
        meta[FREE_ROWS] -= 1
        return free[meta[FREE_ROWS]]
    meta[HIGH] += 1
    return meta[HIGH] - 1


@njit(cache=True, nogil=True, inline="always")
def _give_row(store, key):
    """The block with ``key`` has no pool row: add it to the table if new, and give it a row filled with
    its uniform value (0 for a new block)."""
    keys, rows, fill, values, marks, meta = store[0], store[1], store[2], store[3], store[4], store[6]
    mask = keys.shape[0] - 1
    i = _home(key, mask)
    while True:
        k = keys[i]
        if k == key:
            break
        if k == EMPTY:
            keys[i] = key
            fill[i] = 0.0
            meta[BLOCKS] += 1
            break
        i = (i + 1) & mask
    row = _new_row(store)
    values[row, :] = fill[i]
    marks[row, :] = 0
    rows[i] = row
    return row


@njit(cache=True, nogil=True, inline="always")
def reserve(store, need):
    """Room for ``need`` more written blocks: the pool grows by half and the table doubles when they must."""
    keys, rows, fill, values, marks, free, meta = store
    spare = values.shape[0] - meta[HIGH] + meta[FREE_ROWS]
    if need > spare:
        cap = max(values.shape[0] + values.shape[0] // 2, values.shape[0] + need - spare)
        high = meta[HIGH]
        grown = np.zeros((cap, BLOCK_VOXELS), np.float32)
        grown[:high] = values[:high]
        values = grown
        stamps = np.zeros((cap, BLOCK_VOXELS), np.int32)
        stamps[:high] = marks[:high]
        marks = stamps
        rows_free = np.zeros(cap, np.int32)
        rows_free[: meta[FREE_ROWS]] = free[: meta[FREE_ROWS]]
        free = rows_free
    size = keys.shape[0]
    while 2 * (meta[BLOCKS] + need) > size:
        size *= 2
    if size != keys.shape[0]:
        old_keys, old_rows, old_fill = keys, rows, fill
        keys = np.full(size, EMPTY, np.int64)
        rows = np.full(size, -1, np.int32)
        fill = np.zeros(size, np.float32)
        mask = size - 1
        for j in range(old_keys.shape[0]):
            key = old_keys[j]
            if key != EMPTY:
                i = _home(key, mask)
                while keys[i] != EMPTY:
                    i = (i + 1) & mask
                keys[i] = key
                rows[i] = old_rows[j]
                fill[i] = old_fill[j]
    return keys, rows, fill, values, marks, free, meta


@njit(cache=True, nogil=True)
def compact(store):
    """Stored blocks whose 512 voxels hold one value become that value; their rows go to the free list
    (a mixed block is told after a few voxels). Returns the number of blocks made uniform."""
    keys, rows, fill, values, marks, free, meta = store
    made = 0
    for i in range(keys.shape[0]):
        row = rows[i]
        if keys[i] == EMPTY or row < 0:
            continue
        v = values[row, 0]
        uniform = True
        for k in range(1, BLOCK_VOXELS):
            if values[row, k] != v:
                uniform = False
                break
        if uniform:
            fill[i] = v
            rows[i] = -1
            free[meta[FREE_ROWS]] = row
            meta[FREE_ROWS] += 1
            made += 1
    return made


@njit(cache=True, nogil=True)
def pack_rows(store):
    """Move the stored blocks of rows past the last one in use into the free rows below it, so that the
    pool's first ``rows in use`` rows hold every stored block; returns that number."""
    keys, rows, fill, values, marks, free, meta = store
    used = meta[HIGH] - meta[FREE_ROWS]
    slot_of = np.full(meta[HIGH], -1, np.int64)
    for i in range(keys.shape[0]):
        if keys[i] != EMPTY and rows[i] >= 0:
            slot_of[rows[i]] = i
    hole = 0
    for row in range(used, meta[HIGH]):
        if slot_of[row] < 0:
            continue
        while slot_of[hole] >= 0:
            hole += 1
        values[hole] = values[row]
        rows[slot_of[row]] = hole
        slot_of[hole] = slot_of[row]
        slot_of[row] = -1
    meta[HIGH] = used
    meta[FREE_ROWS] = 0
    return used


@njit(cache=True, nogil=True, inline="always")
def _blocks_bound(length, res):
    """Most blocks a segment of ``length`` metres can cross."""
    return 3 * (int(length / (BLOCK * res)) + 2)


@njit(cache=True, nogil=True, inline="always")
def _local(a0, a1, a2):
    return ((a0 & LOCAL) << (2 * SHIFT)) | ((a1 & LOCAL) << SHIFT) | (a2 & LOCAL)


@njit(cache=True, nogil=True, inline="always")
def value_at(store, a0, a1, a2):
    """Log-odds of the voxel with absolute key (a0, a1, a2); 0 where no block is allocated."""
    row, value = find(store, pack(a0 >> SHIFT, a1 >> SHIFT, a2 >> SHIFT))
    if row < 0:
        return value
    return store[3][row, _local(a0, a1, a2)]


@njit(cache=True, nogil=True)
def _sensor_beam(
    store, tag, marking, lat, ext, res, ox, oy, oz, ux, uy, uz, d, s,
    no_return_clears, free_from, max_range, k_sigma, sigma_floor, l_free, l_occ, l_min, l_max,
):
    """One beam of :func:`update_sensor_model` (same rule as the dense PVS's); returns the updates."""
    values, marks = store[3], store[4]
    use, hit, band, free_to, t_lo, t_end, inv2s2 = beam_segment(
        d, s, marking, no_return_clears, free_from, max_range, k_sigma, sigma_floor)
    if not use:
        return 0
    (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
        ox, oy, oz, ux, uy, uz, t_lo, t_end, lat, 1.0 / res, res, ext[0], ext[1], ext[2],
    )
    if not ok:
        return 0
    count = 0
    a0, a1, a2 = i0 + lat[0], i1 + lat[1], i2 + lat[2]
    block = pack(a0 >> SHIFT, a1 >> SHIFT, a2 >> SHIFT)
    row, _f = find(store, block)
    if row < 0:
        row = _give_row(store, block)
    t_in = voxel_entry(tm0, tm1, tm2, td0, td1, td2)
    while True:
        dd = next_axis(tm0, tm1, tm2)
        t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
        loc = _local(a0, a1, a2)
        kind, add = voxel_update(hit, d, t_in, t_exit, band, inv2s2, l_occ, marking, free_from, free_to)
        if kind == STAMP:
            marks[row, loc] = tag
        elif kind == OCCUPIED:
            values[row, loc] = min(max(values[row, loc] + np.float32(add), l_min), l_max)
            count += 1
        elif kind == FREE and marks[row, loc] != tag:
            values[row, loc] = max(values[row, loc] + l_free, l_min)
            count += 1
        if t_exit >= t1:
            break
        t_in = t_exit
        i0, i1, i2, tm0, tm1, tm2, inside = step(
            dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, ext[0], ext[1], ext[2])
        if not inside:
            break
        a0, a1, a2 = i0 + lat[0], i1 + lat[1], i2 + lat[2]
        key = pack(a0 >> SHIFT, a1 >> SHIFT, a2 >> SHIFT)
        if key != block:
            block = key
            row, _f = find(store, block)
            if row < 0:
                row = _give_row(store, block)
    return count


@njit(cache=True, nogil=True)
def update_sensor_model(
    store, hit_wins, lat, ext, res, origins, directions, ranges, sigmas, starts,
    no_return_clears, free_from, max_range, k_sigma, sigma_floor, l_free, l_occ, l_min, l_max,
):
    """Inverse sensor model with range noise (Kriegel thesis Sec. 3.3.2, Fig. 3.10) on the block grid.

    The rule of :func:`explore.mapping.pvs_updates.update_sensor_model`, beam by beam and frame by
    frame, allocating the blocks the beams pass; the frame stamps in ``store`` start empty (the
    store's stamps live only while one scan is integrated). Returns (updates, store).
    """
    lf = np.float32(l_free)
    lmin = np.float32(l_min)
    lmax = np.float32(l_max)
    count = 0
    for f in range(starts.shape[0] - 1):
        tag = np.int32(2 * (f + 1))
        for marking in (True, False):
            if marking and not hit_wins:
                continue
            for b in range(starts[f], starts[f + 1]):
                d = ranges[b]
                s = sigmas[b]
                # a beam without a return (NaN, or -t: freed to t) reaches at most the working range
                reach = max_range if not d >= 0.0 else d + k_sigma * (s if s > sigma_floor else sigma_floor)
                store = reserve(store, _blocks_bound(reach, res))
                count += _sensor_beam(
                    store, tag, marking, lat, ext, res,
                    origins[b, 0], origins[b, 1], origins[b, 2], directions[b, 0], directions[b, 1], directions[b, 2],
                    d, sigmas[b], no_return_clears, free_from, max_range, k_sigma, sigma_floor, lf, l_occ, lmin, lmax,
                )
    return count, store


@njit(cache=True, nogil=True)
def update_octomap(
    store, lat, ext, res, origins, directions, ranges, starts, no_return_clears,
    max_range, l_hit, l_miss, l_min, l_max,
):
    """OctoMap ``insertPointCloud`` semantics on the block grid, one cloud per frame segment.

    The rule of :func:`explore.mapping.pvs_updates.update_octomap`, frame stamps as in
    :func:`update_sensor_model`. Returns (updates, store).
    """
    inv_res = 1.0 / res
    lh = np.float32(l_hit)
    lm = np.float32(l_miss)
    lmin = np.float32(l_min)
    lmax = np.float32(l_max)
    count = 0
    occ = np.empty(origins.shape[0], np.int64)
    for f in range(starts.shape[0] - 1):
        occ_tag = np.int32(2 * (f + 1))
        free_tag = np.int32(2 * (f + 1) + 1)
        n_occ = 0
        for b in range(starts[f], starts[f + 1]):
            d = ranges[b]
            if math.isnan(d):
                continue
            e0 = int(math.floor((origins[b, 0] + directions[b, 0] * d) * inv_res))
            e1 = int(math.floor((origins[b, 1] + directions[b, 1] * d) * inv_res))
            e2 = int(math.floor((origins[b, 2] + directions[b, 2] * d) * inv_res))
            if 0 <= e0 - lat[0] < ext[0] and 0 <= e1 - lat[1] < ext[1] and 0 <= e2 - lat[2] < ext[2]:
                store = reserve(store, 1)
                row, _f = find(store, pack(e0 >> SHIFT, e1 >> SHIFT, e2 >> SHIFT))
                if row < 0:
                    row = _give_row(store, pack(e0 >> SHIFT, e1 >> SHIFT, e2 >> SHIFT))
                loc = _local(e0, e1, e2)
                if store[4][row, loc] != occ_tag:
                    store[4][row, loc] = occ_tag
                    occ[n_occ] = row * BLOCK_VOXELS + loc
                    n_occ += 1
        for b in range(starts[f], starts[f + 1]):
            d = ranges[b]
            if math.isnan(d):
                if not no_return_clears:
                    continue
                d = max_range
            store = reserve(store, _blocks_bound(d, res))
            values, marks = store[3], store[4]
            e0 = int(math.floor((origins[b, 0] + directions[b, 0] * d) * inv_res))
            e1 = int(math.floor((origins[b, 1] + directions[b, 1] * d) * inv_res))
            e2 = int(math.floor((origins[b, 2] + directions[b, 2] * d) * inv_res))
            (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
                origins[b, 0], origins[b, 1], origins[b, 2], directions[b, 0], directions[b, 1], directions[b, 2],
                0.0, d, lat, inv_res, res, ext[0], ext[1], ext[2],
            )
            if not ok:
                continue
            a0, a1, a2 = i0 + lat[0], i1 + lat[1], i2 + lat[2]
            block = pack(a0 >> SHIFT, a1 >> SHIFT, a2 >> SHIFT)
            row, _f = find(store, block)
            if row < 0:
                row = _give_row(store, block)
            while True:
                if a0 == e0 and a1 == e1 and a2 == e2:
                    break
                dd = next_axis(tm0, tm1, tm2)
                t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
                if t_exit > d:
                    break
                loc = _local(a0, a1, a2)
                m = marks[row, loc]
                if m != occ_tag and m != free_tag:
                    marks[row, loc] = free_tag
                    values[row, loc] = max(values[row, loc] + lm, lmin)
                    count += 1
                i0, i1, i2, tm0, tm1, tm2, inside = step(
                    dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, ext[0], ext[1], ext[2])
                if not inside:
                    break
                a0, a1, a2 = i0 + lat[0], i1 + lat[1], i2 + lat[2]
                key = pack(a0 >> SHIFT, a1 >> SHIFT, a2 >> SHIFT)
                if key != block:
                    block = key
                    row, _f = find(store, block)
                    if row < 0:
                        row = _give_row(store, block)
        values = store[3]
        for j in range(n_occ):
            row = occ[j] // BLOCK_VOXELS
            loc = occ[j] % BLOCK_VOXELS
            values[row, loc] = min(values[row, loc] + lh, lmax)
            count += 1
    return count, store


@njit(cache=True, nogil=True)
def lookup(store, voxels):
    """Log-odds (n,) of the voxels with absolute keys ``voxels`` (n, 3); 0 where unallocated."""
    out = np.zeros(voxels.shape[0], np.float32)
    for i in range(voxels.shape[0]):
        out[i] = value_at(store, voxels[i, 0], voxels[i, 1], voxels[i, 2])
    return out


@njit(cache=True, nogil=True)
def block_peaks(store):
    """Coordinates (m, 3) and largest log-odds (m,) of every block (a uniform block: its value)."""
    coords, rows, peak = blocks_of(store)
    values = store[3]
    for j in range(rows.shape[0]):
        if rows[j] >= 0:
            peak[j] = values[rows[j]].max()
    return coords, peak


@njit(cache=True, nogil=True)
def lookup_marked(store, marked, first, lat, ext, inv_res, points):
    """Log-odds (n,) at ``points`` whose block is set in ``marked`` (a dense block bitmap whose
    index 0 is block ``first``); 0 for every other point and outside the bounds [lat, lat + ext)."""
    out = np.zeros(points.shape[0], np.float32)
    for i in range(points.shape[0]):
        a0 = np.int64(np.floor(points[i, 0] * inv_res))
        a1 = np.int64(np.floor(points[i, 1] * inv_res))
        a2 = np.int64(np.floor(points[i, 2] * inv_res))
        if not (0 <= a0 - lat[0] < ext[0] and 0 <= a1 - lat[1] < ext[1] and 0 <= a2 - lat[2] < ext[2]):
            continue
        b0, b1, b2 = (a0 >> SHIFT) - first[0], (a1 >> SHIFT) - first[1], (a2 >> SHIFT) - first[2]
        if (0 <= b0 < marked.shape[0] and 0 <= b1 < marked.shape[1] and 0 <= b2 < marked.shape[2]
                and marked[b0, b1, b2]):
            out[i] = value_at(store, a0, a1, a2)
    return out


@njit(cache=True, nogil=True, inline="always")
def _free_neighbour(store, a0, a1, a2, lat, ext, l_free_below):
    """True if one of the 6 neighbours (inside the bounds) of voxel (a0, a1, a2) is free."""
    for k in range(6):
        b0, b1, b2 = a0, a1, a2
        step = 1 if k % 2 else -1
        if k < 2:
            b0 += step
        elif k < 4:
            b1 += step
        else:
            b2 += step
        if not (0 <= b0 - lat[0] < ext[0] and 0 <= b1 - lat[1] < ext[1] and 0 <= b2 - lat[2] < ext[2]):
            continue
        if value_at(store, b0, b1, b2) < l_free_below:
            return True
    return False


@njit(cache=True, nogil=True, parallel=True)
def cast_rays(
    store, lat, ext, res, origins, directions, max_ranges, min_range, l_stop, l_free_below,
    l_occ_from, offsets, out_voxels, want_voxels,
):
    """Ray queries on the block grid (the dense :func:`explore.mapping.pvs_kernels.cast_rays`, IROS 2012
    Eq. 1-2); voxel ids are flat C-order indices over the bounds."""
    values = store[3]
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
            origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0], directions[r, 1], directions[r, 2],
            0.0, max_ranges[r], lat, inv_res, res, ext[0], ext[1], ext[2],
        )
        if not ok:
            continue
        block = pack((i0 + lat[0]) >> SHIFT, (i1 + lat[1]) >> SHIFT, (i2 + lat[2]) >> SHIFT)
        row, fill = find(store, block)
        t_in = t0
        h_sum = 0.0
        last_l = np.float32(np.nan)
        last_h = 0.0
        k = 0
        n_unk = 0
        n_occ = 0
        n_fr = 0
        while True:
            a0, a1, a2 = i0 + lat[0], i1 + lat[1], i2 + lat[2]
            dd = next_axis(tm0, tm1, tm2)
            t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
            lo = values[row, _local(a0, a1, a2)] if row >= 0 else fill
            idx = (i0 * ext[1] + i1) * ext[2] + i2
            if want_voxels:
                out_voxels[offsets[r] + k] = idx
            k += 1
            if t_exit > min_range:
                last_l, last_h, h_sum, n_occ, n_unk, is_unknown = tally(
                    lo, last_l, last_h, h_sum, n_occ, n_unk, l_occ_from, l_free_below)
                if is_unknown and _free_neighbour(store, a0, a1, a2, lat, ext, l_free_below):
                    n_fr += 1
            if lo >= l_stop:
                hit_t[r] = t_in
                hit_v[r] = idx
                break
            if t_exit >= t1:
                break
            t_in = t_exit
            i0, i1, i2, tm0, tm1, tm2, inside = step(
                dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, ext[0], ext[1], ext[2])
            if not inside:
                break
            key = pack((i0 + lat[0]) >> SHIFT, (i1 + lat[1]) >> SHIFT, (i2 + lat[2]) >> SHIFT)
            if key != block:
                block = key
                row, fill = find(store, block)
        entropy[r] = h_sum
        unknown[r] = n_unk
        occupied[r] = n_occ
        frontier[r] = n_fr
        visits[r] = k
    return hit_t, hit_v, entropy, unknown, occupied, frontier, visits


cast_rays_serial = serial_build(cast_rays)
"""Serial build of :func:`cast_rays` for small batches."""


@njit(cache=True, nogil=True)
def entropy_visited(store, lat, ext, res, origins, directions, max_ranges, min_range, l_stop):
    """Entropy sum (bits) over the beams of one candidate, each voxel counted once (thesis Eq. 4.32,
    Sec. 4.5.3), as :func:`explore.mapping.pvs_kernels.entropy_visited`; the visited voxels are kept
    in a hash set of their flat indices, so unallocated (unknown) space is marked too.
    Returns (entropy sum, distinct voxels counted, voxel visits)."""
    values = store[3]
    inv_res = 1.0 / res
    seen = np.full(1 << 16, EMPTY, np.int64)
    n_seen = 0
    total = 0.0
    visits = 0
    last_l = np.float32(np.nan)
    last_h = 0.0
    for r in range(origins.shape[0]):
        (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
            origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0], directions[r, 1], directions[r, 2],
            0.0, max_ranges[r], lat, inv_res, res, ext[0], ext[1], ext[2],
        )
        if not ok:
            continue
        block = pack((i0 + lat[0]) >> SHIFT, (i1 + lat[1]) >> SHIFT, (i2 + lat[2]) >> SHIFT)
        row, fill = find(store, block)
        while True:
            dd = next_axis(tm0, tm1, tm2)
            t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
            lo = values[row, _local(i0 + lat[0], i1 + lat[1], i2 + lat[2])] if row >= 0 else fill
            visits += 1
            if t_exit > min_range:
                if 2 * (n_seen + 1) > seen.shape[0]:
                    old = seen
                    seen = np.full(2 * old.shape[0], EMPTY, np.int64)
                    for v in old:
                        if v != EMPTY:
                            j = _home(v, seen.shape[0] - 1)
                            while seen[j] != EMPTY:
                                j = (j + 1) & (seen.shape[0] - 1)
                            seen[j] = v
                idx = (i0 * ext[1] + i1) * ext[2] + i2
                mask = seen.shape[0] - 1
                j = _home(idx, mask)
                while seen[j] != EMPTY and seen[j] != idx:
                    j = (j + 1) & mask
                if seen[j] == EMPTY:
                    seen[j] = idx
                    n_seen += 1
                    if lo != last_l:
                        last_l = lo
                        last_h = _entropy(lo)
                    total += last_h
            if lo >= l_stop or t_exit >= t1:
                break
            i0, i1, i2, tm0, tm1, tm2, inside = step(
                dd, i0, i1, i2, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, ext[0], ext[1], ext[2])
            if not inside:
                break
            key = pack((i0 + lat[0]) >> SHIFT, (i1 + lat[1]) >> SHIFT, (i2 + lat[2]) >> SHIFT)
            if key != block:
                block = key
                row, fill = find(store, block)
    return total, n_seen, visits


@njit(cache=True, nogil=True)
def blocks_of(store):
    """Every block: coordinates (m, 3), pool row (-1: uniform) and uniform value (m,)."""
    keys, rows, fill = store[0], store[1], store[2]
    m = store[6][BLOCKS]
    coords = np.zeros((m, 3), np.int64)
    row = np.zeros(m, np.int64)
    value = np.zeros(m, np.float32)
    mask21 = (1 << 21) - 1
    j = 0
    for i in range(keys.shape[0]):
        key = keys[i]
        if key != EMPTY:
            coords[j, 0] = ((key >> 42) & mask21) - KEY_OFFSET
            coords[j, 1] = ((key >> 21) & mask21) - KEY_OFFSET
            coords[j, 2] = (key & mask21) - KEY_OFFSET
            row[j] = rows[i]
            value[j] = fill[i]
            j += 1
    return coords, row, value


@njit(cache=True, nogil=True)
def insert_blocks(store, coords, data):
    """Add blocks with coordinates ``coords`` (m, 3) and log-odds ``data`` (m, 512) (loading a file)."""
    store = reserve(store, coords.shape[0])
    for j in range(coords.shape[0]):
        row, _f = find(store, pack(coords[j, 0], coords[j, 1], coords[j, 2]))
        if row < 0:
            row = _give_row(store, pack(coords[j, 0], coords[j, 1], coords[j, 2]))
        store[3][row] = data[j]
    return store
