"""The positioning-noise model of Vasquez-Gomez et al. (Sec. A6): velocity controls perturbed by zero-mean
normal errors truncated at beta = 3 sigma, and the log of their transition density (Eq. 2, 3)."""

from __future__ import annotations

import math

import numpy as np

from explore.core import Array

# -- noise model (Vasquez-Gomez Sec. A6) -----------------------------------------------------
#: a velocity command below this (m/s or rad/s) is round-off, not a command: that part stands
#: still and does not err
STILL = 1e-9


def truncated_normal(rng: np.random.Generator, sigma: Array, size: int, beta: float = 3.0) -> np.ndarray:
    """(size, len(sigma)) zero-mean normal samples truncated to |e| <= beta * sigma (rejection)."""
    sigma = np.asarray(sigma, dtype=float)
    out = rng.normal(size=(size, len(sigma))) * sigma
    bad = np.abs(out) > beta * sigma
    while bad.any():
        out[bad] = rng.normal(size=int(bad.sum())) * np.broadcast_to(sigma, out.shape)[bad]
        bad = np.abs(out) > beta * sigma
    return out


def truncated_normal_logpdf(eps: np.ndarray, sigma: Array, beta: float = 3.0,
                            active: np.ndarray | None = None, per_row: bool = False) -> float | np.ndarray:
    """Sum of log densities of the truncated normal errors (log of Eq. 2 / Eq. 3 products).

    Dimensions with sigma = 0 (noise-free) contribute nothing, nor do the entries that
    ``active`` (same shape as ``eps``) marks as not sampled (a control that commands no motion).
    ``per_row``: one sum per row of ``eps`` (e.g. per rollout) instead of one in all.
    """
    sigma = np.asarray(sigma, dtype=float)
    use = sigma > 0
    if not use.any() or len(eps) == 0:
        return np.zeros(len(eps)) if per_row else 0.0
    e, s = np.asarray(eps)[:, use], sigma[use]
    mass = math.erf(beta / math.sqrt(2.0))  # P(-beta sigma <= e <= beta sigma) = 0.997 for beta 3
    logpdf = -0.5 * (e / s) ** 2 - np.log(s * math.sqrt(2.0 * math.pi)) - math.log(mass)
    if active is not None:
        logpdf = np.where(np.asarray(active, dtype=bool)[:, use], logpdf, 0.0)
    return logpdf.sum(axis=1) if per_row else float(logpdf.sum())
