"""Named NBV strategies: a view generator + a utility + a termination, each with parameters.

Includes the 12 combinations of Kriegel's thesis Table 4.5 ({random, ig, quality,
ig_quality} x {sphere, bs, bs_hr}) and the 5 methods of the IROS 2012 Table II (B, S, S/IG,
B/IG, BH/IG). ``custom`` takes the three plugin names as parameters. Every strategy accepts
``generator_params``, ``utility_params`` and ``termination_params`` that override its
defaults.
"""

from __future__ import annotations

from explore.api import OVERRIDES, Param, Strategy, StrategyPlugin, make_strategy


class Custom(StrategyPlugin):
    """Any generator + utility + termination given by name."""

    name = "custom"
    params = (
        Param("generator", str, "boundary_hole", "", "view generator plugin"),
        Param("utility", str, "ig_quality", "", "utility plugin"),
        Param("termination", str, "coverage_target", "", "termination plugin"),
    ) + OVERRIDES

    def __init__(self, generator: str, utility: str, termination: str, generator_params: dict,
                 utility_params: dict, termination_params: dict) -> None:
        self.strategy = Strategy("custom", generator, utility, termination, generator_params, utility_params,
                                 termination_params)


THESIS_SELECTIONS = {
    "random": ("random", {}),
    "ig": ("ig_quality", {"omega": 0.0}),
    "quality": ("ig_quality", {"omega": 1.0}),
    "ig_quality": ("ig_quality", {"omega": -1.0}),
}
THESIS_SEARCHES = {"sphere": "sphere", "bs": "boundary", "bs_hr": "boundary_hole"}
THESIS_TERMINATION = ("coverage_target", {"coverage": 0.8, "density": 0.2, "n_abort": 30})

TABLE_4_5 = [f"{sel}/{search}" for sel in THESIS_SELECTIONS for search in THESIS_SEARCHES]


def _thesis() -> list[type]:
    out = []
    for sel, (utility, uparams) in THESIS_SELECTIONS.items():
        for search, generator in THESIS_SEARCHES.items():
            name = f"{sel}/{search}"
            doc = f"Kriegel thesis Table 4.5: {sel} selection over {search} candidates, stop at ĉ_m 80 %, d̄_m 20 %."
            out.append(make_strategy(name, doc, generator, utility, THESIS_TERMINATION[0], {}, dict(uparams),
                                     dict(THESIS_TERMINATION[1])))
    return out


IROS_TARGET = {"coverage": 0.9875, "density": 0.0, "measure": "border", "n_abort": 30, "switch_delta": 0.0}
IROS = [
    make_strategy("iros/B", "IROS 2012 Table II 'B': boundary search in detection order until none is left.",
                  "boundary", "fov_order", "no_candidates", {"repair": False}),
    make_strategy("iros/S",
                  "IROS 2012 Table II 'S': 121-view sphere, most unknown voxels, stop when unknowns stagnate.",
                  "sphere", "unknown_count", "stagnation", {"lines": True},
                  {}, {"measure": "unknown", "window": 2, "delta": 0.01}),
    make_strategy("iros/S_IG", "IROS 2012 Table II 'S/IG': sphere + information gain, stop at ĉ_m 98.75 %.",
                  "sphere", "information_gain", "coverage_target", {}, {}, dict(IROS_TARGET)),
    make_strategy("iros/B_IG", "IROS 2012 Table II 'B/IG': boundary search + information gain, ĉ_m 98.75 %.",
                  "boundary", "information_gain", "coverage_target", {}, {}, dict(IROS_TARGET)),
    make_strategy("iros/BH_IG", "IROS 2012 Table II 'BH/IG': boundary search + hole detection + IG, ĉ_m 98.75 %.",
                  "boundary_hole", "information_gain", "coverage_target", {}, {}, dict(IROS_TARGET)),
]

class VasquezEU(StrategyPlugin):
    """Vasquez-Gomez expected utility (Algorithm 1, k noisy rollouts) of pos reg sur dist over random views."""

    name = "vasquez/eu"
    params = (Param("k", int, 100, "", "rollouts per candidate (Eq. 18: k >= 90 for alpha 0.01, gamma 0.05)",
                    low=1),) + OVERRIDES
    parts = ("random", "expected_utility", "unknown_below")
    defaults = ({"count": 40}, {"base": "area_factor", "k": 100}, {})

    def __init__(self, k: int, generator_params: dict, utility_params: dict, termination_params: dict) -> None:
        self.strategy = Strategy(self.name, *self.parts, {"count": 40, **generator_params},
                                 {"base": "area_factor", "k": int(k), **utility_params}, dict(termination_params))


#: the stop calibrated on the broad object set (issue 20, docs/results.md, benchmarks/calibrate_stop.py):
#: ĉ_m 95 %, or 90 % once boundary search / hole rescan has nothing left and one fallback view was
#: scanned (below that the session's fallback views go on), or ĉ_m without the support opening 99 %
#: once a fallback view was scanned, or ĉ_m 80 % once it grew by less than 1 point over 5 scans (the
#: candidates add no surface; before any fallback view, the first such stall scans the fallback's best
#: view first and stops two scans later)
CALIBRATED_TERMINATION = {"coverage": 0.95, "exhausted_coverage": 0.90, "off_support_coverage": 0.99,
                          "saturated_coverage": 0.80, "saturated_off_support": 0.90, "saturation_scans": 5,
                          "saturation_delta": 0.01,
                          "density": 0.2, "n_abort": 30}

EXTRA = [
    make_strategy("ig_quality/bs_hr_calibrated",
                  "Thesis IG/Quality over BS/HR candidates with the stop calibrated on the broad object set: "
                  "ĉ_m 95 %, or 90 % when BS/HR has no candidate left after a fallback view, or 99 % without the "
                  "support opening after a fallback view, or 80 % once ĉ_m stops growing and a fallback view was "
                  "tried (c_a at the stop >= 97 % on every object).",
                  "boundary_hole", "ig_quality", "coverage_target", {}, {"omega": -1.0}, dict(CALIBRATED_TERMINATION)),
    make_strategy("vasquez/du", "Vasquez-Gomez deterministic utility (pos reg sur dist) over random views.",
                  "random", "area_factor", "unknown_below", {"count": 40}),
    VasquezEU,
    make_strategy("random/random", "Random views, random choice (the weakest baseline).",
                  "random", "random", "max_scans"),
]

PLUGINS: list = _thesis() + IROS + EXTRA + [Custom]
