"""Built-in termination rules: each ``decide(ctx) -> Decision`` (continue / switch / stop + reason).

They read only the planning context (ĉ_m and d̄_m history, scan count, candidate stack,
the last selection's diagnostics, unknown-voxel counts), never the ground truth.
"""

from __future__ import annotations

from explore.api import Termination
from explore.core import BUDGET, NO_CANDIDATES, SUCCESS, Param, reaches
from explore.nbv import CONTINUE, FALLBACK, STOP, SWITCH, Decision, PlanningContext


def window_ends(history: list[float], window: int) -> tuple[float, float] | None:
    """(the value ``window`` scans ago, the latest value) of a per-scan history; None while it is shorter."""
    if len(history) <= window:
        return None
    return float(history[-1 - window]), float(history[-1])


class MaxScans(Termination):
    """Stop after a number of scans."""

    name = "max_scans"
    params = (Param("max_scans", int, 30, "", "scans to take", low=1),)

    def decide(self, ctx: PlanningContext) -> Decision:
        if ctx.iteration >= self.max_scans:
            return Decision(STOP, f"{ctx.iteration} scans taken (max {self.max_scans})", BUDGET)
        return Decision(CONTINUE, "")


class CoverageTarget(Termination):
    """Stop at ĉ_m >= target and d̄_m >= target, else at n_abort scans (thesis Sec. 4.6: 80 % / 20 % / 30).

    With ``exhausted_coverage`` < 1 it also stops at that lower ĉ_m when the strategy's generator
    has nothing left to look at (boundary search and hole rescan find no open edge), after one view of
    the session's fallback generator (over all directions) if it has one and none was scanned yet: ĉ_m
    (Eq. 4.35) underestimates c_a by 1-38 points depending on the shape (docs/results.md, the
    broad set), so a single target either stops early on some shapes or never on others. Most of
    that bias is the opening where the object stands on its support, which no sensor sees: with
    ``off_support_coverage`` > 0 it also stops when ĉ_m without that opening reaches the target
    once a fallback view (chosen over all directions) has been scanned; the fallback view is what
    finds a cavity that the fan areas of its small openings do not count. With
    ``saturated_coverage`` < 1 it also stops at that ĉ_m once ĉ_m has stopped growing: shapes whose
    many small holes no view closes (parts of several bodies, thin bars) keep boundary or hole
    candidates that add no surface, and would otherwise scan on to n_abort. Boundary search and hole
    rescan also stall in front of a cavity they have no candidate into (a shape sorter's inside,
    seen through its openings), so if no fallback view (over all directions) has been scanned yet
    and the session has a fallback generator, the first saturation only offers its candidates
    (``FALLBACK``), and the stop waits two scans for them. With ``saturated_off_support`` < 1 a
    saturated ĉ_m also stops at that ĉ_m without the support opening: under a part that overhangs
    its support the open underside's loop leaves the support plane, the third clause does not leave
    all of it out, and ĉ_m stays below ``saturated_coverage`` however complete the model.
    """

    name = "coverage_target"
    params = (
        Param("coverage", float, 0.8, "", "ĉ_m target (thesis simulation 80 %; IROS 98.75 % with 'border')",
              low=0.0, high=1.0),
        Param("density", float, 0.2, "", "d̄_m target (thesis 20 %)", low=0.0, high=1.0),
        Param("n_abort", int, 30, "", "stop after this many scans regardless", low=1),
        Param("measure", str, "area", "", "ĉ_m from areas with hole fans (Eq. 4.35) or border edges (IROS Eq. 3)",
              choices=("area", "border")),
        Param("switch_delta", float, 0.01, "", "advise a mode switch when ĉ_m grows less (Eq. 4.38); 0 = never",
              low=0.0),
        Param("exhausted_coverage", float, 1.0, "", "also stop at this ĉ_m when the strategy's generator has no "
              "candidate left (nothing more for boundary search / hole rescan to look at); 1 = never",
              low=0.0, high=1.0),
        Param("off_support_coverage", float, 0.0, "", "also stop at this ĉ_m without the opening where the object "
              "stands on its support, once a fallback view has been scanned; 0 = never", low=0.0, high=1.0),
        Param("saturated_coverage", float, 1.0, "", "also stop at this ĉ_m once it grew by less than "
              "saturation_delta over the last saturation_scans scans (the candidates add no surface); 1 = never",
              low=0.0, high=1.0),
        Param("saturated_off_support", float, 1.0, "", "the saturation stop also at this ĉ_m without the "
              "support opening (a part overhanging its support, whose open underside the third clause misses "
              "where its loop leaves the support plane); 1 = never", low=0.0, high=1.0),
        Param("saturation_scans", int, 3, "", "scans over which ĉ_m must grow", low=1),
        Param("saturation_delta", float, 0.01, "", "growth of ĉ_m below which it has saturated", low=0.0),
    )

    def reset(self) -> None:
        self.switched = False
        self.offered_at: int | None = None  # scan count at which the fallback's candidates were offered

    def estimate(self, ctx: PlanningContext) -> float:
        if self.measure == "border":
            return float(ctx.surface.coverage_border())
        return float(ctx.coverage_history[-1]) if ctx.coverage_history else float(ctx.surface.coverage_area())

    def _offer_fallback(self, ctx: PlanningContext, reason: str, margin: float) -> Decision | None:
        """``FALLBACK`` the first time a clause would stop before any view of the session's fallback
        generator (over all directions) was scanned; None once one was, or without a fallback."""
        if ctx.fallback_available and not ctx.fallback_scans and self.offered_at is None:
            self.offered_at = ctx.iteration
            return Decision(FALLBACK, f"{reason}: the fallback's views are offered first", margin=margin)
        return None

    def decide(self, ctx: PlanningContext) -> Decision:
        c = self.estimate(ctx)
        d = float(ctx.density_history[-1]) if ctx.density_history else float(ctx.surface.mean_density())
        margin = min(c - self.coverage, d - self.density)
        if reaches(c, self.coverage) and reaches(d, self.density):
            return Decision(STOP, f"ĉ_m = {c:.3f} >= {self.coverage} and d̄_m = {d:.3f} >= {self.density}", SUCCESS,
                            margin)
        if ctx.exhausted and self.exhausted_coverage < 1.0 and reaches(c, self.exhausted_coverage) \
                and reaches(d, self.density):
            reason = f"no candidate left at ĉ_m = {c:.3f} >= {self.exhausted_coverage}, d̄_m = {d:.3f} >= {self.density}"
            margin = min(c - self.exhausted_coverage, d - self.density)
            return self._offer_fallback(ctx, reason, margin) or Decision(STOP, reason, SUCCESS, margin)
        off = float(ctx.off_support_history[-1]) if ctx.off_support_history else 0.0
        if self.off_support_coverage > 0.0 and ctx.fallback_scans and reaches(off, self.off_support_coverage) \
                and reaches(d, self.density):
            reason = (f"ĉ_m without the support opening = {off:.3f} >= {self.off_support_coverage} after "
                      f"{ctx.fallback_scans} fallback scan(s), d̄_m = {d:.3f} >= {self.density}")
            return Decision(STOP, reason, SUCCESS, min(off - self.off_support_coverage, d - self.density))
        history = ctx.coverage_history
        ends = window_ends(history, self.saturation_scans)
        at_floor = reaches(c, self.saturated_coverage)
        high = at_floor or reaches(off, self.saturated_off_support)
        if self.saturated_coverage < 1.0 and ends is not None and high and reaches(d, self.density) \
                and not reaches(gain := ends[1] - ends[0], self.saturation_delta):
            level = (f"ĉ_m = {c:.3f} >= {self.saturated_coverage}" if at_floor else
                     f"ĉ_m = {c:.3f} (without the support opening {off:.3f} >= {self.saturated_off_support})")
            reason = (f"{level} grew by {gain:.4f} < {self.saturation_delta} over {self.saturation_scans} scans, "
                      f"d̄_m = {d:.3f} >= {self.density}")
            margin = min(self.saturation_delta - gain,
                         max(c - self.saturated_coverage, off - self.saturated_off_support))
            if offer := self._offer_fallback(ctx, reason, margin):
                return offer
            if self.offered_at is None or ctx.iteration - self.offered_at >= 2:
                return Decision(STOP, reason, SUCCESS, margin)
        if ctx.iteration >= self.n_abort:
            return Decision(STOP, f"n_abort = {self.n_abort} scans reached (ĉ_m = {c:.3f}, d̄_m = {d:.3f})", BUDGET,
                            margin)
        stalled = len(history) >= 2 and history[-1] - history[-2] < self.switch_delta
        if self.switch_delta > 0 and not self.switched and stalled:
            self.switched = True
            return Decision(SWITCH, f"ĉ_m grew by {history[-1] - history[-2]:.4f} < {self.switch_delta}: hole rescan",
                            margin=margin)
        return Decision(CONTINUE, f"ĉ_m = {c:.3f}, d̄_m = {d:.3f}", margin=margin)


