"""The utility contract: how good a candidate view or scan path is, and the ray-based utilities' common part.

A utility's ``score(candidates, ctx)`` returns one value per candidate (higher is better)
and fills ``candidate.diagnostics``. A :class:`RayUtility` simulates each candidate's beams
(``sensor.beams`` with a beam stride and a frame spacing) through a snapshot of the PVS with one
shared numba pass (:mod:`explore.mapping.visibility`) and combines the per-candidate accumulators
(``ACC_NAMES``) in :meth:`RayUtility.combine`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from explore.core import Param, Points3
from explore.core.plugin import Plugin
from explore.mapping import (
    ACC_NAMES,
    TraceSettings,
    trace,
)
from explore.nbv.candidates import Candidate, PlanningContext
from explore.sim import ScanPath

RAY_PARAMS = (
    Param("beam_stride", int, 4, "", "use every n-th beam of a stripe / pixel (thesis: every 4th)", low=1),
    Param("frame_spacing", float, 0.006, "m", "distance between simulated stripes along a path", low=1e-4),
    Param("visited", bool, True, "", "count each voxel once per candidate (thesis visited marking)"),
    Param("hierarchy", int, 0, "",
          "hierarchical ray tracing level a (0 = uniform; Vasquez-Gomez HRT: 2^a x 2^a bundles, coarse pass first)",
          low=0, high=4),
)


class Utility(Plugin, ABC):
    """Contract of kind ``utility``: how good each candidate is (higher is better).

    :meth:`score` gets the candidates of one selection (:class:`~explore.nbv.candidates.Candidate`:
    ``target`` a 4x4 world_T_sensor pose or a :class:`~explore.sim.scan.ScanPath`, metres) and the
    :class:`~explore.nbv.candidates.PlanningContext` (PVS, surface model, sensor, robot; never the
    ground truth). It returns an (n,) float array, one value per candidate in their order, and
    may add numbers to ``candidate.diagnostics`` (they reach the trace and ``metrics.json``).
    Values of one call are compared with each other only; their scale is free.
    """

    kind = "utility"

    @abstractmethod
    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        """(n,) utility of each candidate, in the candidates' order."""


def candidate_beams(sensor: Any, cand: Candidate, beam_stride: int, frame_spacing: float) -> tuple[Points3, Points3]:
    """Origins and directions of one candidate's simulated beams, cached on the candidate.

    Candidates are immutable once generated and persistent ones (the sphere) are scored in
    every iteration, so the beams are computed once per (stride, spacing).
    """
    key = (beam_stride, frame_spacing)
    cached = cand.beams_cache
    if cached is not None and cached[0] == key:
        return cached[1], cached[2]
    stride = 1
    if isinstance(cand.target, ScanPath):
        per_frame = cand.target.speed / max(sensor.rate_hz, 1e-9)
        stride = max(1, int(round(frame_spacing / max(per_frame, 1e-9))))
    o, d, _ = sensor.beams(cand.target, beam_stride=beam_stride, frame_stride=stride)
    cand.beams_cache = (key, o, d)
    return o, d


def beams_of(ctx: PlanningContext, candidates: list[Candidate], beam_stride: int,
             frame_spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins, directions and candidate index of the simulated beams of every candidate."""
    origins, dirs, groups = [], [], []
    for index, cand in enumerate(candidates):
        o, d = candidate_beams(ctx.sensor, cand, beam_stride, frame_spacing)
        origins.append(o)
        dirs.append(d)
        groups.append(np.full(len(o), index, dtype=np.int64))
    if not origins:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.vstack(origins), np.vstack(dirs), np.concatenate(groups)


class RayUtility(Utility):
    """A utility computed from the candidates' simulated beams; a subclass only writes :meth:`combine`."""

    params = RAY_PARAMS

    def settings(self) -> TraceSettings:
        return TraceSettings(visited=bool(getattr(self, "visited", True)), hierarchy=int(getattr(self, "hierarchy", 0)),
                             lam=float(getattr(self, "lam", 0.7)),
                             incidence_deg=float(getattr(self, "incidence_deg", 70.0)))

    def accumulate(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        """Accumulators (n, N_ACC) of the candidates' simulated beams."""
        origins, dirs, groups = beams_of(ctx, candidates, self.beam_stride, self.frame_spacing)
        sensor = ctx.sensor
        min_range = 0.0 if getattr(sensor, "clear_from_origin", True) else sensor.min_range
        per_frame = len(sensor.local_directions()[:: self.beam_stride])
        acc = trace(ctx.grid, origins, dirs, groups, len(candidates), min_range, sensor.max_range,
                    self.settings(), per_frame, occluders=ctx.environment_boxes)
        for cand, row in zip(candidates, acc, strict=True):
            cand.diagnostics.update({name: float(v) for name, v in zip(ACC_NAMES, row, strict=True)})
        return acc

    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        if not candidates:
            return np.zeros(0)
        acc = self.accumulate(candidates, ctx)
        values = self.combine(acc, candidates, ctx)
        for cand, value in zip(candidates, values, strict=True):
            cand.diagnostics["utility"] = float(value)
        return values

    @abstractmethod
    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        """(n,) utility from the accumulators ``acc`` (n, len(ACC_NAMES)); columns by the ``ACC`` indices."""


def non_free_count(ctx: PlanningContext) -> int:
    """N_v (thesis Eq. 4.32): voxels that are not free."""
    pvs = ctx.pvs
    if hasattr(pvs, "non_free_count"):
        return max(1, int(pvs.non_free_count()))
    return max(1, int(np.count_nonzero(ctx.grid.prob >= 0.05)))
