"""Built-in utilities: how good a candidate view or scan path is.

A utility's ``score(candidates, ctx)`` returns one value per candidate (higher is better)
and fills ``candidate.diagnostics``. The ray-based utilities simulate the candidate's beams
(``sensor.beams`` with a beam stride and a frame spacing) through a snapshot of the PVS with
one shared numba pass (:mod:`explore.mapping.visibility`), then combine the accumulated numbers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import Param, Points3
from explore.mapping import (
    ACC_NAMES,
    ENTROPY,
    HITS,
    OCC_FIRST,
    OCCLUSION,
    PROXIMITY,
    QUAL_LIT,
    QUAL_NEED,
    REAR_ENTROPY,
    REAR_VOXEL,
    TRAVERSED,
    UNK_FIRST,
    UNKNOWN_VOXELS,
    UNOBSERVED,
    TraceSettings,
    trace,
)
from explore.nbv import Candidate, PlanningContext, collision_free_share
from explore.sim import ScanPath

RAY_PARAMS = (
    Param("beam_stride", int, 4, "", "use every n-th beam of a stripe / pixel (thesis: every 4th)", low=1),
    Param("frame_spacing", float, 0.006, "m", "distance between simulated stripes along a path", low=1e-4),
    Param("visited", bool, True, "", "count each voxel once per candidate (thesis visited marking)"),
    Param("hierarchy", int, 0, "",
          "hierarchical ray tracing level a (0 = uniform; Vasquez-Gomez HRT: 2^a x 2^a bundles, coarse pass first)",
          low=0, high=4),
)


class Utility:
    """Base class: ``score(candidates, ctx) -> (n,) array``; higher is better."""

    kind = "utility"
    name = "utility"
    params: tuple = ()

    def __init__(self, **values: Any) -> None:
        for key, value in values.items():
            setattr(self, key, value)

    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        raise NotImplementedError


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
    """A utility computed from simulated beams (see :mod:`explore.mapping.visibility`)."""

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
                    self.settings(), per_frame)
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

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        raise NotImplementedError


def non_free_count(ctx: PlanningContext) -> int:
    """N_v (thesis Eq. 4.32): voxels that are not free."""
    pvs = ctx.pvs
    if hasattr(pvs, "non_free_count"):
        return max(1, int(pvs.non_free_count()))
    return max(1, int(np.count_nonzero(ctx.grid.prob >= 0.05)))


class RandomUtility(Utility):
    """Random selection (thesis Table 4.5 'Random')."""

    name = "random"

    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return ctx.rng.random(len(candidates))


class FovOrder(Utility):
    """Oldest candidate first, in detection order (IROS Table II 'B': boundaries by FOV position)."""

    name = "fov_order"

    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return np.array([-c.created * 1000.0 - c.info.get("id", 0) for c in candidates], dtype=float)


class UnknownCount(RayUtility):
    """Unknown voxels seen by the simulated beams (Wong et al. 1999; IROS Table II 'S')."""

    name = "unknown_count"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, UNKNOWN_VOXELS]


class InformationGain(RayUtility):
    """Entropy along the simulated beams until p >= 0.95 (Kriegel IROS 2012 Eq. 1-2)."""

    name = "information_gain"
    params = tuple(p if p.name != "visited" else Param("visited", bool, False, "",
                   "count each voxel once per candidate (IROS Eq. 2 is a plain double sum)") for p in RAY_PARAMS)

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, ENTROPY]


class IGQuality(RayUtility):
    """IG/quality f = (1 - w) e_v + w (1 - q_s), w = n/(n + 5) (thesis Eq. 4.30-4.34).

    ``variant``: ``need`` (default) scores λ b_i + (1 − λ)(1 − d̄_i), i.e. rewards seeing voxels
    with border edges and low density, as the thesis text intends; ``kriegel_literal`` is
    Eq. 4.33/4.30 as printed, ω (1 − Σ(λ b_i + (1 − λ) d̄_i)/N_v), which penalises views of
    border voxels. ``normalise``: ``max`` (default) divides each term by its maximum over
    the candidates; ``n_v`` divides both by N_v as Eq. 4.32/4.34. On the bunny the entropy
    sum spreads 300-600 times more across candidates than the quality sum, so with ``n_v``
    ω cannot balance the two and IG/Quality acts as IG. Measurements of both options:
    docs/results.md (Kriegel thesis Table 4.5).
    """

    name = "ig_quality"
    params = RAY_PARAMS + (
        Param("omega", float, -1.0, "", "weight w of the quality term; < 0: w = n_s/(n_s + n_q) (Eq. 4.31)",
              low=-1.0, high=1.0),
        Param("n_q", float, 5.0, "", "n_q of Eq. 4.31", low=1e-6),
        Param("lam", float, 0.7, "", "lambda of Eq. 4.33 (border vs density)", low=0.0, high=1.0),
        Param("incidence_deg", float, 70.0, "deg", "no quality beyond this incidence angle (Eq. 4.33)",
              low=0.0, high=90.0),
        Param("variant", str, "need", "",
              "need: w sum(lambda b + (1-lambda)(1-d))/N_v; "
              "kriegel_literal: w (1 - sum(lambda b + (1-lambda) d)/N_v)",
              choices=("need", "kriegel_literal")),
        Param("normalise", str, "max", "",
              "n_v: both terms / N_v as Eq. 4.32-4.34 (the entropy sum then dominates); "
              "max: each term / its maximum over the candidates, so w really balances them",
              choices=("n_v", "max")),
    )

    def weight(self, ctx: PlanningContext) -> float:
        if self.omega >= 0.0:
            return float(self.omega)
        n = float(ctx.iteration)
        return n / (n + self.n_q)

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        n_v = float(non_free_count(ctx))
        e_v = acc[:, ENTROPY] / n_v  # Eq. 4.32
        w = self.weight(ctx)
        if self.variant == "kriegel_literal":
            modelling = 1.0 - acc[:, QUAL_LIT] / n_v  # Eq. 4.34 and the (1 - q_s) of Eq. 4.30 as printed
        else:
            modelling = acc[:, QUAL_NEED] / n_v
        if self.normalise == "max":
            e_v = e_v / max(float(e_v.max()), 1e-12)
            if self.variant == "kriegel_literal":
                need = acc[:, QUAL_LIT] / n_v
                modelling = 1.0 - need / max(float(need.max()), 1e-12)
            else:
                modelling = modelling / max(float(modelling.max()), 1e-12)
        for cand, e, m in zip(candidates, e_v, modelling, strict=True):
            cand.diagnostics.update({"e_v": float(e), "modelling_term": float(m), "omega": w})
        return (1.0 - w) * e_v + w * modelling


class AreaFactor(RayUtility):
    """Vasquez-Gomez deterministic utility pos * reg * sur * dist (Eq. 4-8) with overlap h."""

    name = "area_factor"
    params = RAY_PARAMS + (
        Param("overlap", float, 0.5, "", "registration factor: oc_o / (oc_o + un_o) > h (sim 50 %, real 65 %)",
              low=0.0, high=1.0),
        Param("clearance", float, 0.02, "m", "positioning factor: sensor clearance from non-free voxels", low=0.0),
        Param("rotation_weight", float, 0.05, "m/rad", "distance factor: metres per radian of rotation", low=0.0),
        Param("tie_break", float, 1e-6, "", "added w * sur so that all-zero products still rank by sur", low=0.0),
    )

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        occ, unk = acc[:, OCC_FIRST], acc[:, UNK_FIRST]
        un_total = max(1.0, float(np.count_nonzero((ctx.grid.prob >= 0.25) & (ctx.grid.prob < 0.75))))
        reg = (occ / np.maximum(occ + unk, 1.0) > self.overlap).astype(float)
        sur = unk / un_total
        pos = np.array([float(collision_free_share(ctx.grid, c.target, self.clearance,
                                                   environment_boxes=ctx.environment_boxes) == 1.0)
                        for c in candidates])
        here = ctx.sensor_pose if ctx.sensor_pose is not None else np.eye(4)
        dist = []
        for cand in candidates:
            start = cand.start
            rho = float(np.linalg.norm(start[:3, 3] - here[:3, 3]))
            cosang = np.clip((np.trace(here[:3, :3].T @ start[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
            rho += self.rotation_weight * float(np.arccos(cosang))
            dist.append(1.0 / (1.0 + rho))
        dist = np.asarray(dist)
        for cand, r, s, p in zip(candidates, reg, sur, pos, strict=True):
            cand.diagnostics.update({"reg": float(r), "sur": float(s), "pos": float(p)})
        return pos * reg * sur * dist + self.tie_break * pos * sur


class OcclusionAware(RayUtility):
    """Sum of P_v(x) H(x) over the beams' voxels (Isler et al. 2016, Delmerico et al. 2018)."""

    name = "occlusion_aware"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, OCCLUSION]


