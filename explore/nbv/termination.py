"""The termination contract: whether to continue, switch the generator's mode, offer the fallback or stop."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from explore.core.plugin import Plugin
from explore.nbv.candidates import Decision, PlanningContext


class Termination(Plugin, ABC):
    """Contract of kind ``termination``: after each scan, continue, switch, offer the fallback or stop.

    :meth:`decide` reads the :class:`~explore.nbv.candidates.PlanningContext` (ĉ_m and d̄_m
    histories, scan count, the candidate stack, ``exhausted`` when the strategy's generator had
    nothing left (a fallback's candidates may be on the stack), the last selection's
    diagnostics; never the ground truth) and returns a :class:`~explore.nbv.candidates.Decision`: ``CONTINUE``,
    ``SWITCH`` (the generator's next mode, e.g. boundary to hole), ``FALLBACK`` (when ``ctx.fallback_available``:
    the session puts its fallback generator's candidates on the stack and scans the best of them next)
    or ``STOP`` with an outcome
    (``explore.core.outcomes``: ``success`` only when the goal was reached, ``budget_exhausted``,
    ``no_candidates``) and a one-line reason.
    """

    kind = "termination"

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.reset()

    def reset(self) -> None:
        """Forget the state of a previous run (called before every run)."""

    @abstractmethod
    def decide(self, ctx: PlanningContext) -> Decision:
        """The decision after the latest scan."""
