"""What defines a run and what is checked before it starts: the run's configuration (tree, world, plugins, seed,
budgets, --set overrides), its run directory (never one that holds a run already), and every name and setting checked
before the directory is created (bad input leaves nothing behind)."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import (
    BadInput,
    Param,
    PluginCheckFailed,
    check_output,
    parse_assignment,
    validate_params,
)
from explore.mapping import check_grid
from explore.runtime.rerun_log import check_rerun
from explore.runtime.trees import load_tree
from explore.sim import load_world_spec

METRICS_SCHEMA_VERSION = 1
GLOBAL_SETTINGS = ("resolution",)  # --set keys of the run itself (the PVS voxel size start_modelling reads)


PLANNING_CLOCKS = ("work", "wall")


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
    video: bool = False  # --video: run.mp4, one frame per scan (explore.runtime.video)

    @staticmethod
    def parse_settings(items: list[str]) -> dict[str, Any]:
        return dict(parse_assignment(item) for item in items)

    def setting(self, key: str, default: Any = None) -> Any:
        return self.settings.get(key, default)

    def scoped(self, prefix: str) -> dict[str, Any]:
        """Settings ``prefix.name=value`` as {name: value}; a dotted name reaches into a mapping
        parameter (``strategy.utility_params.jitter=0.05`` -> {"utility_params": {"jitter": 0.05}})."""
        head = f"{prefix}."
        out: dict[str, Any] = {}
        for key, value in self.settings.items():
            if not key.startswith(head):
                continue
            *parents, leaf = key[len(head):].split(".")
            node = out
            for part in parents:
                child = node.get(part)
                node[part] = dict(child) if isinstance(child, dict) else {}
                node = node[part]
            node[leaf] = value
        return out


def jsonable(value: Any, digits: int | None = 6) -> Any:
    """Plain JSON values; floats rounded to ``digits`` decimals (None keeps every digit), NaN/inf as null."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, digits) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), digits)
    if isinstance(value, np.floating | float):
        if not np.isfinite(value):
            return None
        return float(value) if digits is None else round(float(value), digits)
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
    """Create the run directory; never overwrite an existing run's results or a file a run would write."""
    if path.exists() and not path.is_dir():
        raise BadInput(str(path), None, "exists and is not a folder")
    present = [name for name in RUN_FILES if (path / name).exists()]
    if present:
        what = ("a run (metrics.json)" if "metrics.json" in present
                else f"{', '.join(present)}, which a run would overwrite")
        raise BadInput(str(path), None, f"already holds {what}; choose another --out")
    path.mkdir(parents=True, exist_ok=True)
    return path


RUN_FILES = ("trace.jsonl", "metrics.json", "metrics.json.tmp", "tree.dot", "tree.png", "model.ply", "model.png",
             "pvs.npz", "pvs.bt", "coverage.png", "run.mp4")


def highest_missing(path: Path) -> Path | None:
    """The outermost folder of ``path`` that does not exist yet (None if ``path`` exists)."""
    path = path.absolute()
    if path.exists():
        return None
    while not path.parent.exists():
        path = path.parent
    return path


def remove_run_files(out_dir: Path, created: Path | None) -> None:
    """Undo a run stopped by bad input: its own files, and the folders this run created."""
    if created is not None:
        shutil.rmtree(created, ignore_errors=True)
        return
    for name in RUN_FILES:
        (out_dir / name).unlink(missing_ok=True)


def attach_plugins(sim: Any, registry: Any, chosen: dict[str, tuple[str, dict[str, Any]]],
                   overrides: dict[str, dict[str, Any]], prefixed: bool = True) -> None:
    """``sim.attach_plugins`` with the sensor and robot ``chosen`` (kind -> (plugin, parameters)). A
    plugin's own consistency check (e.g. max_range above min_range) that fails only with the ``--set``
    ``overrides`` (kind -> the keys given) names them, not the world file, whose parameters pass
    without them; keys read ``kind.key`` (``explore run``) or ``key`` (``prefixed`` False)."""
    try:
        sim.attach_plugins(registry, **chosen)
    except PluginCheckFailed as error:
        kind = error.kind
        given = overrides.get(kind, {})
        if not given or kind not in chosen or error.source != str(sim.spec.path):
            raise
        name, params = chosen[kind]
        try:
            registry.create(kind, name, {k: v for k, v in params.items() if k not in given}, error.source, kind)
        except Exception:  # noqa: BLE001 - the world's own parameters fail too: its error stands
            raise error from None
        keys = ", ".join(f"{kind}.{key}" if prefixed else key for key in given)
        raise BadInput("--set", keys, f"{error.message} ({error.field}, the other parameters from "
                                      f"{error.source})") from None