class NoCandidates(Termination):
    """Stop when no candidate is left on the stack (IROS 'B': no boundaries left)."""

    name = "no_candidates"
    params = (Param("n_abort", int, 30, "", "stop after this many scans regardless", low=1),)

    def decide(self, ctx: PlanningContext) -> Decision:
        if (ctx.exhausted or ctx.available == 0) and ctx.iteration > 0:
            return Decision(STOP, "no candidate left", NO_CANDIDATES)
        if ctx.iteration >= self.n_abort:
            return Decision(STOP, f"n_abort = {self.n_abort} scans reached", BUDGET)
        return Decision(CONTINUE, "")


class UnknownBelow(Termination):
    """Stop when the best candidate sees fewer unknown voxels than a threshold (Vasquez-Gomez: 30)."""

    name = "unknown_below"
    params = (
        Param("threshold", float, 30.0, "", "unknown voxels the selected candidate must see", low=0.0),
        Param("n_abort", int, 30, "", "stop after this many scans regardless", low=1),
    )

    def decide(self, ctx: PlanningContext) -> Decision:
        seen = ctx.best_diagnostics.get("unknown_first", ctx.best_diagnostics.get("unknown"))
        if seen is not None and not reaches(seen, self.threshold):
            return Decision(STOP, f"best candidate sees {seen:.0f} < {self.threshold:.0f} unknown voxels", SUCCESS,
                            self.threshold - seen)
        if ctx.iteration >= self.n_abort:
            return Decision(STOP, f"n_abort = {self.n_abort} scans reached", BUDGET)
        return Decision(CONTINUE, "")


