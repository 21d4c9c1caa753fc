"""One exploration run: a tree, a world and the overrides, executed tick by tick.

:class:`RunContext` is the value every behaviour receives in ``setup(context=...)``: the
simulation, the registry, the run's blackboard namespace, a worker thread for long steps,
the trace and a place (``state``) where behaviours keep library objects (the modelling
session, the scene, the database). :func:`execute` ticks the tree until it finishes and
writes the run directory (``metrics.json``, ``trace.jsonl``, meshes, ``pvs.npz``, pictures,
the tree as dot/PNG). The schema of ``metrics.json`` is documented in ``docs/metrics.md``.
"""

from __future__ import annotations

import itertools
import json
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from .errors import BadInput
from .params import parse_assignment

METRICS_SCHEMA_VERSION = 1
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

    @staticmethod
    def parse_settings(items: list[str]) -> dict[str, Any]:
        return dict(parse_assignment(item) for item in items)

    def setting(self, key: str, default: Any = None) -> Any:
        return self.settings.get(key, default)

    def scoped(self, prefix: str) -> dict[str, Any]:
        """Settings ``prefix.name=value`` as {name: value}."""
        head = f"{prefix}."
        return {k[len(head) :]: v for k, v in self.settings.items() if k.startswith(head)}


class RunContext:
    """Shared state of one run; behaviours get it in ``setup(context=...)``."""

    GLOBAL_SETTINGS = ("resolution", "tau", "surface.point_spacing")

    def __init__(self, config: RunConfig, registry: Any, out_dir: Path) -> None:
        from .simulation import Simulation
        from .world import load_world_spec

        self.config = config
        self.registry = registry
        self.out_dir = out_dir
        self.namespace = f"/run{next(_RUN_IDS)}"
        self.started = time.perf_counter()
        self.rng = np.random.default_rng(config.seed)
        self.state: dict[str, Any] = {}
        self.events: list[dict[str, Any]] = []
        self.status_line = ""
        self._trace_file = open(out_dir / "trace.jsonl", "w", encoding="utf-8")  # noqa: SIM115
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="explore-worker")
        self._futures: list[Future] = []
        spec = load_world_spec(config.world)
        self.sim = Simulation(spec)
        try:
            sensor = (config.sensor or spec.sensor.plugin, self._plugin_params("sensor", spec.sensor))
            robot = (config.robot or spec.robot.plugin, self._plugin_params("robot", spec.robot))
            self.sim.attach_plugins(registry, sensor=sensor, robot=robot)
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
        future = self._pool.submit(fn)
        self._futures = [f for f in self._futures if not f.done()] + [future]
        return future

    def wait_for_work(self, timeout: float) -> None:
        """Block until a worker finishes or ``timeout`` passes (no busy ticking)."""
        pending = [f for f in self._futures if not f.done()]
        if pending:
            wait(pending, timeout=timeout, return_when="FIRST_COMPLETED")

    # -- trace -------------------------------------------------------------------------------
    def trace(self, event: str, **fields: Any) -> None:
        record = {"t": round(time.perf_counter() - self.started, 4), "event": event, **_jsonable(fields)}
        self.events.append(record)
        self._trace_file.write(json.dumps(record) + "\n")
        self._trace_file.flush()

    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
        if not self._trace_file.closed:
            self._trace_file.close()
        if getattr(self, "sim", None) is not None:
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
    status: str  # "success" | "failure"
    reason: str
    metrics: dict[str, Any]
    out_dir: Path


def execute(
    config: RunConfig,
    registry: Any,
    on_tick: Callable[[Any, RunContext], None] | None = None,
) -> RunResult:
    """Load, validate, build and tick the tree; write the run directory."""
    import py_trees
    from py_trees.common import Status

    from .trees import build, load_tree

    tree_file = load_tree(config.tree, registry)
    overrides = _behaviour_overrides(config, tree_file, registry)
    out_dir = prepare_out_dir(config.out or default_out_dir(config))
    context = RunContext(config, registry, out_dir)
    try:
        root = build(tree_file.root, registry, overrides, context.namespace)
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
                        message = node.feedback_message
                        context.trace("status", tick=ticks, node=node.name, status=status, message=message)
            if on_tick is not None:
                on_tick(root, context)
            if root.status in (Status.SUCCESS, Status.FAILURE):
                break
            context.wait_for_work(0.1)
        if root.status == Status.SUCCESS:
            status, reason = "success", root.feedback_message or "tree succeeded"
        elif root.status == Status.FAILURE:
            status, reason = "failure", _failure_reason(root)
        else:
            status, reason = "failure", f"tree still running after max_ticks={config.max_ticks}"
        tree.shutdown()
        from .run_outputs import write_outputs

        metrics = write_outputs(context, tree_file, root, status, reason)
        context.trace("end", status=status, reason=reason)
        return RunResult(status, reason, metrics, out_dir)
    finally:
        context.close()


def _failure_reason(root: Any) -> str:
    """The deepest failed node's reason (the step that actually failed)."""
    from py_trees.common import Status

    reason = root.feedback_message or "tree failed"
    for node in root.iterate():
        if node.status == Status.FAILURE and node.feedback_message and not node.children:
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
    return overrides
