"""A comparison's grid: the product of worlds x strategies x planners x robots x seeds, each run a RunSpec with a
stable id (a folder name built from its grid values, so a repeated command finds the runs it already has), and the
file names of a results folder."""

from __future__ import annotations

import itertools
import json
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from explore.core import FINISHED, BadInput

RESULTS_FILE = "results.csv"


GRID_FILE = "compare.json"


RUNS_DIR = "runs"


SPEC_FILE = "spec.json"


RESULT_FILE = "result.json"


ERROR_FILE = "error.json"


LOG_FILE = "run.log"


DEFAULT = "default"  # column value when the tree's / world's default is used


ID_COLUMNS = ("run_id", "world", "strategy", "planner", "robot", "variant", "seed", "status", "reason")


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


# how a grid's run can end: on its own (metrics.json), or killed by the driver (no metrics)
ROW_STATUSES = (*FINISHED, "crashed", "timeout")
# the one-number metrics (a number or empty) and the per-scan lists (a JSON list of numbers)
NUMBER_COLUMNS = tuple(c for c in METRIC_COLUMNS if not c.endswith("_per_scan"))
LIST_COLUMNS = tuple(c for c in METRIC_COLUMNS if c.endswith("_per_scan"))

# metrics that measure time (differ between machines); everything else is deterministic
TIMING_COLUMNS = ("elapsed_s", "wall_s", "selection_s_mean", "selection_s_per_scan", "planning_time_s")


THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


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
    video: bool = False  # also write run.mp4 (changes no result)
    variant: str | None = None  # the name of the grid's settings variant (its settings are in ``settings``)

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
            "variant": self.variant or DEFAULT,
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
    videos: bool = False  # one video per method: its first seed's run.mp4 (changes no result)
    # named sets of settings compared as one more dimension (``--variant "DU: start_nbvs.noise=false"``), each
    # applied over ``settings``; none: one unnamed variant, and run ids without a variant part
    variants: dict[str, dict[str, Any]] = field(default_factory=dict)

    MAX_RUNS = 100_000  # ~35 days of 30 s runs on 2 cores: a larger grid is a typo, not a plan
    # fields that change what a run computes: a results folder holds one value of each
    DEFINING = ("tree", "max_scans", "settings", "plugins", "threads", "variants")

    def runs(self, out: Path) -> list[RunSpec]:
        """Every run, in grid order (world, strategy, planner, robot, variant, seed)."""
        specs: list[RunSpec] = []
        seen: dict[str, tuple] = {}
        variants: list[str | None] = list(self.variants) or [None]
        product = itertools.product(self.worlds, self.strategies, self.planners, self.robots, variants, self.seeds)
        for world, strategy, planner, robot, variant, seed in product:
            key = (world, strategy, planner, robot, variant, seed)
            named = [slug(variant)] if variant is not None else []
            run_id = "__".join([slug(world), slug(strategy), slug(planner), slug(robot), *named, f"seed{seed:03d}"])
            if run_id in seen:
                raise BadInput("explore compare", None, f"runs {seen[run_id]} and {key} share the id {run_id}")
            seen[run_id] = key
            specs.append(
                RunSpec(
                    run_id=run_id, tree=self.tree, world=world, strategy=strategy, planner=planner,
                    robot=robot, seed=seed, out_dir=str((out / RUNS_DIR / run_id).resolve()),
                    max_scans=self.max_scans, settings={**self.settings, **self.variants.get(variant or "", {})},
                    timeout=self.timeout, plugins=tuple(self.plugins), threads=self.threads,
                    video=self.videos and seed == self.seeds[0], variant=variant,
                )
            )
        return specs

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def read_grid_file(out: Path) -> dict[str, Any] | None:
    """The grid a results folder was made with (``compare.json``, written atomically), None if it has none; a
    file that is not a JSON object is someone else's edit: refused, and left as it is."""
    path = out / GRID_FILE
    if not path.is_file():
        return None
    try:
        grid = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise BadInput(str(path), None, f"not a comparison's grid file ({error}); restore it or choose another "
                       "--out (the file was left untouched)") from None
    if not isinstance(grid, dict):
        raise BadInput(str(path), None, f"not a comparison's grid file (a JSON {type(grid).__name__}, expected an "
                       "object); restore it or choose another --out (the file was left untouched)")
    return grid


OnDone = Callable[[RunSpec, dict[str, Any]], None]  # what an executor calls as each run ends
