"""The view generator contract: where the next candidate views or scan paths come from."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from explore.core.plugin import Plugin
from explore.nbv.candidates import Candidate, PlanningContext


class ViewGenerator(Plugin, ABC):
    """Contract of kind ``view_generator``: new candidates for the candidate stack.

    :meth:`generate` reads the :class:`~explore.nbv.candidates.PlanningContext` (PVS, surface
    model, sensor, history; never the ground truth) and returns new
    :class:`~explore.nbv.candidates.Candidate` objects: a 4x4 world_T_sensor pose (metres, sensor
    z along the optical axis, OpenCV frame) for an area sensor, a
    :class:`~explore.sim.scan.ScanPath` for a line sensor (``ctx.sensor.geometry``). Build them
    with :func:`~explore.nbv.candidates.make_target`. The session keeps candidates across
    iterations and drops stale ones unless the generator is ``persistent``.
    """

    kind = "view_generator"
    #: a fixed search space (the sphere): the stack never drops its candidates as stale
    persistent = False

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.reset()

    def reset(self) -> None:
        """Forget the state of a previous run (called before every run)."""

    @abstractmethod
    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        """New candidates for this iteration (may be empty: the termination then decides)."""
