"""One exploration run: a tree, a world and the overrides, executed tick by tick.

:class:`RunContext` is the value every behaviour receives in ``setup(context=...)``: the
simulation, the registry, the run's blackboard namespace, a worker thread for long steps,
the trace, the optional Rerun log and a place (``state``) where behaviours keep library
objects (the modelling session, the scene, the database). :func:`execute` checks every
name and setting, ticks the tree until it finishes and writes the run directory
(``metrics.json``, ``trace.jsonl``, meshes, ``pvs.npz``, pictures, the tree as dot/PNG).
The schema of ``metrics.json`` is documented in ``docs/metrics.md``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import queue
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import (
    BUDGET,
    FAILURE,
    INTERRUPTED,
    SUCCESS,
    BadInput,
    Terminated,
    check_output,
    parse_assignment,
    set_threads,
    validate_params,
)
from explore.motion import work_clock

METRICS_SCHEMA_VERSION = 1
PLANNING_CLOCKS = ("work", "wall")
_RUN_IDS = itertools.count(1)


@dataclass
class RunConfig:
    """Everything that defines a run (same config and seed => same metrics)."""

    tree: str
    world: str
    strategy: str | None = None
    planner: str | None = None
    robot: str | None = None
    sensor: str | None = None
    seed: int = 0
    max_scans: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)  # --set key=value
    out: Path | None = None
    max_ticks: int = 100000
    rerun: Path | None = None  # --rerun FILE.rrd
    planning_clock: str = "work"  # motion-planning time limits in work done (deterministic) or "wall" time
    threads: int = 0  # numba / Open3D threads (0: every core); the results do not depend on it

    @staticmethod
    def parse_settings(items: list[str]) -> dict[str, Any]:
        return dict(parse_assignment(item) for item in items)

    def setting(self, key: str, default: Any = None) -> Any:
        return self.settings.get(key, default)

    def scoped(self, prefix: str) -> dict[str, Any]:
        """Settings ``prefix.name=value`` as {name: value}."""
        head = f"{prefix}."
        return {k[len(head) :]: v for k, v in self.settings.items() if k.startswith(head)}


class Worker:
    """Runs the submitted steps one after another in a daemon thread.

    A step abandoned while it runs (e.g. a ``timeout`` decorator stopped its behaviour)
    cannot be killed in Python: it finishes in its own thread and its result is dropped,
    while the steps submitted after it run in a fresh thread instead of waiting behind it.
    """

    def __init__(self, name: str = "explore-worker") -> None:
        self.name = name
        self.abandoned = 0
        self._lock = threading.Lock()
        self._queue: queue.SimpleQueue | None = None
        self._start()

    def _start(self) -> None:
        self._queue = queue.SimpleQueue()
        thread = threading.Thread(target=self._loop, args=(self._queue,), daemon=True,
                                  name=f"{self.name}-{self.abandoned}")
        thread.start()

    def _loop(self, own: queue.SimpleQueue) -> None:
        while True:
            item = own.get()
            with self._lock:
                if own is not self._queue:  # retired after an abandoned step: hand the work over
                    if item is not None:
                        self._queue.put(item)
                    return
            if item is None:
                return
            future, fn = item
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn()
            except BaseException as error:  # noqa: BLE001 - delivered to whoever polls the future
                future.set_exception(error)
            else:
                future.set_result(result)

    def submit(self, fn: Callable[[], Any]) -> Future:
        future: Future = Future()
        with self._lock:
            self._queue.put((future, fn))
        return future

    def abandon(self, future: Future) -> bool:
        """Drop a step: cancel it if it has not started; else move later steps to a fresh thread.

        Returns True if the step was still running (it goes on in the background).
        """
        if future.cancel() or future.done():
            return False
        with self._lock:
            old = self._queue
            self.abandoned += 1
            self._start()
            while True:
                try:
                    self._queue.put(old.get_nowait())
                except queue.Empty:
                    break
            old.put(None)
        return True

    def close(self) -> None:
        with self._lock:
            while True:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
                if item is not None:
                    item[0].cancel()
            self._queue.put(None)


class RunContext:
    """Shared state of one run; behaviours get it in ``setup(context=...)``."""

    GLOBAL_SETTINGS = ("resolution",)  # read by start_modelling (PVS voxel size)

    def __init__(self, config: RunConfig, registry: Any, out_dir: Path) -> None:
        from explore.sim import Simulation, load_world_spec

        self.config = config
        self.registry = registry
        self.out_dir = out_dir
        self.namespace = f"/run{next(_RUN_IDS)}"
        self.started = time.perf_counter()
        self.rng = np.random.default_rng(config.seed)
        self.state: dict[str, Any] = {}
        self.events: list[dict[str, Any]] = []
        self.status_line = ""
        self.root: Any = None  # the py_trees root once built
        self.rerun: Any = None
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
            self.sim.attach_plugins(registry, sensor=sensor, robot=robot)
            if config.rerun is not None:
                from explore.runtime.rerun_log import RerunLog

                self.rerun = RerunLog(config.rerun)
                self.rerun.world(self.sim)
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
        record = {"t": round(time.perf_counter() - self.started, 4), "event": event, **_jsonable(fields)}
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
        if not self._trace_file.closed:
            self._trace_file.close()
        if self.sim is not None:
            self.sim.close()


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.floating | float):
        return None if not np.isfinite(value) else round(float(value), 6)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Path):
        return str(value)
    return value


def default_out_dir(config: RunConfig) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    tree = Path(config.tree).stem
    world = Path(config.world).stem
    return Path("runs") / f"{stamp}-{tree}-{world}"


def prepare_out_dir(path: Path) -> Path:
    """Create the run directory; never overwrite an existing run's results."""
    if (path / "metrics.json").exists():
        raise BadInput(str(path), None, "already holds a run (metrics.json); choose another --out")
    if path.exists() and not path.is_dir():
        raise BadInput(str(path), None, "exists and is not a folder")
    path.mkdir(parents=True, exist_ok=True)
    return path


