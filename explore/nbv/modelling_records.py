"""What a modelling session records and returns: one record per scan, the result of a run, the strategy it
resolves, and the summary of why planning failed."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from explore.core import BadInput
from explore.nbv.scan_planning import ScanPlan

#: source prefix of candidates from the session's fallback generator ("fallback_sphere", ...)
FALLBACK_PREFIX = "fallback_"


@dataclass
class ScanRecord:
    """What one iteration did."""

    index: int
    source: str
    info: dict[str, Any]
    scan_length_m: float
    travel_m: float
    selection_s: float
    candidates: int
    coverage_estimate: float
    coverage_border: float
    coverage_off_support: float  # ĉ_m without the opening at the support (mesh_holes.coverage_area)
    density: float
    unknown_voxels: int
    decision: str = ""
    reason: str = ""
    score: float = float("nan")
    margin: float = float("nan")  # the chosen candidate's lead over the runner-up (explore.core.decisions)
    termination_margin: float = float("nan")  # how far the termination rule was from its stop
    step_s: float = 0.0
    coverage: float = float("nan")  # ground-truth c_a, filled by metrics()


@dataclass
class ModellingResult:
    """The outcome of :meth:`ModellingSession.run`."""

    status: str
    reason: str
    records: list[ScanRecord]
    metrics: dict[str, Any] = field(default_factory=dict)


def require_an_object(sim: Any) -> None:
    """A single-object session (model_object, nbvs_mobile) models the world's objects and measures its coverage
    on them: a world without objects is bad input for it, said before the run starts (the scene trees, which
    look for objects, take an empty table)."""
    if not sim.spec.objects:
        raise BadInput(str(sim.spec.path), "objects", "no object to model: this tree models the world's objects "
                       "(the scene trees take a world without objects)")


def resolve_strategy(strategy: Any, registry: Any) -> Any:
    """A :class:`~explore.nbv.strategy.Strategy` from a name, (name, params), an object or None
    (the registry's default strategy)."""
    if strategy is None:
        strategy = registry.default("strategy")
    if isinstance(strategy, str):
        return registry.create("strategy", strategy, {}, "<strategy>").strategy
    if isinstance(strategy, tuple):
        return registry.create("strategy", strategy[0], strategy[1], "<strategy>").strategy
    return getattr(strategy, "strategy", strategy)


def failure_summary(what: str, failures: list[ScanPlan]) -> str:
    """``"10 candidates tried: 6 unreachable, 4 unknown"`` (the verdicts of failed plans)."""
    counts: dict[str, int] = {}
    for failure in failures:
        counts[failure.verdict] = counts.get(failure.verdict, 0) + 1
    detail = ", ".join(f"{n} {verdict}" for verdict, n in counts.items())
    return f"{len(failures)} {what} tried: {detail}" if failures else f"no {what}"
