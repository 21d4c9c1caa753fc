"""Comparisons: the product of runs over worlds x strategies x planners x robots x seeds.

Every run is one isolated process (``python -m explore.runtime.compare --worker SPEC``) that calls
:func:`explore.runtime.run.execute` and writes its own run directory under ``DIR/runs/<run id>``.
Run ids are stable folder names built from the grid values, so re-running the same command
skips every run whose directory already holds a complete ``metrics.json`` (or a
``result.json`` written by the driver). A crash or a timeout is recorded with its reason
(status ``crashed`` / ``timeout``) and does not stop the others; such runs are tried again
on the next invocation. ``results.csv`` (one row per finished run, grid order) is rewritten
atomically after every finished run, so an interrupt loses nothing.

Runs get the same environment on every executor (``PYTHONHASHSEED=0``, ``threads`` BLAS /
OpenMP / numba threads each), so the same seeds give the same results locally and on Ray.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from explore.core import FINISHED, BadInput, brief

RESULTS_FILE = "results.csv"
GRID_FILE = "compare.json"
RUNS_DIR = "runs"
SPEC_FILE = "spec.json"
RESULT_FILE = "result.json"
ERROR_FILE = "error.json"
LOG_FILE = "run.log"
DEFAULT = "default"  # column value when the tree's / world's default is used

ID_COLUMNS = ("run_id", "world", "strategy", "planner", "robot", "seed", "status", "reason")
METRIC_COLUMNS = (
    "scans",
    "n_s",
    "coverage",
    "coverage_at_stop",
    "coverage_estimate",
    "path_length_m",
    "selection_s_mean",
    "collisions",
    "planning_success",
    "planning_time_s",
    "elapsed_s",
    "wall_s",
    "coverage_per_scan",
    "coverage_estimate_per_scan",
    "selection_s_per_scan",
)
# metrics that measure time (differ between machines); everything else is deterministic
TIMING_COLUMNS = ("elapsed_s", "wall_s", "selection_s_mean", "selection_s_per_scan", "planning_time_s")
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def slug(value: str | None) -> str:
    """A folder-safe form of a grid value (``ig_quality/bs_hr`` -> ``ig_quality+bs_hr``)."""
    if value is None or value == "":
        return DEFAULT
    text = Path(value).stem if value.endswith((".yaml", ".yml")) else value
    return re.sub(r"[^A-Za-z0-9._+-]", "-", text.replace("/", "+"))


@dataclass(frozen=True)
class RunSpec:
    """One run of a comparison: everything its isolated process needs."""

    run_id: str
    tree: str
    world: str
    strategy: str | None
    planner: str | None
    robot: str | None
    seed: int
    out_dir: str
    max_scans: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    timeout: float = 1800.0
    plugins: tuple[str, ...] = ()
    threads: int = 1

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["plugins"] = list(self.plugins)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunSpec:
        return cls(**{**data, "plugins": tuple(data.get("plugins", ()))})

    @property
    def path(self) -> Path:
        return Path(self.out_dir)

    def grid_values(self) -> dict[str, Any]:
        return {
            "run_id": self.run_id,
            "world": slug(self.world),
            "strategy": self.strategy or DEFAULT,
            "planner": self.planner or DEFAULT,
            "robot": self.robot or DEFAULT,
            "seed": self.seed,
        }


@dataclass
class Grid:
    """The experiment grid of ``explore compare``; :meth:`runs` is its cartesian product."""

    tree: str
    worlds: list[str]
    strategies: list[str | None] = field(default_factory=lambda: [None])
    planners: list[str | None] = field(default_factory=lambda: [None])
    robots: list[str | None] = field(default_factory=lambda: [None])
    seeds: list[int] = field(default_factory=lambda: [0])
    max_scans: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    timeout: float = 1800.0
    plugins: list[str] = field(default_factory=list)
    threads: int = 1

    # fields that change what a run computes: a results folder holds one value of each
    DEFINING = ("tree", "max_scans", "settings", "plugins", "threads")

    def runs(self, out: Path) -> list[RunSpec]:
        """Every run, in grid order (world, strategy, planner, robot, seed)."""
        specs: list[RunSpec] = []
        seen: dict[str, tuple] = {}
        product = itertools.product(self.worlds, self.strategies, self.planners, self.robots, self.seeds)
        for world, strategy, planner, robot, seed in product:
            key = (world, strategy, planner, robot, seed)
            run_id = "__".join([slug(world), slug(strategy), slug(planner), slug(robot), f"seed{seed:03d}"])
            if run_id in seen:
                raise BadInput("explore compare", None, f"runs {seen[run_id]} and {key} share the id {run_id}")
            seen[run_id] = key
            specs.append(
                RunSpec(
                    run_id=run_id, tree=self.tree, world=world, strategy=strategy, planner=planner,
                    robot=robot, seed=seed, out_dir=str((out / RUNS_DIR / run_id).resolve()),
                    max_scans=self.max_scans, settings=dict(self.settings), timeout=self.timeout,
                    plugins=tuple(self.plugins), threads=self.threads,
                )
            )
        return specs

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# -- run directories ---------------------------------------------------------------------------
def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def complete_metrics(run_dir: Path) -> dict[str, Any] | None:
    """The run's metrics if its ``metrics.json`` is complete (parses, has a final status)."""
    metrics = _read_json(run_dir / "metrics.json")
    if isinstance(metrics, dict) and metrics.get("status") in FINISHED:
        return metrics
    return None