@dataclass
class RunResult:
    status: str  # one of explore.core.outcomes.STATUSES
    reason: str
    metrics: dict[str, Any]
    out_dir: Path


def execute(
    config: RunConfig,
    registry: Any,
    on_tick: Callable[[Any, RunContext], None] | None = None,
) -> RunResult:
    """Check the inputs, build and tick the tree, write the run directory.

    Every name and setting is checked before the run directory is created. Bad input found
    later (e.g. a behaviour raising :class:`BadInput`) removes what this run wrote and
    re-raises; any other ending writes ``metrics.json`` with the status and reason.
    """
    tree_file, overrides = check_inputs(config, registry)
    path = config.out or default_out_dir(config)
    created = _highest_missing(path)  # the folder this run creates (with runs/ if that is new too)
    out_dir = prepare_out_dir(path)
    set_threads(config.threads)
    try:
        context = RunContext(config, registry, out_dir)
    except BadInput:
        _remove_run_files(out_dir, created)
        raise
    try:
        with work_clock() if config.planning_clock == "work" else contextlib.nullcontext():
            status, reason, root = _tick(config, registry, context, tree_file, overrides, on_tick)
        from explore.runtime.outputs import write_outputs

        metrics = write_outputs(context, tree_file, root, status, reason)
        context.trace("end", status=status, reason=reason)
        return RunResult(status, reason, metrics, out_dir)
    except BadInput:
        context.close()
        _remove_run_files(out_dir, created)
        raise
    except BaseException as error:  # an interrupt (SIGINT, SIGTERM) or a crash: still leave the results behind
        from explore.runtime.outputs import write_outputs

        if isinstance(error, KeyboardInterrupt):
            status, reason = INTERRUPTED, "terminated (SIGTERM)" if isinstance(error, Terminated) else "interrupted"
        else:
            status, reason = FAILURE, f"crashed: {type(error).__name__}: {error}"
        context.settle()  # the step running in the worker ends before its results are read
        write_outputs(context, tree_file, context.root, status, reason)
        context.trace("end", status=status, reason=reason)
        raise
    finally:
        context.close()


