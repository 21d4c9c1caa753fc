"""Bayes updates of the PVS log-odds grid by the beams of a scan: the inverse sensor model with range noise
(Kriegel thesis Sec. 3.3.2, Fig. 3.10) and OctoMap's insertPointCloud semantics. Updates run serially: beams of one
scan share the voxels near the sensor, and lost float updates would break the Bayes bookkeeping."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from explore.mapping.traversal import next_axis, ray_start, step_flat, voxel_entry


@njit(cache=True, nogil=True, inline="always")
def beam_segment(d, s, marking, no_return_clears, free_from, max_range, k_sigma, sigma_floor):
    """The part of one beam the inverse sensor model touches (Kriegel thesis Fig. 3.10), for both layouts.

    Returns ``use, hit, band, free_to, t_lo, t_end, inv2s2``: a return at range d with noise
    s = max(sigma, sigma_floor) has the occupied band d +- k s and frees [free_from, d - k s]; a beam
    without a return frees [free_from, max_range] if ``no_return_clears``, and [free_from, -d] if d < 0 (a
    miss the sensor's second viewpoint saw, ``PVS._seen_misses``). ``marking`` (the pass that stamps a
    frame's band voxels) needs only the band. ``use`` is False when the beam touches nothing.
    """
    if d < 0.0:
        return not marking, False, 0.0, -d, max(0.0, free_from), -d, 0.0
    hit = not math.isnan(d)
    if hit:
        if math.isnan(s) or s < sigma_floor:
            s = sigma_floor
        band = k_sigma * s
        t_lo = max(0.0, d - band) if marking else max(0.0, min(free_from, d - band))
        return True, True, band, d - band, t_lo, d + band, 1.0 / (2.0 * s * s)
    use = not marking and no_return_clears
    return use, False, 0.0, max_range, max(0.0, free_from), max_range, 0.0


#: what :func:`voxel_update` asks of one voxel
KEEP, STAMP, OCCUPIED, FREE = 0, 1, 2, 3


@njit(cache=True, nogil=True, inline="always")
def voxel_update(hit, d, t_in, t_exit, band, inv2s2, l_occ, marking, free_from, free_to):
    """What the inverse sensor model does to the voxel a beam crosses over [t_in, t_exit] (Kriegel
    thesis Fig. 3.10), for both layouts: ``(OCCUPIED, l)`` adds l = l_occ exp(-delta^2 / 2 s^2) for a
    voxel within the band d +- k s of the return (delta: its distance from d; ``STAMP`` in the marking
    pass), ``FREE`` for a voxel wholly within [free_from, free_to] (the caller frees it unless this
    frame stamped it as a band voxel), else ``KEEP``."""
    if hit:
        if d < t_in:
            delta = t_in - d
        elif d > t_exit:
            delta = d - t_exit
        else:
            delta = 0.0
        if delta <= band:
            if marking:
                return STAMP, 0.0
            return OCCUPIED, l_occ * math.exp(-delta * delta * inv2s2)
        if marking:
            return KEEP, 0.0
    if t_exit <= free_to and t_in >= free_from:
        return FREE, 0.0
    return KEEP, 0.0


@njit(cache=True, nogil=True)
def _sensor_beam(
    flat, mflat, stamp, marking, n0, n1, n2, lat, res, origins, directions, b, d, s,
    no_return_clears, free_from, max_range, k_sigma, sigma_floor, l_free, l_occ, l_min, l_max,
):
    """One beam of :func:`update_sensor_model`; with ``marking`` only stamp its band voxels."""
    inv_res = 1.0 / res
    use, hit, band, free_to, t_lo, t_end, inv2s2 = beam_segment(
        d, s, marking, no_return_clears, free_from, max_range, k_sigma, sigma_floor)
    if not use:
        return 0
    (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
        origins[b, 0], origins[b, 1], origins[b, 2], directions[b, 0], directions[b, 1],
        directions[b, 2], t_lo, t_end, lat, inv_res, res, n0, n1, n2,
    )
    if not ok:
        return 0
    count = 0
    idx = (i0 * n1 + i1) * n2 + i2
    jump0, jump1 = s0 * n1 * n2, s1 * n2  # the flat index's step along axes 0, 1
    t_in = voxel_entry(tm0, tm1, tm2, td0, td1, td2)
    while True:
        dd = next_axis(tm0, tm1, tm2)
        t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
        kind, add = voxel_update(hit, d, t_in, t_exit, band, inv2s2, l_occ, marking, free_from, free_to)
        if kind == STAMP:
            mflat[idx] = stamp
        elif kind == OCCUPIED:
            flat[idx] = min(max(flat[idx] + np.float32(add), l_min), l_max)
            count += 1
        elif kind == FREE and mflat[idx] != stamp:
            flat[idx] = max(flat[idx] + l_free, l_min)
            count += 1
        if t_exit >= t1:
            break
        t_in = t_exit
        i0, i1, i2, idx, tm0, tm1, tm2, inside = step_flat(
            dd, i0, i1, i2, idx, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, jump0, jump1, n0, n1, n2)
        if not inside:
            break
    return count


@njit(cache=True, nogil=True)
def update_sensor_model(
    grid, mark, stamp, hit_wins, lat, res, origins, directions, ranges, sigmas, starts,
    no_return_clears, free_from, max_range, k_sigma, sigma_floor, l_free, l_occ, l_min, l_max,
):
    """Inverse sensor model with range noise (Kriegel thesis Sec. 3.3.2, Fig. 3.10).

    Per beam with measured range d and noise s = max(sigma, sigma_floor): a voxel whose
    ray segment [t_in, t_exit] comes within k*s of d gets ``w * l_occ`` with
    w = exp(-delta^2 / 2 s^2) (delta = distance from d to the segment, 0 if d lies in
    it); a voxel entirely inside [free_from, d - k s] gets ``l_free``; voxels behind get
    nothing. A no-return beam (NaN range) frees [free_from, max_range] if
    ``no_return_clears``. Log-odds are clamped to [l_min, l_max] after every update
    (Bayes' rule 3.4 in log-odds form). With ``hit_wins``, a voxel inside the band of any
    return of a frame (``starts`` delimit frames) gets no free update from that frame, as
    OctoMap prefers occupied cells per cloud: beams grazing a surface do not erase it.
    Returns (number of voxel updates, next stamp).
    """
    flat = grid.reshape(-1)
    mflat = mark.reshape(-1)
    n0, n1, n2 = grid.shape
    lf = np.float32(l_free)
    lmin = np.float32(l_min)
    lmax = np.float32(l_max)
    count = 0
    for f in range(starts.shape[0] - 1):
        stamp += 1
        tag = np.int32(2 * stamp)  # never equal to a free tag of update_octomap
        if hit_wins:
            for b in range(starts[f], starts[f + 1]):
                _sensor_beam(
                    flat, mflat, tag, True, n0, n1, n2, lat, res, origins, directions, b,
                    ranges[b], sigmas[b], no_return_clears, free_from, max_range, k_sigma, sigma_floor, lf,
                    l_occ, lmin, lmax,
                )
        for b in range(starts[f], starts[f + 1]):
            count += _sensor_beam(
                flat, mflat, tag, False, n0, n1, n2, lat, res, origins, directions, b,
                ranges[b], sigmas[b], no_return_clears, free_from, max_range, k_sigma, sigma_floor, lf,
                l_occ, lmin, lmax,
            )
    return count, stamp


@njit(cache=True, nogil=True)
def update_octomap(
    grid, mark, stamp, lat, res, origins, directions, ranges, starts, no_return_clears,
    max_range, l_hit, l_miss, l_min, l_max,
):
    """OctoMap ``insertPointCloud`` semantics, one cloud per frame segment.

    ``starts`` (m + 1,) delimit the beams of each frame (one sensor origin). Per cloud, as
    ``OccupancyOcTreeBase::computeUpdate``: the endpoint cell of every return is occupied;
    the cells ``computeRayKeys`` visits from the origin up to, excluding, the endpoint cell
    (stopping at the first cell that extends past the endpoint) are free unless also
    occupied in this cloud; a beam without return is a max-range ray (free cells up to
    ``max_range``) if ``no_return_clears``. Each cell is updated once per cloud, clamped.
    ``mark`` holds per-voxel cloud stamps (2*stamp occupied, 2*stamp + 1 free).
    Returns (number of voxel updates, next stamp).
    """
    n0, n1, n2 = grid.shape
    flat = grid.reshape(-1)
    mflat = mark.reshape(-1)
    inv_res = 1.0 / res
    lh = np.float32(l_hit)
    lm = np.float32(l_miss)
    lmin = np.float32(l_min)
    lmax = np.float32(l_max)
    count = 0
    occ = np.empty(origins.shape[0], np.int64)
    for f in range(starts.shape[0] - 1):
        stamp += 1
        occ_tag = np.int32(2 * stamp)
        free_tag = np.int32(2 * stamp + 1)
        n_occ = 0
        for b in range(starts[f], starts[f + 1]):
            d = ranges[b]
            if math.isnan(d):
                continue
            e0 = int(math.floor((origins[b, 0] + directions[b, 0] * d) * inv_res)) - lat[0]
            e1 = int(math.floor((origins[b, 1] + directions[b, 1] * d) * inv_res)) - lat[1]
            e2 = int(math.floor((origins[b, 2] + directions[b, 2] * d) * inv_res)) - lat[2]
            if 0 <= e0 < n0 and 0 <= e1 < n1 and 0 <= e2 < n2:
                e = (e0 * n1 + e1) * n2 + e2
                if mflat[e] != occ_tag:
                    mflat[e] = occ_tag
                    occ[n_occ] = e
                    n_occ += 1
        for b in range(starts[f], starts[f + 1]):
            d = ranges[b]
            if math.isnan(d):
                if not no_return_clears:
                    continue
                d = max_range
            px = origins[b, 0] + directions[b, 0] * d
            py = origins[b, 1] + directions[b, 1] * d
            pz = origins[b, 2] + directions[b, 2] * d
            e0 = int(math.floor(px * inv_res)) - lat[0]
            e1 = int(math.floor(py * inv_res)) - lat[1]
            e2 = int(math.floor(pz * inv_res)) - lat[2]
            end = -1
            if 0 <= e0 < n0 and 0 <= e1 < n1 and 0 <= e2 < n2:
                end = (e0 * n1 + e1) * n2 + e2
            (ok, t0, t1, i0, i1, i2, s0, s1, s2, tm0, tm1, tm2, td0, td1, td2) = ray_start(
                origins[b, 0], origins[b, 1], origins[b, 2],
                directions[b, 0], directions[b, 1], directions[b, 2],
                0.0, d, lat, inv_res, res, n0, n1, n2,
            )
            if not ok:
                continue
            idx = (i0 * n1 + i1) * n2 + i2
            jump0, jump1 = s0 * n1 * n2, s1 * n2  # the flat index's step along axes 0, 1
            while True:
                if idx == end:
                    break
                dd = next_axis(tm0, tm1, tm2)
                t_exit = tm0 if dd == 0 else (tm1 if dd == 1 else tm2)
                if t_exit > d:
                    break
                m = mflat[idx]
                if m != occ_tag and m != free_tag:
                    mflat[idx] = free_tag
                    v = flat[idx] + lm
                    flat[idx] = max(v, lmin)
                    count += 1
                i0, i1, i2, idx, tm0, tm1, tm2, inside = step_flat(
                    dd, i0, i1, i2, idx, tm0, tm1, tm2, s0, s1, s2, td0, td1, td2, jump0, jump1, n0, n1, n2)
                if not inside:
                    break
        for j in range(n_occ):
            e = occ[j]
            v = flat[e] + lh
            flat[e] = min(v, lmax)
            count += 1
    return count, stamp
