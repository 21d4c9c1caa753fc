"""The voting of Drost et al. 2010 (Sec. 3.3) compiled: pairs near each reference point, and the
best (model reference, alpha) of every scene reference point.

Each scene reference point votes in its own accumulator of (model point, alpha bin) cells; the
kernel keeps one accumulator of n_m × n_alpha cells and clears what a reference touched, where a
dense vote array (n_ref × n_m × n_alpha) grows to hundreds of megabytes for a small model
matched in a large cluster.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from explore.core import Points3


def pairs_within(points: Points3, refs: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(ri, pi): every pair of reference ``refs[ri]`` and point ``pi`` (not itself) at most about
    ``radius`` apart, ordered by ri then pi. The search radius is a hair wider than ``radius``: the
    caller keeps the pairs whose own distance passes, so no pair within ``radius`` is lost to the
    tree's rounding."""
    near = cKDTree(points).query_ball_point(points[refs], radius * (1.0 + 1e-9) + 1e-12, return_sorted=True)
    counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(refs))
    ri = np.repeat(np.arange(len(refs)), counts)
    pi = np.concatenate(near).astype(np.int64) if counts.sum() else np.zeros(0, dtype=np.int64)
    own = refs[ri] == pi
    return ri[~own], pi[~own]


@njit(cache=True, nogil=True)
def best_votes(ri: np.ndarray, lo: np.ndarray, hi: np.ndarray, model_alphas: np.ndarray, model_refs: np.ndarray,
               scene_alphas: np.ndarray, n_ref: int, n_model: int, alpha_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Per scene reference point (pairs grouped by ``ri``): the accumulator cell with the most votes
    (model reference * alpha_bins + alpha bin; the lowest such cell on a tie, as ``argmax``) and its
    votes. Pair p matched the table entries ``lo[p]:hi[p]``; alpha = alpha_m - alpha_s (Drost Eq. 3)."""
    acc = np.zeros(n_model * alpha_bins, dtype=np.int64)
    best = np.zeros(n_ref, dtype=np.int64)
    votes = np.zeros(n_ref, dtype=np.int64)
    two_pi = 2.0 * math.pi
    n = len(ri)
    start = 0
    while start < n:
        ref = ri[start]
        end = start
        while end < n and ri[end] == ref:
            end += 1
        top, top_cell = 0, 0
        for p in range(start, end):
            for e in range(lo[p], hi[p]):
                alpha = model_alphas[e] - scene_alphas[p]
                cell = np.int64(model_refs[e]) * alpha_bins + \
                    np.int64(math.floor((alpha + math.pi) / two_pi * alpha_bins)) % alpha_bins
                acc[cell] += 1
                if acc[cell] > top or (acc[cell] == top and cell < top_cell):
                    top, top_cell = acc[cell], cell
        best[ref], votes[ref] = top_cell, top
        for p in range(start, end):
            for e in range(lo[p], hi[p]):
                alpha = model_alphas[e] - scene_alphas[p]
                acc[np.int64(model_refs[e]) * alpha_bins +
                    np.int64(math.floor((alpha + math.pi) / two_pi * alpha_bins)) % alpha_bins] = 0
        start = end
    return best, votes
