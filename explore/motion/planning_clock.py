"""The clock that motion-planning time limits are measured on: wall time or work done.

With wall time a run depends on the CPU load: a planner cut short by its time limit
returns another path (or none), the noisy execution of that path differs, and so does the
rest of the run. Inside :func:`work_clock` the planning budgets count work instead: every
validity check and every planner iteration advances the clock by a fixed nominal cost
(:data:`COSTS`, seconds measured on the 2-core CI machine by ``benchmarks/planning_clock.py``),
so the same seed gives the same plans beside any other load. Reported planning times stay
wall times. A planner that spends a limit's worth of wall time ten times over without
reaching its work budget is still stopped (:meth:`Budget.expired`), so nothing hangs; that
fallback is the only place where wall time decides.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

# Nominal seconds per unit of work, fitted to wall time by benchmarks/planning_clock.py (2 cores, no load:
# 4.7-5.4e-4, 1.3e-4 and ~0 s); a work limit then lasted 0.7-1.9 times as long in wall time. The checks got
# faster since (at 8b27dfb a limit lasts 0.18-0.42 times as long, docs/results.md); the costs are kept so
# that the same seed still gives the same plans as the measured runs.
COSTS: dict[str, float] = {
    "state": 4.0e-4,  # MotionProblem.is_valid: pybullet pair tests and the PVS points of one configuration
    "planar": 1.0e-4,  # PlanarChecker: one rigid base pose against boxes (numba) and the PVS
    "iteration": 1.0e-5,  # one evaluation of a planner's termination condition (one iteration)
}
WALL_FACTOR = 10.0  # the hang guard: a budget also ends after this many times its length in wall time

_work: float | None = None  # None: the wall clock
counts: dict[str, int] = dict.fromkeys(COSTS, 0)  # units charged inside work_clock (for calibration)
wall_stops = 0  # budgets the hang guard ended since work_clock began: wall time decided, a rerun may differ


def now() -> float:
    """Seconds on the planning clock (``time.perf_counter`` unless inside :func:`work_clock`)."""
    return time.perf_counter() if _work is None else _work


def charge(kind: str, count: int = 1) -> None:
    """Advance the work clock by ``count`` units of ``kind`` (nothing on the wall clock)."""
    global _work
    if _work is not None:
        _work += COSTS[kind] * count
        counts[kind] += count


@contextmanager
def work_clock() -> Iterator[None]:
    """Measure planning budgets in work done (starting at 0) until the block ends."""
    global _work, wall_stops
    previous = _work
    _work, wall_stops = 0.0, 0
    try:
        yield
    finally:
        _work = previous


def wall_guard_stops() -> int:
    """Budgets the hang guard ended since :func:`work_clock` began (each one let wall time decide)."""
    return wall_stops


class Budget:
    """A time limit from now on the planning clock, with the wall-time hang guard."""

    def __init__(self, limit: float) -> None:
        self.limit = max(0.0, float(limit))
        self.deadline = now() + self.limit
        self.wall_deadline = time.perf_counter() + WALL_FACTOR * self.limit + 1.0
        self._guard_stopped = False

    def remaining(self) -> float:
        return self.deadline - now()

    def expired(self) -> bool:
        global wall_stops
        if now() >= self.deadline:
            return True
        if _work is None or time.perf_counter() < self.wall_deadline:
            return False
        if not self._guard_stopped:  # the hang guard decides: counted once per budget
            self._guard_stopped = True
            wall_stops += 1
        return True

    def share(self, fraction: float) -> Budget:
        """A budget of ``fraction`` of the remaining time (ending no later than this one)."""
        out = Budget(max(0.0, self.remaining()) * fraction)
        out.wall_deadline = min(out.wall_deadline, self.wall_deadline)
        return out

    def slice(self, seconds: float) -> Budget:
        """A budget of ``seconds`` (at most what remains, ending no later than this one)."""
        out = Budget(min(float(seconds), max(0.0, self.remaining())))
        out.wall_deadline = min(out.wall_deadline, self.wall_deadline)
        return out

    def ompl_condition(self) -> Any:
        """An OMPL ``PlannerTerminationCondition`` that charges one iteration per evaluation."""
        from ompl import base as ob

        def done() -> bool:
            charge("iteration")
            return self.expired()

        return ob.PlannerTerminationCondition(done)
