"""Example plugin package for explore: a utility and a strategy that uses it.

Registered through the ``explore.plugins`` entry point declared in ``pyproject.toml``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from explore_plugins.strategies import make_strategy
from explore_plugins.utilities import RAY_PARAMS, RayUtility

from explore.core import Param
from explore.mapping import ENTROPY
from explore.runtime import hookimpl


class TravelIG(RayUtility):
    """Information gain discounted by travel: IG * exp(-distance / scale)."""

    name = "travel_ig"
    params = RAY_PARAMS + (
        Param("scale", float, 0.5, "m", "travel distance that divides the gain by e", low=1e-3),
    )

    def combine(self, acc: np.ndarray, candidates: list, ctx: Any) -> np.ndarray:
        here = ctx.sensor_pose[:3, 3] if ctx.sensor_pose is not None else ctx.region_centre
        travel = np.array([np.linalg.norm(c.start[:3, 3] - here) for c in candidates])
        return acc[:, ENTROPY] * np.exp(-travel / self.scale)


TravelStrategy = make_strategy(
    "example/travel_ig",
    "Example: boundary search + hole rescan with travel-discounted IG (from explore-example-strategy).",
    "boundary_hole",
    "travel_ig",
    "coverage_target",
    {},
    {"scale": 0.5},
    {"coverage": 0.8, "density": 0.2, "n_abort": 30},
)


@hookimpl
def explore_register_plugins(register: Callable[..., Any]) -> None:
    register(TravelIG)
    register(TravelStrategy)