def _tick(config: RunConfig, registry: Any, context: RunContext, tree_file: Any,
          overrides: dict[str, dict[str, Any]], on_tick: Callable[[Any, RunContext], None] | None,
          ) -> tuple[str, str, Any]:
    """Tick until the root finishes (or ``max_ticks``); trace every status change."""
    import py_trees
    from py_trees.common import Status

    from explore.runtime.trees import build

    root = build(tree_file.root, registry, overrides, context.namespace)
    context.root = root
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup(context=context)
    context.trace("start", tree=tree_file.name, world=context.sim.spec.name, seed=config.seed)
    previous: dict[int, str] = {}
    ticks = 0
    while ticks < config.max_ticks:
        tree.tick()
        ticks += 1
        for node in root.iterate():
            status = node.status.value
            if previous.get(id(node)) != status:
                previous[id(node)] = status
                if node is not root or status != "RUNNING":
                    context.trace("status", tick=ticks, node=node.name, status=status, message=node.feedback_message)
        if on_tick is not None:
            on_tick(root, context)
        if root.status in (Status.SUCCESS, Status.FAILURE):
            break
        context.wait_for_work(0.1)
    if root.status == Status.SUCCESS:  # the tree succeeded: did the mission reach its goal?
        providers = [p for p in context.state.values() if getattr(p, "end_outcome", "")]
        short = next((p for p in providers if p.end_outcome != SUCCESS), None)
        if short is not None:
            status, reason = short.end_outcome, short.end_reason
        else:
            ends = [getattr(p, "end_reason", "") for p in context.state.values()]
            status, reason = SUCCESS, root.feedback_message or next((e for e in ends if e), "tree succeeded")
    elif root.status == Status.FAILURE:
        status, reason = FAILURE, _failure_reason(root)
    else:
        status, reason = BUDGET, f"tree still running after max_ticks={config.max_ticks}"
    tree.shutdown()
    return status, reason, root


RUN_FILES = ("trace.jsonl", "metrics.json", "metrics.json.tmp", "tree.dot", "tree.png", "model.ply", "model.png",
             "pvs.npz", "coverage.png")


def _highest_missing(path: Path) -> Path | None:
    """The outermost folder of ``path`` that does not exist yet (None if ``path`` exists)."""
    path = path.absolute()
    if path.exists():
        return None
    while not path.parent.exists():
        path = path.parent
    return path


def _remove_run_files(out_dir: Path, created: Path | None) -> None:
    """Undo a run stopped by bad input: its own files, and the folders this run created."""
    if created is not None:
        shutil.rmtree(created, ignore_errors=True)
        return
    for name in RUN_FILES:
        (out_dir / name).unlink(missing_ok=True)