def check_inputs(config: RunConfig, registry: Any) -> tuple[Any, dict[str, dict[str, Any]]]:
    """Everything that can be checked before a run starts: the tree, the world, plugin names,
    ``--set`` keys and plugin parameters, the Rerun file. Raises :class:`BadInput`."""
    if isinstance(config.seed, bool) or not isinstance(config.seed, int) or config.seed < 0:
        raise BadInput("--seed", str(config.seed), "must be an integer >= 0")
    if config.max_scans is not None and (isinstance(config.max_scans, bool) or config.max_scans < 1):
        raise BadInput("--max-scans", str(config.max_scans), "must be at least 1")
    named = {"TREE": config.tree, "--world": config.world, "--strategy": config.strategy,
             "--planner": config.planner, "--robot": config.robot, "--sensor": config.sensor}
    for option, name in named.items():
        if name is not None and not str(name).strip():
            raise BadInput(option, None, "an empty name")
    tree_file = load_tree(config.tree, registry)
    overrides = _behaviour_overrides(config, tree_file, registry)
    spec = load_world_spec(config.world)
    robot = config.robot or spec.robot.plugin or registry.default("robot", "world")[0]
    where = ("--robot", None) if config.robot else (str(spec.path), "robot.plugin")
    planner = config.planner or registry.planner_for(registry.get("robot", robot, *where).factory)
    tree_strategy = None if config.strategy else _tree_strategy(tree_file, overrides, registry)
    chosen = {
        "strategy": config.strategy or (tree_strategy[0] if tree_strategy else None),
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
        elif kind == "strategy" and tree_strategy:  # the tree's choice
            info = registry.get(kind, name, *tree_strategy[1:])
        else:  # the world's choice
            info = registry.get(kind, name, str(spec.path), f"{prefixes[kind]}.plugin")
        scoped = config.scoped(prefixes[kind])
        if scoped:
            validate_params(info.params, scoped, "--set", f"{prefixes[kind]}.")
    _check_grid_size(config, tree_file, overrides, spec, registry)
    if config.planning_clock not in PLANNING_CLOCKS:
        raise BadInput("--planning-clock", None,
                       f"{config.planning_clock!r} is not one of {', '.join(PLANNING_CLOCKS)}")
    if config.out is not None:
        check_output(config.out, "--out", folder=True)
    if config.rerun is not None:
        check_rerun(config.rerun)
    return tree_file, overrides


def _check_grid_size(config: RunConfig, tree_file: Any, overrides: dict[str, dict[str, Any]], spec: Any,
                     registry: Any) -> None:
    """The voxel size (``--set resolution=``, else the tree's) is finite and positive, and a dense grid
    over the world's region at that size fits in memory: checked before the run starts, not as a
    MemoryError in it. A tree whose region PVS may be sparse (a ``pvs_layout`` of auto or sparse:
    hashed blocks, memory that follows what the rays reach) is not held to the dense grid's memory."""
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
    for node in tree_file.root.walk():
        if not node.behaviour:
            continue
        layout = next((p for p in registry.get("behaviour", node.behaviour).params if p.name == "pvs_layout"), None)
        if layout is not None and overrides.get(node.behaviour, {}).get(
                "pvs_layout", node.params.get("pvs_layout", layout.default)) != "dense":
            return
    check_grid(spec.region_min, spec.region_max, resolution, source, field_)


def _tree_strategy(tree_file: Any, overrides: dict[str, dict[str, Any]], registry: Any) -> tuple[str, str, str] | None:
    """The strategy a run of the tree uses without ``--strategy``: the ``strategy`` parameter of the first of its
    behaviours that declares one (from ``--set``, the tree file or its default), with where it was given (source,
    field); None if no behaviour declares one."""
    for node in tree_file.root.walk():
        if not node.behaviour:
            continue
        declared = {p.name: p for p in registry.get("behaviour", node.behaviour).params}
        if "strategy" not in declared:
            continue
        if overrides.get(node.behaviour, {}).get("strategy"):
            return str(overrides[node.behaviour]["strategy"]), "--set", f"{node.behaviour}.strategy"
        if node.params.get("strategy"):
            return str(node.params["strategy"]), str(tree_file.path), f"{node.behaviour}.params.strategy"
        return str(declared["strategy"].default), str(tree_file.path), f"{node.behaviour}.strategy (its default)"
    return None


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
        elif key in GLOBAL_SETTINGS:
            continue
        else:
            valid = sorted(in_tree) + ["sensor.*", "robot.*", "strategy.*", "planner.*", *GLOBAL_SETTINGS]
            raise BadInput("--set", key, f"unknown setting (valid prefixes: {', '.join(valid)})")
    for name, values in overrides.items():
        validate_params(registry.get("behaviour", name).params, values, "--set", f"{name}.")
    return overrides


def write_json_atomic(path: Path, data: Any, digits: int | None = 6) -> None:
    """Write JSON through a temporary file so an interrupt never leaves half a file.

    Run metrics keep 6 decimals; a comparison's results and summary keep every digit so
    they equal what is recomputed from ``results.csv``."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(jsonable(data, digits), indent=2, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)