def finished_row(spec: RunSpec) -> dict[str, Any] | None:
    """The results row of an already finished run (None: the run must be executed)."""
    row = _read_json(spec.path / RESULT_FILE)
    if isinstance(row, dict) and row.get("status") in FINISHED and row.get("run_id") == spec.run_id:
        return row
    metrics = complete_metrics(spec.path)
    return row_from_metrics(spec, metrics, math.nan) if metrics is not None else None


def _flat(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def row_from_metrics(spec: RunSpec, metrics: dict[str, Any], wall_s: float) -> dict[str, Any]:
    """One results row: the grid values, the status and every metric of the run."""
    row: dict[str, Any] = spec.grid_values()
    row["status"] = metrics.get("status", "failure")
    row["reason"] = metrics.get("reason", "")
    for key, value in metrics.items():
        if key in ID_COLUMNS or key == "settings":
            continue
        row[key] = _flat(value)
    row["wall_s"] = None if not math.isfinite(wall_s) else round(wall_s, 3)
    return row


def failed_row(spec: RunSpec, status: str, reason: str, wall_s: float) -> dict[str, Any]:
    """The row of a run that crashed or timed out (no metrics)."""
    row = spec.grid_values()
    row.update(status=status, reason=reason, wall_s=round(wall_s, 3))
    return row


def _prepare_run_dir(spec: RunSpec) -> None:
    """Start from an empty directory (an unfinished run's leftovers are removed)."""
    if spec.path.exists() and complete_metrics(spec.path) is None:
        shutil.rmtree(spec.path)
    spec.path.mkdir(parents=True, exist_ok=True)
    (spec.path / SPEC_FILE).write_text(json.dumps(spec.to_dict(), indent=2) + "\n", encoding="utf-8")


def worker_env(spec: RunSpec) -> dict[str, str]:
    """The environment of a run's process: identical on every executor."""
    env = dict(os.environ)
    for var in _THREAD_VARS:
        env[var] = str(spec.threads)
    env["PYTHONHASHSEED"] = "0"
    env["MPLBACKEND"] = "Agg"
    env.setdefault("PYTHONWARNINGS", "ignore")
    env["EXPLORE_COMPARE_PARENT"] = str(os.getpid())
    return env


class IsolatedRun:
    """A run in its own process group; :meth:`poll` returns its row once it has ended."""

    def __init__(self, spec: RunSpec) -> None:
        self.spec = spec
        _prepare_run_dir(spec)
        self._log = open(spec.path / LOG_FILE, "wb")  # noqa: SIM115 - closed in _end
        self.started = time.monotonic()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "explore.runtime.compare", "--worker", str(spec.path / SPEC_FILE)],
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=worker_env(spec),
            start_new_session=True,  # Ctrl-C goes to the driver, which ends the runs itself
        )

    def elapsed(self) -> float:
        return time.monotonic() - self.started

    def poll(self) -> dict[str, Any] | None:
        code = self.process.poll()
        if code is None:
            if self.elapsed() > self.spec.timeout:
                self.kill()
                reason = f"timed out after {self.spec.timeout:g} s"
                return self._end(failed_row(self.spec, "timeout", reason, self.elapsed()))
            return None
        metrics = complete_metrics(self.spec.path)
        if metrics is not None:
            return self._end(row_from_metrics(self.spec, metrics, self.elapsed()))
        return self._end(failed_row(self.spec, "crashed", self._crash_reason(code), self.elapsed()))

    def wait(self, interval: float = 0.2) -> dict[str, Any]:
        while True:
            row = self.poll()
            if row is not None:
                return row
            time.sleep(interval)

    def kill(self) -> None:
        """End the run's whole process group (the run and anything it started)."""
        if self.process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait()

    def _crash_reason(self, code: int) -> str:
        error = _read_json(self.spec.path / ERROR_FILE)
        if isinstance(error, dict) and error.get("reason"):
            return str(error["reason"])
        if code < 0:
            try:
                what = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                what = f"killed by signal {-code}"
        else:
            what = f"exit code {code}"
        self._log.flush()
        lines = [ln for ln in (self.spec.path / LOG_FILE).read_text(errors="replace").splitlines() if ln.strip()]
        return f"{what}: {lines[-1].strip()[:200]}" if lines else what

    def _end(self, row: dict[str, Any]) -> dict[str, Any]:
        self._log.close()
        if row["status"] not in FINISHED:
            _write_json_atomic(self.spec.path / ERROR_FILE, {"status": row["status"], "reason": row["reason"]})
        return row