class Stagnation(Termination):
    """Stop when ĉ_m (or the unknown-voxel count) changed less than delta over a window of scans."""

    name = "stagnation"
    params = (
        Param("measure", str, "coverage", "", "what must stop changing", choices=("coverage", "unknown")),
        Param("window", int, 2, "", "scans over which the change is measured", low=1),
        Param("delta", float, 0.005, "", "relative change below which the run stagnates", low=0.0),
        Param("min_scans", int, 3, "", "never stop before this many scans", low=1),
        Param("n_abort", int, 30, "", "stop after this many scans regardless", low=1),
    )

    def decide(self, ctx: PlanningContext) -> Decision:
        if ctx.iteration >= self.n_abort:
            return Decision(STOP, f"n_abort = {self.n_abort} scans reached", BUDGET)
        history = ctx.coverage_history if self.measure == "coverage" else ctx.unknown_history
        ends = window_ends(history, self.window)
        if ctx.iteration < self.min_scans or ends is None:
            return Decision(CONTINUE, "")
        old, new = ends
        change = abs(new - old) / max(abs(old), 1e-9) if self.measure == "unknown" else abs(new - old)
        if not reaches(change, self.delta):
            return Decision(STOP, f"{self.measure} changed by {change:.4f} < {self.delta} over {self.window} scans",
                            NO_CANDIDATES, self.delta - change)
        return Decision(CONTINUE, "", margin=self.delta - change)


PLUGINS = [MaxScans, CoverageTarget, NoCandidates, UnknownBelow, Stagnation]
