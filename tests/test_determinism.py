"""Same seed, same run: every shipped tree on one of its worlds, run twice at the same time, once with
one thread and once with every thread beside a busy process, gives the same metrics.json and the
same trace apart from wall times, tick numbers and paths (explore.runtime.rundiff)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from explore.runtime import list_trees, run_differences

EXPLORE = Path(sys.executable).parent / "explore"
SMALL_NBVS = ["--set", "start_nbvs.n_samples=800", "--set", "start_nbvs.top=6", "--set", "strategy.k=10"]
# tree -> (world, extra arguments): small budgets, every tree of trees/
RUNS = {
    "model_object": ("bunny_pedestal", ["--max-scans", "4"]),
    "nbvs_mobile": ("cluttered", ["--strategy", "vasquez/eu", "--max-scans", "3", *SMALL_NBVS]),
    "scene_exploration": ("scene_small", []),
    "table_patrol": ("scene_small_mobile", []),
}


def test_every_shipped_tree_has_a_determinism_run() -> None:
    assert {p.stem for p in list_trees() if p.parent.name == "trees"} <= set(RUNS)


@pytest.mark.slow
@pytest.mark.parametrize("tree", sorted(RUNS))
def test_same_seed_same_run_at_any_thread_count_and_load(tree: str, tmp_path: Path) -> None:
    world, extra = RUNS[tree]
    runs = {}
    for threads in ("1", "0"):
        out = tmp_path / f"threads{threads}"
        db = tmp_path / f"db{threads}" / "objects.db"  # each run starts from the same (empty) database
        scene = ["--set", f"start_scene.db={db}"] if tree in ("scene_exploration", "table_patrol") else []
        args = [str(EXPLORE), "run", tree, "--world", world, "--seed", "3", "--threads", threads, "-q",
                "--out", str(out), *extra, *scene]
        runs[threads] = (out, subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        for out, process in runs.values():
            text, _ = process.communicate(timeout=600)
            assert (out / "metrics.json").exists(), text[-2000:]
    finally:
        busy.kill()
        busy.wait()
    differences = run_differences(runs["1"][0], runs["0"][0])
    assert not differences, "\n".join(differences[:20])


def test_the_command_line_sets_one_blas_thread_before_numpy_loads() -> None:
    from explore.core import THREAD_VARIABLES

    code = ("import os, sys; import explore_cli; print('numpy' in sys.modules, "
            f"[os.environ.get(n) for n in {list(THREAD_VARIABLES)!r}])")
    env = {k: v for k, v in __import__("os").environ.items() if k not in THREAD_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.stdout.strip() == f"False {['1'] * len(THREAD_VARIABLES)}", out.stderr