def run_isolated(spec_data: dict[str, Any]) -> dict[str, Any]:
    """Run one spec in its own process and wait for its row (used by remote executors)."""
    return IsolatedRun(RunSpec.from_dict(spec_data)).wait()


# -- the worker process ------------------------------------------------------------------------
def load_plugin_objects(specs: Iterable[str]) -> list[tuple[str, object]]:
    """Plugin objects named ``FILE.py:ATTR`` or ``MODULE:ATTR`` (for ``Registry.load(extra=)``)."""
    import importlib
    import importlib.util

    objects: list[tuple[str, object]] = []
    for item in specs:
        where, _, attr = item.rpartition(":")
        if not where or not attr:
            raise BadInput("--plugin", item, "expected FILE.py:OBJECT or MODULE:OBJECT")
        try:
            if where.endswith(".py"):
                path = Path(where)
                if not path.is_file():
                    raise BadInput("--plugin", item, "no such file")
                name = f"explore_extra_{re.sub(r'[^A-Za-z0-9_]', '_', path.stem)}"
                module = sys.modules.get(name)
                if module is None:
                    spec = importlib.util.spec_from_file_location(name, path)
                    module = importlib.util.module_from_spec(spec)
                    sys.modules[name] = module
                    spec.loader.exec_module(module)
            else:
                module = importlib.import_module(where)
            objects.append((f"extra:{item}", getattr(module, attr)))
        except BadInput:
            raise
        except Exception as error:  # noqa: BLE001 - reported as bad input
            raise BadInput("--plugin", item, f"cannot load: {type(error).__name__}: {error}") from None
    return objects


def make_registry(plugins: Sequence[str] = ()) -> Any:
    """The registry a run sees: entry-point plugins plus ``plugins`` (FILE.py:OBJ / MODULE:OBJ)."""
    from explore.runtime.registry import Registry

    blocked = [b for b in os.environ.get("EXPLORE_BLOCK_PLUGINS", "").split(",") if b]
    return Registry.load(extra=load_plugin_objects(plugins), blocked=blocked)


