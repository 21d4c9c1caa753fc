"""The value every behaviour of a run receives in setup(context=...): the simulation, the registry, the run's
blackboard namespace, the worker for long steps, the trace (in tree order, whatever the timing) and a place (state)
where behaviours keep library objects."""

from __future__ import annotations

import contextlib
import itertools
import json
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, wait
from pathlib import Path
from typing import Any

import numpy as np

from explore.runtime.rerun_log import RerunLog
from explore.runtime.run_inputs import (
    RunConfig,
    attach_plugins,
    jsonable,
)
from explore.runtime.video import RunVideo, record_scans
from explore.runtime.worker import Worker
from explore.sim import Simulation, load_world_spec

_RUN_IDS = itertools.count(1)


class RunContext:
    """Shared state of one run; behaviours get it in ``setup(context=...)``."""


    def __init__(self, config: RunConfig, registry: Any, out_dir: Path) -> None:
        self.config = config
        self.registry = registry
        self.out_dir = out_dir
        self.namespace = f"/run{next(_RUN_IDS)}"
        self.started = time.perf_counter()
        self.rng = np.random.default_rng(config.seed)
        self.state: dict[str, Any] = {}
        self.events: list[dict[str, Any]] = []
        self.status_line = ""
        self.activity = ""  # what the running step is doing (see progress)
        self.root: Any = None  # the py_trees root once built
        self.rerun: Any = None
        self.video: Any = None
        self.sim: Any = None
        self._trace_file = open(out_dir / "trace.jsonl", "w", encoding="utf-8")  # noqa: SIM115
        self._local = threading.local()
        self._worker = Worker()
        self._futures: list[Future] = []
        try:
            spec = load_world_spec(config.world)
            self.sim = Simulation(spec)
            sensor = (config.sensor or spec.sensor.plugin, self._plugin_params("sensor", spec.sensor))
            robot = (config.robot or spec.robot.plugin, self._plugin_params("robot", spec.robot))
            attach_plugins(self.sim, registry, {"sensor": sensor, "robot": robot},
                           {kind: config.scoped(kind) for kind in ("sensor", "robot")})
            if config.rerun is not None:
                self.rerun = RerunLog(config.rerun)
                self.rerun.world(self.sim)
            if config.video:
                self.video = RunVideo(out_dir / "run.mp4", self)
                record_scans(self.sim.sensor, self.video)
        except BaseException:
            self.close()
            raise

    def _plugin_params(self, kind: str, plugin_spec: Any) -> dict[str, Any]:
        chosen = getattr(self.config, kind)
        params = dict(plugin_spec.params) if chosen in (None, plugin_spec.plugin) else {}
        params.update(self.config.scoped(kind))
        return params

    # -- workers -----------------------------------------------------------------------------
    def submit(self, fn: Callable[[], Any]) -> Future:
        """Run ``fn`` in the run's worker (one step at a time); poll the future while ticking."""
        future = self._worker.submit(fn)
        self._futures = [f for f in self._futures if not f.done()] + [future]
        return future

    def abandon(self, future: Future, node: str = "") -> None:
        """A behaviour stopped waiting for its step (timeout, or its branch was left)."""
        if self._worker.abandon(future):
            self.trace("abandoned", node=node, note="the step goes on in the background; later steps use a "
                                                    "fresh worker thread")
        self._futures = [f for f in self._futures if f is not future]

    def wait_for_work(self, timeout: float) -> None:
        """Block until a worker finishes or ``timeout`` passes (no busy ticking)."""
        pending = [f for f in self._futures if not f.done()]
        if pending:
            wait(pending, timeout=timeout, return_when="FIRST_COMPLETED")

    # -- trace -------------------------------------------------------------------------------
    def trace(self, event: str, **fields: Any) -> None:
        """Write one trace event (held back while a step runs in the worker, see :meth:`held_trace`)."""
        record = {"t": round(time.perf_counter() - self.started, 4), "event": event, **jsonable(fields)}
        held = getattr(self._local, "held", None)
        if held is not None:
            held.append(record)
        else:
            self._write(record)

    def _write(self, record: dict[str, Any]) -> None:
        self.events.append(record)
        self._trace_file.write(json.dumps(record) + "\n")
        self._trace_file.flush()

    @contextlib.contextmanager
    def held_trace(self) -> Iterator[list[dict[str, Any]]]:
        """Hold the trace events of a step that runs in the worker thread; :meth:`release` writes them
        when the tick takes the step's result. The trace's order is then the tree's order, not the
        order in which two threads happened to write (which depends on the machine's load)."""
        self._local.held = held = []
        try:
            yield held
        finally:
            self._local.held = None

    def release(self, held: list[dict[str, Any]]) -> None:
        """Write the held events of a finished step (in the main thread, during the tick)."""
        for record in held:
            self._write(record)

    def progress(self, text: str) -> None:
        """What the running step is doing now (any thread): shown by the live view and the plain
        output's progress lines (:class:`explore.runtime.progress.ProgressLines`), not traced."""
        self.activity = text

    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def settle(self, timeout: float = 30.0) -> None:
        """Cancel the queued steps and wait (at most ``timeout``) for the running one to end."""
        self._worker.close()
        pending = [f for f in self._futures if not f.done() and not f.cancel()]
        if pending:
            wait(pending, timeout=timeout)

    def close(self) -> None:
        self._worker.close()
        for future in self._futures:
            if not future.done():
                future.cancel()
        pending = [f for f in self._futures if not f.done()]
        if pending:  # a step that is running: let it end before the simulation goes away
            wait(pending, timeout=10.0)
        if self.rerun is not None:
            self.rerun.close()
        if self.video is not None:
            self.video.close()
        if not self._trace_file.closed:
            self._trace_file.close()
        if self.sim is not None:
            self.sim.close()
