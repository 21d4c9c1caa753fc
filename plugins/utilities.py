"""Built-in utilities: how good a candidate view or scan path is.

A utility's ``score(candidates, ctx)`` returns one value per candidate (higher is better)
and fills ``candidate.diagnostics``. The ray-based utilities simulate the candidate's beams
(``sensor.beams`` with a beam stride and a frame spacing) through a snapshot of the PVS with
one shared numba pass (:mod:`explore.mapping.visibility`), then combine the accumulated numbers.
"""

from __future__ import annotations

import numpy as np

from explore.api import RAY_PARAMS, AreaFactor, RayUtility, Utility, beams_of, non_free_count
from explore.core import Param
from explore.mapping import (
    ENTROPY,
    HITS,
    OCCLUSION,
    PROXIMITY,
    QUAL_LIT,
    QUAL_NEED,
    REAR_ENTROPY,
    REAR_VOXEL,
    TRAVERSED,
    UNKNOWN_VOXELS,
    UNOBSERVED,
)
from explore.nbv import Candidate, PlanningContext


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
