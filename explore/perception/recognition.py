"""Object recognition on segmented clusters: PPF voting, FPFH + RANSAC, VFH "mean distance".

Every recogniser takes a :class:`~explore.perception.segmentation.Cluster`, the database models
(:class:`Model`: name + mesh in its object frame + stored descriptors) and the scans the
cluster came from, and returns :class:`Hypothesis` objects (model name, world_T_model,
quality) sorted by quality, best first.

- :class:`PPFRecognizer` -- Drost et al. 2010 point-pair features (Kriegel thesis Eq. 3.9),
  voting over (model reference point, alpha), pose clustering, ICP refinement, and Kriegel's
  render-and-compare verification q_h = (N_m/N_r)(N_m/N_c)^2 (Eq. 3.10) as quality.
- :class:`FPFHRansacRecognizer` -- Open3D FPFH features + RANSAC + ICP, same verification.
- :class:`VFHRecognizer` -- Görner Ch. 5: VFH signatures (308 bins) of rendered training
  views, priming with a k = 1 nearest-neighbour search, "mean distance" over the closest
  66 % of the cluster's views, threshold gamma.

A hypothesis is *accepted* only if its verification q_h reaches ``min_q_h`` (Kriegel: "the
best hypothesis is accepted if q_h > threshold"; the value is unpublished, we use 0.5: on the
tabletop overview right matches score 0.84-0.98 and the best wrong ones 0.02-0.25, see
``benchmarks/scene.py``). :func:`rivals` names the hypotheses that make a recognition
ambiguous (a second model or a second pose that explains the data almost as well), which the
scene exploration resolves with more views.

Model preprocessing (rendered training views, PPF hash tables, signatures) is cached per
recogniser instance; :meth:`describe` gives the arrays to store in the object database
(``descriptors`` kind ``ppf`` / ``vfh``), which are reused when present.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from explore.perception.hypotheses import Model
from explore.perception.ppf import PPFRecognizer
from explore.perception.vfh import VFHRecognizer


def model_descriptors(model: Model, recognizers: Sequence[Any] | None = None) -> dict[str, tuple[np.ndarray, dict]]:
    """Descriptors to store with a database object: kind -> (array, parameters).

    By default the PPF model clouds and the VFH training signatures with the default
    parameters (what ``explore db add`` and the database-update behaviour store); recognisers
    without a ``describe`` method (FPFH recomputes its features) are skipped. A recogniser
    reuses a stored descriptor only if its parameters match (:meth:`PPFRecognizer.table`).
    """
    chosen = list(recognizers) if recognizers is not None else [PPFRecognizer(), VFHRecognizer()]
    return {r.descriptor_kind: r.describe(model) for r in chosen if hasattr(r, "describe")}
