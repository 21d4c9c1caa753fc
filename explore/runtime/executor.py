"""The executor contract: where the runs of ``explore compare`` execute."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

from explore.core.plugin import Plugin
from explore.runtime.compare_grid import OnDone, RunSpec


class Executor(Plugin, ABC):
    """Contract of kind ``executor``.

    :meth:`run` executes every :class:`~explore.runtime.compare_grid.RunSpec`, each in its own
    process started with :func:`~explore.runtime.isolated_runs.run_isolated` (the same worker
    command and environment everywhere, so the same seeds give the same results on any
    executor), and calls ``on_done(spec, row)`` in the calling thread as each run ends.
    :meth:`check` runs before any run starts: a resource that cannot be reached is a
    :class:`~explore.core.errors.BadInput` (one line, exit code 2), never a traceback later.
    """

    kind = "executor"

    def check(self) -> None:
        """Fail early (BadInput) when the executor cannot run anything; nothing to check by default."""

    @abstractmethod
    def run(self, specs: Sequence[RunSpec], on_done: OnDone) -> None:
        """Execute ``specs``; ``on_done(spec, row)`` as each ends (rows have ``status`` and ``reason``)."""