class UnobservedVoxel(RayUtility):
    """Sum of P_v(x) over unknown voxels (Isler et al. 2016 'unobserved voxel')."""

    name = "unobserved_voxel"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, UNOBSERVED]


class RearSideVoxel(RayUtility):
    """Unknown voxels directly behind an occupied one hit by a beam (Isler et al. 2016 'rear side voxel')."""

    name = "rear_side_voxel"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, REAR_VOXEL]


class RearSideEntropy(RayUtility):
    """P_v-weighted entropy of the unknown voxels behind hit surfaces (Isler et al. 2016 'rear side entropy')."""

    name = "rear_side_entropy"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, REAR_ENTROPY]


class ProximityCount(RayUtility):
    """Unknown voxels weighted by P_v and closeness to occupied voxels (Isler et al. 2016 'proximity count')."""

    name = "proximity_count"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, PROXIMITY]


class AverageEntropy(RayUtility):
    """Entropy sum divided by the voxels traversed (Delmerico et al. 2018 'average entropy')."""

    name = "average_entropy"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        return acc[:, ENTROPY] / np.maximum(acc[:, TRAVERSED], 1.0)


class HitShare(RayUtility):
    """Share of beams that end on an occupied voxel (overlap with the known surface; a diagnostic)."""

    name = "hit_share"

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        origins, _, groups = beams_of(ctx, candidates, self.beam_stride, self.frame_spacing)
        n = np.bincount(groups, minlength=len(candidates)).astype(float)
        return acc[:, HITS] / np.maximum(n, 1.0)


PLUGINS = [
    RandomUtility, FovOrder, UnknownCount, InformationGain, IGQuality, AreaFactor, OcclusionAware,
    UnobservedVoxel, RearSideVoxel, RearSideEntropy, ProximityCount, AverageEntropy, HitShare,
]