def check_inputs(config: RunConfig, registry: Any) -> tuple[Any, dict[str, dict[str, Any]]]:
    """Everything that can be checked before a run starts: the tree, the world, plugin names,
    ``--set`` keys and plugin parameters, the Rerun file. Raises :class:`BadInput`."""
    from explore.nbv import DEFAULT_PLANNER
    from explore.runtime.trees import load_tree
    from explore.sim import load_world_spec

    if isinstance(config.seed, bool) or not isinstance(config.seed, int) or config.seed < 0:
        raise BadInput("--seed", str(config.seed), "must be an integer >= 0")
    if config.max_scans is not None and (isinstance(config.max_scans, bool) or config.max_scans < 1):
        raise BadInput("--max-scans", str(config.max_scans), "must be at least 1")
    tree_file = load_tree(config.tree, registry)
    overrides = _behaviour_overrides(config, tree_file, registry)
    spec = load_world_spec(config.world)
    robot = config.robot or spec.robot.plugin
    planner = config.planner or DEFAULT_PLANNER
    if "start_nbvs" in {node.behaviour for node in tree_file.root.walk()}:  # view/state planning picks by base
        from explore.nbv import default_planner

        where = ("--robot", None) if config.robot else (str(spec.path), "robot.plugin")
        planner = config.planner or default_planner(registry.get("robot", robot, *where).factory)
    chosen = {
        "strategy": config.strategy,
        "motion_planner": planner,
        "robot": robot,
        "sensor": config.sensor or spec.sensor.plugin,
    }
    options = {"strategy": "--strategy", "motion_planner": "--planner", "robot": "--robot", "sensor": "--sensor"}
    prefixes = {"strategy": "strategy", "motion_planner": "planner", "robot": "robot", "sensor": "sensor"}
    given = {"strategy": config.strategy, "motion_planner": config.planner, "robot": config.robot,
             "sensor": config.sensor}
    for kind, name in chosen.items():
        if name is None:
            continue
        if given[kind] is not None or kind == "motion_planner":
            info = registry.get(kind, name, options[kind], None)
        else:  # the world's choice
            info = registry.get(kind, name, str(spec.path), f"{prefixes[kind]}.plugin")
        scoped = config.scoped(prefixes[kind])
        if scoped:
            validate_params(info.params, scoped, "--set", f"{prefixes[kind]}.")
    _check_grid_size(config, tree_file, overrides, spec)
    if config.planning_clock not in PLANNING_CLOCKS:
        raise BadInput("--planning-clock", None,
                       f"{config.planning_clock!r} is not one of {', '.join(PLANNING_CLOCKS)}")
    if config.out is not None:
        check_output(config.out, "--out", folder=True)
    if config.rerun is not None:
        from explore.runtime.rerun_log import check_rerun

        check_rerun(config.rerun)
    return tree_file, overrides


def _check_grid_size(config: RunConfig, tree_file: Any, overrides: dict[str, dict[str, Any]], spec: Any) -> None:
    """The voxel size (``--set resolution=``, else the tree's) is finite and positive, and the world's
    region at that size fits in memory: checked before the run starts, not as a MemoryError in it."""
    from explore.core import Param
    from explore.mapping import check_grid

    if "resolution" in config.settings:
        resolution = Param("resolution", float, 0.005, "m", low=1e-6).convert(
            config.settings["resolution"], "--set", "resolution")
        source, field_ = "--set", "resolution"
    else:
        given = [overrides.get(n.behaviour, {}).get("resolution", n.params.get("resolution"))
                 for n in tree_file.root.walk() if n.behaviour]
        sizes = [float(size) for size in given if size]
        if not sizes:
            return
        resolution, source, field_ = min(sizes), str(spec.path), "region"
    check_grid(spec.region_min, spec.region_max, resolution, source, field_)


def _failure_reason(root: Any) -> str:
    """The deepest failed node's reason (the step that actually failed)."""
    from py_trees.common import Status

    reason = root.feedback_message or "tree failed"
    failed = [n for n in root.iterate() if n.status == Status.FAILURE and n.feedback_message and not n.children]
    steps = [n for n in failed if not getattr(n, "is_condition", False)]  # a condition's failure is an answer
    for node in steps or failed:
        reason = f"{node.name}: {node.feedback_message}"
    return reason


def _behaviour_overrides(config: RunConfig, tree_file: Any, registry: Any) -> dict[str, dict[str, Any]]:
    """Sort ``--set`` keys into behaviour parameters and run settings; reject unknown keys."""
    in_tree = {node.behaviour for node in tree_file.root.walk() if node.behaviour}
    overrides: dict[str, dict[str, Any]] = {}
    for key, value in config.settings.items():
        head, _, rest = key.partition(".")
        if head in in_tree and rest:
            overrides.setdefault(head, {})[rest] = value
        elif head in ("sensor", "robot", "strategy", "planner") and rest:
            continue
        elif key in RunContext.GLOBAL_SETTINGS:
            continue
        else:
            valid = sorted(in_tree) + ["sensor.*", "robot.*", "strategy.*", "planner.*", *RunContext.GLOBAL_SETTINGS]
            raise BadInput("--set", key, f"unknown setting (valid prefixes: {', '.join(valid)})")
    for name, values in overrides.items():
        validate_params(registry.get("behaviour", name).params, values, "--set", f"{name}.")
    return overrides