def _die_with_parent() -> None:
    """Linux: end this run when the process that started it dies (even by SIGKILL)."""
    parent = int(os.environ.get("EXPLORE_COMPARE_PARENT", "0") or 0)
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if parent and os.getppid() != parent:
        os._exit(137)


def worker_main(argv: Sequence[str]) -> int:
    """Entry of a run's process: read the spec, execute the run, record an error if any."""
    import traceback

    _die_with_parent()
    spec = RunSpec.from_dict(json.loads(Path(argv[0]).read_text(encoding="utf-8")))
    from explore.runtime.run import RunConfig, execute

    try:
        registry = make_registry(spec.plugins)
        config = RunConfig(
            tree=spec.tree, world=spec.world, strategy=spec.strategy, planner=spec.planner, robot=spec.robot,
            seed=spec.seed, max_scans=spec.max_scans, settings=dict(spec.settings), out=spec.path,
        )
        result = execute(config, registry)
    except BadInput as error:
        _write_json_atomic(spec.path / ERROR_FILE, {"status": "crashed", "reason": f"bad input: {error.line()}"})
        return 2
    except BaseException as error:  # noqa: BLE001 - any crash is recorded with its reason
        traceback.print_exc()
        _write_json_atomic(spec.path / ERROR_FILE, {"status": "crashed", "reason": f"{type(error).__name__}: {error}"})
        return 3
    print(f"{result.status}: {result.reason}")  # noqa: T201 - goes to run.log
    return 0


# -- results.csv ---------------------------------------------------------------------------------
def _write_json_atomic(path: Path, data: Any) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if not math.isfinite(value) else repr(value)
    if isinstance(value, list | dict | tuple):
        return json.dumps(value, separators=(",", ":"), default=str)
    return str(value)


def result_columns(rows: Iterable[dict[str, Any]]) -> list[str]:
    """Column order: grid values and status, the documented metrics, then the rest sorted."""
    present: set[str] = set()
    for row in rows:
        present.update(row)
    known = [c for c in METRIC_COLUMNS if c in present]
    rest = sorted(present - set(ID_COLUMNS) - set(known))
    return [*ID_COLUMNS, *known, *rest]


