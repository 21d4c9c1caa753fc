"""The evaluation of a modelling session against the ground truth (the only place it is read; planners never see
it): the coverage c_a after every scan (thesis Sec. 4.7), the motion numbers and the metrics of docs/metrics.md."""

from __future__ import annotations

from typing import Any

from explore.mapping import GroundTruthMetrics, coverage_auc
from explore.nbv.modelling_records import FALLBACK_PREFIX


class Evaluation:
    """Part of :class:`ModellingSession`: ground-truth metrics."""

    def motion_metrics(self) -> dict[str, Any]:
        """Planning success and time, executed trajectories, collisions (see docs/metrics.md)."""
        return self.motion.metrics()

    # -- evaluation (the only place that reads the ground truth) -------------------------
    def ground_truth(self) -> GroundTruthMetrics:
        """The ground-truth evaluator of this world (observable surface computed once)."""
        if self._metrics is None:
            self._metrics = GroundTruthMetrics(self.sim)
        return self._metrics

    def coverage_curve(self) -> list[float]:
        """Ground-truth c_a after every scan (from the point sets kept after each integration)."""
        gt = self.ground_truth()
        return [gt.coverage(points) for points in self.point_history]

    def metrics(self, ground_truth: bool = True) -> dict[str, Any]:
        """Scans, c_a and ĉ_m per scan, RMS error, Chamfer distance, coverage AUC, path lengths,
        selection times, status.

        ``rms_error_m`` / ``chamfer_m`` are of the final reconstruction (``*_at_stop_m`` at the
        scan n_s the termination first said stop); ``coverage_auc`` is the mean c_a over
        ``max_scans`` scans (a run that ended early keeps its last value). Scans that came
        from the session's fallback generator are counted in ``fallback_scans``.
        """
        curve = self.coverage_curve() if ground_truth and self.point_history else []
        for record, value in zip(self.records, curve, strict=False):
            record.coverage = value
        n_s = self.first_stop if self.first_stop is not None else self.n_scans
        quality: dict[str, float] = {}
        if curve:
            gt = self.ground_truth()
            final = gt.evaluate(self.point_history[-1])
            at_stop = gt.evaluate(self.point_history[max(n_s, 1) - 1])
            quality = {
                "rms_error_m": final["rms_error"], "chamfer_m": final["chamfer"],
                "rms_error_at_stop_m": at_stop["rms_error"], "chamfer_at_stop_m": at_stop["chamfer"],
                "coverage_auc": coverage_auc(curve, self.max_scans),
            }
        fallback = sum(r.source.startswith(FALLBACK_PREFIX) for r in self.records)
        return {
            "strategy": self.strategy.name,
            "world": self.sim.spec.name,
            "seed": self.seed,
            "scans": self.n_scans,
            "n_s": n_s,
            "stop_reason": self.first_stop_reason or self.reason,
            "status": self.status,
            "reason": self.reason,
            "coverage": curve,
            "coverage_at_stop": curve[n_s - 1] if curve and n_s >= 1 else float("nan"),
            **quality,
            "coverage_estimate": [r.coverage_estimate for r in self.records],
            "coverage_border": [r.coverage_border for r in self.records],
            "coverage_off_support": [r.coverage_off_support for r in self.records],
            "density": [r.density for r in self.records],
            "scan_path_m": float(sum(r.scan_length_m for r in self.records)),
            "travel_m": float(sum(r.travel_m for r in self.records)),
            "scan_path_at_stop_m": float(sum(r.scan_length_m for r in self.records[:n_s])),
            "selection_s": list(self.selection_times),
            "selection_candidates": list(self.selection_sizes),
            "sources": [r.source for r in self.records],
            "fallback_scans": int(fallback),
        }
