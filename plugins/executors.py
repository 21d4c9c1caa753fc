"""Built-in executor plugins: where the runs of ``explore compare`` execute.

An executor has one method, ``run(specs, on_done)``: execute every
:class:`explore.compare.RunSpec` (each in its own process, see
:class:`explore.compare.IsolatedRun`) and call ``on_done(spec, row)`` in the calling thread
as each run ends. Both built-ins start the very same worker command with the same
environment, so the same seeds give the same results on either.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from explore.compare import OnDone, RunSpec, run_isolated, run_local
from explore.params import Param


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class LocalExecutor:
    """Local process pool: every run in its own process, ``jobs`` at a time (0 = the cores)."""

    kind = "executor"
    name = "local"
    params = (Param("jobs", int, 0, "", "concurrent runs (0: one per core)", low=0),)

    def __init__(self, jobs: int = 0) -> None:
        self.jobs = jobs or _cores()

    def run(self, specs: Sequence[RunSpec], on_done: OnDone) -> None:
        run_local(specs, on_done, self.jobs)


class RayExecutor:
    """Ray tasks: the runs on a Ray cluster (``address``) or a local Ray instance (``jobs`` CPUs).

    Each task starts the run's process on its node, so ``--out`` must be a folder that every
    node can write (a shared file system); the rows travel back to the driver either way.
    """

    kind = "executor"
    name = "ray"
    params = (
        Param("address", str, "", "", "Ray cluster address (empty: start a local instance)"),
        Param("jobs", int, 0, "", "CPUs of a local instance (0: one per core)", low=0),
    )

    def __init__(self, address: str = "", jobs: int = 0) -> None:
        self.address = address
        self.jobs = jobs or _cores()

    def run(self, specs: Sequence[RunSpec], on_done: OnDone) -> None:
        import ray

        started_here = not ray.is_initialized()
        if started_here:
            options: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
            if self.address:
                ray.init(address=self.address, **options)
            else:
                ray.init(num_cpus=self.jobs, include_dashboard=False, **options)
        task = ray.remote(num_cpus=1, max_retries=0)(run_isolated)
        refs = {task.remote(spec.to_dict()): spec for spec in specs}
        try:
            while refs:
                done, _ = ray.wait(list(refs), num_returns=1)
                for ref in done:
                    spec = refs.pop(ref)
                    try:
                        row = ray.get(ref)
                    except Exception as error:  # noqa: BLE001 - a lost task is a crashed run
                        row = {**spec.grid_values(), "status": "crashed", "reason": f"ray: {type(error).__name__}"}
                    on_done(spec, row)
        finally:
            for ref in refs:
                ray.cancel(ref, force=True)
            if started_here:
                ray.shutdown()


PLUGINS: list = [LocalExecutor, RayExecutor]