def write_results(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Write ``results.csv`` atomically (temporary file + rename)."""
    buffer = io.StringIO()
    columns = result_columns(rows)
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(buffer.getvalue(), encoding="utf-8")
    os.replace(tmp, path)


def _parse_cell(text: str) -> Any:
    if text == "":
        return None
    if text[0] in "[{":
        try:
            return json.loads(text)
        except ValueError:
            return text
    if text in ("true", "false"):
        return text == "true"
    try:
        number = float(text)
    except ValueError:
        return text
    return int(number) if re.fullmatch(r"-?\d+", text) else number


def read_results(path: Path) -> list[dict[str, Any]]:
    """Rows of a ``results.csv`` with numbers, booleans and JSON lists parsed (BadInput if it is not one)."""
    from explore.core import read_text

    text = read_text(path)
    try:
        rows = list(csv.DictReader(io.StringIO(text, newline=""), strict=True))
    except csv.Error as error:
        raise BadInput(str(path), None, f"not a results table: {error}") from None
    if rows and ("run_id" not in rows[0] or "status" not in rows[0]):
        raise BadInput(str(path), None, "not a results table of explore compare (no run_id and status columns)")
    return [{str(k): _parse_cell(v if isinstance(v, str) else "") for k, v in row.items()} for row in rows]


# -- the driver ----------------------------------------------------------------------------------
OnDone = Callable[[RunSpec, dict[str, Any]], None]


def check_grid_file(out: Path, grid: Grid) -> None:
    """Refuse to mix runs with different defining settings in one results folder."""
    previous = _read_json(out / GRID_FILE)
    if not isinstance(previous, dict):
        return
    current = json.loads(json.dumps(grid.to_dict()))
    for key in Grid.DEFINING:
        if key in previous and previous[key] != current[key]:
            raise BadInput(
                str(out), key,
                f"holds a comparison with {key}={brief(previous[key])}, not {brief(current[key])}; "
                "choose another --out",
            )


class _Progress:
    """A rich progress bar with ETA (terminal) or one line per finished run (log)."""

    def __init__(self, total: int, done: int, console: Any) -> None:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.console = console
        self.total = total
        self.count = done
        self.started = time.monotonic()
        self.new = 0
        self.bar = None
        if console is not None and console.is_terminal:
            self.bar = Progress(
                TextColumn("[bold]compare"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=False,
            )
            self.task = self.bar.add_task("runs", total=total, completed=done)
            self.bar.start()

    def eta(self) -> str:
        if not self.new:
            return "?"
        left = (time.monotonic() - self.started) / self.new * (self.total - self.count)
        return f"{left:.0f} s"

    def advance(self, row: dict[str, Any]) -> None:
        self.count += 1
        self.new += 1
        if self.console is not None:
            extra = "" if row.get("scans") is None else f" scans={row['scans']}"
            if row.get("coverage") is not None:
                extra += f" coverage={row['coverage']:.3f}"
            line = f"[{self.count}/{self.total}] {row['run_id']}: {row['status']}{extra}"
            if row["status"] not in FINISHED:
                line += f" ({row['reason']})"
            self.console.print(f"{line}  ETA {self.eta()}", markup=False, highlight=False, soft_wrap=True)
        if self.bar is not None:
            self.bar.advance(self.task)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def compare(grid: Grid, out: Path, executor: Any, console: Any = None, report: bool = True) -> list[dict[str, Any]]:
    """Run every missing run of ``grid`` with ``executor``; write results.csv and the report."""
    out.mkdir(parents=True, exist_ok=True)
    check_grid_file(out, grid)
    _write_json_atomic(out / GRID_FILE, grid.to_dict())
    specs = grid.runs(out)
    rows: dict[str, dict[str, Any]] = {}
    for spec in specs:
        row = finished_row(spec)
        if row is not None:
            rows[spec.run_id] = row
    order = [s.run_id for s in specs]
    results = out / RESULTS_FILE

    def ordered() -> list[dict[str, Any]]:
        return [rows[i] for i in order if i in rows]

    write_results(results, ordered())
    todo = [s for s in specs if s.run_id not in rows]
    if console is not None:
        console.print(
            f"{len(specs)} runs: {len(rows)} already finished, {len(todo)} to run", highlight=False, soft_wrap=True
        )
    progress = _Progress(len(specs), len(rows), console)

    def on_done(spec: RunSpec, row: dict[str, Any]) -> None:
        rows[spec.run_id] = row
        if row["status"] in FINISHED:
            spec.path.mkdir(parents=True, exist_ok=True)
            _write_json_atomic(spec.path / RESULT_FILE, row)
        write_results(results, ordered())
        progress.advance(row)

    try:
        if todo:
            executor.run(todo, on_done)
    finally:
        progress.close()
    final = ordered()
    if report:
        from explore.runtime.report import write_report

        write_report(out, final)
    return final


def run_local(specs: Sequence[RunSpec], on_done: OnDone, jobs: int, poll: float = 0.1) -> None:
    """Run ``specs`` as isolated processes, ``jobs`` at a time; ends them all on an interrupt."""
    pending = list(specs)
    active: list[IsolatedRun] = []
    try:
        while pending or active:
            while pending and len(active) < jobs:
                active.append(IsolatedRun(pending.pop(0)))
            for run in list(active):
                row = run.poll()
                if row is not None:
                    active.remove(run)
                    on_done(run.spec, row)
            time.sleep(poll)
    finally:
        for run in active:
            run.kill()
            run._log.close()


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--worker":
        code = worker_main(sys.argv[2:])
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.stderr.write("usage: python -m explore.runtime.compare --worker SPEC.json (use `explore compare`)\n")
    raise SystemExit(2)
