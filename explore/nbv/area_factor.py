"""Vasquez-Gomez et al.'s deterministic utility (Eq. 4-8), the one the NBVS sessions build on.

A library part: :class:`~explore.nbv.nbvs.NBVSSession` scores visibility with it whatever utility
a run names, and registers it as the ``area_factor`` utility plugin."""

from __future__ import annotations

import numpy as np

from explore.core import Param
from explore.mapping import (
    OCC_FIRST,
    UNK_FIRST,
)
from explore.nbv.candidates import Candidate, PlanningContext, collision_free_share
from explore.nbv.utility import RAY_PARAMS, RayUtility


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
