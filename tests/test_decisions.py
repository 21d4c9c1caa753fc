"""Decisions with margins: near-ties broken by order, thresholds that a last-digit difference cannot flip."""

from __future__ import annotations

import math

import numpy as np

from explore.core import TIE, pick_best, reaches


def test_pick_best_breaks_near_ties_by_order_and_reports_the_lead() -> None:
    best = pick_best([0.2, 0.7, 0.7 * (1 + 0.1 * TIE), 0.5])
    assert best is not None and best.index == 1  # within TIE of the first 0.7: the earlier one wins
    assert math.isclose(best.margin, 0.2)
    clear = pick_best([0.2, 0.7, 0.7 + 1e-6])
    assert clear is not None and clear.index == 2 and math.isclose(clear.margin, 1e-6, rel_tol=1e-3)
    alone = pick_best([np.nan, 3.0, -np.inf])
    assert alone is not None and alone.index == 1 and alone.margin == math.inf
    assert pick_best([np.nan, np.inf]) is None and pick_best([]) is None


def test_the_order_of_a_last_digit_difference_does_not_change_the_pick() -> None:
    """Two runs whose sums differ in the last bit choose the same candidate."""
    a = np.array([0.356766, 0.356766 + 1e-16, 0.1])
    b = np.array([0.356766 + 1e-16, 0.356766, 0.1])
    assert pick_best(a).index == pick_best(b).index == 0


def test_reaches_counts_a_last_digit_below_the_threshold_as_reaching_it() -> None:
    assert reaches(0.66, 0.66) and reaches(0.66 - 1e-15, 0.66) and not reaches(0.66 - 1e-6, 0.66)
    assert reaches(31.0, 30.0) and not reaches(29.0, 30.0) and not reaches(math.nan, 0.5)
