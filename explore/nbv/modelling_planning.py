"""Choosing and planning the next best scan (Kriegel thesis Fig. 4.1): candidates from the strategy's view
generator (and a fallback generator for robots with a limited workspace), scored by the utility with near-ties
broken by stack order, the termination rule (Sec. 4.6), and planning the best candidates in turn (the NBS
rule: through occupied space a candidate is discarded, through unknown space it is kept for later).
"""

from __future__ import annotations

import time

import numpy as np

from explore.core import BUDGET, pick_best
from explore.nbv.candidates import FALLBACK, STOP, SWITCH, Candidate, Decision
from explore.nbv.modelling_records import FALLBACK_PREFIX, failure_summary
from explore.nbv.scan_planning import KEEP_FOR_LATER, ScanPlan


class CandidatePlanning:
    """Part of :class:`ModellingSession`: candidate generation, selection, termination and scan planning."""

    def generate(self) -> int:
        """Add the generator's candidates to the stack (stale ones are dropped); returns how many.

        Candidates the robot surely cannot reach (capability map of a fixed-base arm, see
        :class:`explore.nbv.scan_planning.CapabilityMap`) are left out before they are scored.
        """
        keep = (self.generator.name,) if getattr(self.generator, "persistent", False) else ()
        self.stack.drop_stale(self.ctx.iteration, self.ctx.executed, keep_sources=keep)
        new = [c for c in self.generator.generate(self.ctx)
               if not any(self.stack._similar(c.pose, pose) for pose in self.ctx.executed)
               and self.motion.may_reach(c.target)]
        self.stack.push(new)
        self.ctx.exhausted = len(self.stack) == 0
        if self.ctx.exhausted and self.fallback is not None:  # the termination still decides whether to go on
            extra = self._fallback_candidates()
            self.stack.push(extra)
            new = new + extra
        self._pending["candidates"] = len(self.stack)
        return len(new)

    def _fallback_candidates(self) -> list[Candidate]:
        if hasattr(self.fallback, "reset"):
            self.fallback.reset()
        extra = [c for c in self.fallback.generate(self.ctx) if self.motion.may_reach(c.target)]
        for cand in extra:
            cand.source = f"{FALLBACK_PREFIX}{cand.source}"
        return extra

    def select(self, rescore: bool = True) -> Candidate | None:
        """Score the stack with the utility and pop the best candidate (timed).

        ``rescore=False`` pops the next best by the scores of the last scoring (the PVS has
        not changed since), used when planning to the best candidate failed.
        """
        self.ctx.available = len(self.stack)
        if len(self.stack) == 0:
            return None
        items = list(self.stack)
        if rescore:
            start = time.perf_counter()
            scores = np.asarray(self.utility.score(items, self.ctx), dtype=float)
            for cand, value in zip(items, scores, strict=True):
                cand.score = float(value)
            elapsed = time.perf_counter() - start
            self.selection_times.append(elapsed)
            self.selection_sizes.append(len(items))
            self._pending["selection_s"] = elapsed
        else:
            scores = np.array([c.score for c in items], dtype=float)
        if self.take_fallback:  # the termination asked for one view of the fallback's (see terminate)
            self.take_fallback = False
            offered = np.array([c.source.startswith(FALLBACK_PREFIX) for c in items])
            if offered.any():
                scores = np.where(offered, scores, -np.inf)
        pick = pick_best(scores)  # near-ties go to the first candidate in stack order
        chosen = self.stack.pop(pick.index if pick is not None else 0)
        self._pending["margin"] = pick.margin if pick is not None else float("nan")
        self.ctx.best_diagnostics = dict(chosen.diagnostics)
        if hasattr(self.generator, "remember"):
            self.generator.remember(chosen)
        self._pend_candidate(chosen)
        return chosen

    @property
    def pending_margin(self) -> float:
        """The lead of the candidate just selected over the runner-up (explore.core.decisions)."""
        return float(self._pending["margin"])

    def terminate(self) -> Decision:
        """Ask the termination plugin (and the hard cap); a ``switch`` sets the hole mode, a ``fallback``
        puts the fallback generator's candidates on the stack and makes the next selection pick the best
        of them (the strategy's own candidates stall: one view chosen over all directions first)."""
        if self.n_scans >= self.max_scans:
            return Decision(STOP, f"max_scans = {self.max_scans} reached", BUDGET)
        decision = self.termination.decide(self.ctx)
        if decision.action == SWITCH:
            self.ctx.mode = "hole"
        if decision.action == FALLBACK and self.fallback is not None:
            self.stack.push(self._fallback_candidates())
            self.take_fallback = True
        self._pending.update(decision=decision.action, reason=decision.reason, termination_margin=decision.margin)
        return decision

    def plan(self, candidate: Candidate) -> ScanPlan:
        """Plan one candidate: scan-path IK, PVS along the scan (NBS rule), approach motion.

        See :mod:`explore.nbv.scan_planning`. The first scan is planned against the known
        environment only (the PVS knows nothing yet); with ``place_first`` it needs no
        approach (the sensor is put at the scan start).
        """
        start = None if (self.n_scans == 0 and self.place_first) else np.asarray(self.robot.q, dtype=float)
        return self.motion.plan(candidate, start, self.n_scans + 1, use_pvs=self.n_scans > 0)

    def plan_initial(self) -> ScanPlan | None:
        """Plan the random initial scan, else the next side or edge of the region; None if none is reachable."""
        failures: list[ScanPlan] = []
        for candidate in self.initial_candidates():
            result = self.plan(candidate)
            if result.ok:
                self._pend_candidate(candidate)
                return result
            failures.append(result)
        self.plan_failure = (f"{failure_summary('initial scans', failures)}; they stand "
                             f"{self.sensor.optimal_distance:.3g} m from the region, the sensor's optimal distance")
        return None

    def plan_best(self, candidate: Candidate | None) -> ScanPlan | None:
        """Plan the selected candidate; if that fails, the next best ones (up to ``max_plan_attempts``).

        Candidates blocked by unknown space or without an approach motion go back on the
        stack for later iterations; unreachable ones and those through occupied space are
        discarded (NBS rule). When none of the strategy's candidates can be planned (a robot
        with a limited workspace), the fallback generator's candidates are scored and tried
        the same way. None (reason in ``plan_failure``) if no candidate could be planned.
        """
        failures: list[ScanPlan] = []
        kept: list[Candidate] = []
        result = self._plan_in_order(candidate, failures, kept)
        if result is None and self.fallback is not None:
            self.stack.push(self._fallback_candidates())
            seconds = self.selection_times[-1] if self.selection_times else 0.0
            candidate = self.select()
            if candidate is not None and self.selection_times:  # one selection time per scan
                self._pending["selection_s"] = seconds + self.selection_times.pop()
                self.selection_sizes.pop()
                if self.selection_times:
                    self.selection_times[-1] = self._pending["selection_s"]
            result = self._plan_in_order(candidate, failures, kept)
        self.stack.push(kept)
        if result is not None:
            self._pend_candidate(result.candidate)
            return result
        self.plan_failure = failure_summary("candidates", failures)
        return None

    def _plan_in_order(self, candidate: Candidate | None, failures: list[ScanPlan],
                       kept: list[Candidate]) -> ScanPlan | None:
        """Plan ``candidate``, then the next best by the last scores, until one works or the budget is spent."""
        tried = 0
        while candidate is not None and tried < self.max_plan_attempts:
            result = self.plan(candidate)
            tried += 1
            if result.ok:
                return result
            failures.append(result)
            if result.verdict in KEEP_FOR_LATER:
                kept.append(candidate)
            candidate = self.select(rescore=False) if tried < self.max_plan_attempts else None
        return None
