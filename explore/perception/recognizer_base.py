"""The shared part of the recognisers: caching model data, recognising every model, verification and
the q_h acceptance (Kriegel Eq. 3.10)."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from explore.core import Pose
from explore.perception.contracts import Recognizer
from explore.perception.hypotheses import Q_H_MIN, Hypothesis, Model, ScanSource, accepted
from explore.perception.model_data import ModelCloud
from explore.perception.segmentation import Cluster
from explore.perception.verification import (
    as_scan_map,
    icp_refine,
    inlier_fraction,
    o3d_cloud,
    render_and_compare,
)
from explore.sim import Scan


class RecognizerBase(Recognizer):
    """Shared plumbing: model caching, verification and refinement."""

    name = "base"
    descriptor_kind = ""

    match_threshold: float = 0.005
    icp: bool = True
    max_hypotheses: int = 5
    normal_radius: float = 0.01
    refine_top: int = 2
    min_prescore: float = 0.2
    min_q_h: float = Q_H_MIN

    def __init__(self) -> None:
        self._cache: dict[tuple[str, int, float], Any] = {}

    def accept(self, hypotheses: Sequence[Hypothesis]) -> list[Hypothesis]:
        """:func:`accepted` with this recogniser's ``min_q_h``."""
        return accepted(hypotheses, self.min_q_h)

    def recognize(self, cluster: Cluster, models: Sequence[Model], scans: ScanSource | None = None) -> list[Hypothesis]:
        """Hypotheses for ``cluster`` over all ``models``, best first."""
        if len(cluster.points) < 5:
            return []
        scan_map = as_scan_map(scans, cluster)
        out: list[Hypothesis] = []
        for model in models:
            out.extend(self.recognize_model(cluster, model, scan_map))
        return sorted(out, key=lambda h: -h.quality)

    __call__ = recognize

    def recognize_model(self, cluster: Cluster, model: Model, scans: Mapping[int, Scan]) -> list[Hypothesis]:
        """Hypotheses for ``cluster`` as ``model``: the per-model step of :meth:`recognize` (PPF, FPFH).
        A recogniser that compares all models at once (VFH) overrides :meth:`recognize` instead."""
        raise TypeError(f"{type(self).__name__}: implement recognize_model, or override recognize")

    def _finish(
        self, cluster: Cluster, model: Model, data: ModelCloud, poses: Sequence[tuple[Pose, dict[str, Any]]],
        scans: Mapping[int, Scan], started: float,
    ) -> list[Hypothesis]:
        """Pre-score candidate poses by their inlier fraction, ICP-refine and verify the best few."""
        points = o3d_cloud(cluster.points).voxel_down_sample(0.003)
        points = np.asarray(points.points)
        scored = [(inlier_fraction(points, data, pose, 0.01), pose, diag) for pose, diag in poses]
        scored.sort(key=lambda item: -item[0])
        out = []
        for pre, pose, diag in scored[: self.refine_top]:
            diag = {**diag, "prescore": pre}
            if pre < self.min_prescore:
                continue
            if self.icp:
                pose, fitness, rmse = icp_refine(points, data, pose)
                diag.update(icp_fitness=fitness, icp_rmse=rmse)
            if scans:
                check = render_and_compare(model.mesh, pose, cluster, scans, self.match_threshold)
                diag.update(check.as_dict())
                quality = check.quality
            else:  # no scans to render into: the ICP inlier fraction stands in
                quality = float(diag.get("icp_fitness", pre))
            diag["seconds"] = time.perf_counter() - started
            out.append(Hypothesis(model.name, pose, quality, self.name, diag))
        out.sort(key=lambda h: -h.quality)
        return out[: self.max_hypotheses]
