"""Every run of a comparison in its own process (python -m explore.runtime.compare --worker SPEC): the same
environment on every executor (PYTHONHASHSEED=0, the given threads), a timeout, a crash or a killed driver recorded
with its reason; the local process pool; plugin objects given as FILE.py:OBJ."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from explore.core import FINISHED, BadInput
from explore.runtime.compare_grid import (
    ERROR_FILE,
    LOG_FILE,
    SPEC_FILE,
    THREAD_VARS,
    OnDone,
    RunSpec,
)
from explore.runtime.compare_results import (
    complete_metrics,
    failed_row,
    read_json,
    row_from_metrics,
)
from explore.runtime.registry import Registry
from explore.runtime.run import RunConfig, execute
from explore.runtime.run_inputs import write_json_atomic


def _prepare_run_dir(spec: RunSpec) -> None:
    """Start from an empty directory (an unfinished run's leftovers are removed)."""
    if spec.path.exists() and complete_metrics(spec.path) is None:
        shutil.rmtree(spec.path)
    spec.path.mkdir(parents=True, exist_ok=True)
    (spec.path / SPEC_FILE).write_text(json.dumps(spec.to_dict(), indent=2) + "\n", encoding="utf-8")


def worker_env(spec: RunSpec) -> dict[str, str]:
    """The environment of a run's process: identical on every executor, its object database its own."""
    env = dict(os.environ)
    for var in THREAD_VARS:
        env[var] = str(spec.threads)
    env["PYTHONHASHSEED"] = "0"
    env["MPLBACKEND"] = "Agg"
    env.setdefault("PYTHONWARNINGS", "ignore")
    env["EXPLORE_COMPARE_PARENT"] = str(os.getpid())
    # a run's own object database (a scene tree's default): runs that shared the user's learned each other's
    # models in whatever order they ran, raced to seed the same known objects, and filled the user's database
    env["EXPLORE_DB"] = str(spec.path / "objects.db")
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
        error = read_json(self.spec.path / ERROR_FILE)
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
            write_json_atomic(self.spec.path / ERROR_FILE, {"status": row["status"], "reason": row["reason"]})
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
    try:
        registry = make_registry(spec.plugins)
        config = RunConfig(
            tree=spec.tree, world=spec.world, strategy=spec.strategy, planner=spec.planner, robot=spec.robot,
            seed=spec.seed, max_scans=spec.max_scans, settings=dict(spec.settings), out=spec.path, video=spec.video,
        )
        result = execute(config, registry)
    except BadInput as error:
        write_json_atomic(spec.path / ERROR_FILE, {"status": "crashed", "reason": f"bad input: {error.line()}"})
        return 2
    except BaseException as error:  # noqa: BLE001 - any crash is recorded with its reason
        traceback.print_exc()
        write_json_atomic(spec.path / ERROR_FILE, {"status": "crashed", "reason": f"{type(error).__name__}: {error}"})
        return 3
    print(f"{result.status}: {result.reason}")  # noqa: T201 - goes to run.log
    return 0


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
