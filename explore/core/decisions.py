"""Decisions that do not hang on the last digit: argmax and thresholds with a stable tie rule, and margins.

A floating-point difference in the last digit (an ICP sum in another order, a different BLAS)
must not flip a choice. Scores within :data:`TIE` (relative) of the best are a tie, broken by
order (the first candidate wins); a value within :data:`TIE` of a threshold reaches it. Each
decision also reports its *margin* (how far the winner was ahead of the runner-up, or the value
from the threshold), which the runs write to their trace, so one can see how close a call was.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

TIE = 1e-9  # relative difference below which two scores (or a value and a threshold) are equal


def _scale(*values: float) -> float:
    return max(1.0, *(abs(v) for v in values if math.isfinite(v)))


@dataclass(frozen=True)
class Pick:
    """The winner of :func:`pick_best`: its index, score and lead over the runner-up (inf when alone)."""

    index: int
    score: float
    margin: float


def pick_best(scores: Sequence[float] | np.ndarray) -> Pick | None:
    """The highest finite score; near-ties (within :data:`TIE`) go to the first in order. None if none."""
    values = np.asarray(scores, dtype=float).reshape(-1)
    finite = np.isfinite(values)
    if not finite.any():
        return None
    best = float(values[finite].max())
    tied = finite & (values >= best - TIE * _scale(best))
    index = int(np.flatnonzero(tied)[0])
    others = values[finite & ~tied]
    margin = best - float(others.max()) if len(others) else math.inf
    return Pick(index, float(values[index]), margin)


def reaches(value: float, threshold: float) -> bool:
    """``value >= threshold``, where a value within :data:`TIE` below the threshold counts as reaching it."""
    return bool(value >= threshold - TIE * _scale(threshold, value))
