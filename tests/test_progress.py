"""Long work shows progress: no shipped tree stays silent for 5 s (plain output, explore.runtime.progress)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from explore.runtime.progress import ProgressLines

SILENCE_S = 5.0
SMALL_NBVS = {"start_nbvs.n_samples": 800, "start_nbvs.top": 6, "strategy.k": 10}
# tree -> (world, max scans, strategy, settings): every shipped tree with a small budget
RUNS = {
    "model_object": ("bunny_pedestal", 4, None, {}),
    "nbvs_mobile": ("cluttered", 3, "vasquez/eu", SMALL_NBVS),
    "scene_exploration": ("scene_small", None, None, {}),
    "table_patrol": ("scene_small_mobile", None, None, {}),
}


class _Clock:
    """A run context stand-in for ProgressLines: elapsed time, a status line and an activity."""

    def __init__(self) -> None:
        self.now, self.status_line, self.activity = 0.0, "", ""

    def elapsed(self) -> float:
        return self.now


def _root(step: str) -> SimpleNamespace:
    tip = SimpleNamespace(name=step, status=SimpleNamespace(value="RUNNING"))
    return SimpleNamespace(tip=lambda: tip)


def test_progress_lines_report_changes_and_beat_while_a_step_works() -> None:
    lines, clock = ProgressLines(heartbeat_s=2.0), _Clock()
    shown = []
    for t in [i * 0.1 for i in range(61)]:  # one step working for 6 s, ticked every 0.1 s
        clock.now = t
        clock.activity = "expected utility: candidate 3 of 6" if t >= 3.0 else ""
        line = lines(_root("nbvs_score"), clock)
        if line is not None:
            shown.append(line)
    assert shown[0] == "[   2.0 s] nbvs_score: working (2 s in this step)"
    assert "[   3.0 s] nbvs_score: expected utility: candidate 3 of 6" in shown
    assert shown[-1].endswith("nbvs_score: expected utility: candidate 3 of 6 (5 s in this step)")
    assert lines.longest_silence(6.0) <= 2.0 + 1e-9
    blocked = ProgressLines()  # a step that holds the tick for 6 s: the silence is measured
    clock.now, clock.activity = 0.5, ""
    blocked(_root("slow_step"), clock)
    clock.now = 6.5
    blocked(_root("slow_step"), clock)
    assert blocked.longest_silence(6.5) == pytest.approx(6.5)


@pytest.mark.slow
@pytest.mark.parametrize("tree", sorted(RUNS))
def test_no_tree_step_is_silent_for_five_seconds(tree: str, registry, tmp_path: Path) -> None:
    """Every step either finishes, reports what it does, or beats every 2 s; a step that keeps the
    tick from running (work done in the tree's thread instead of the worker) fails this test."""
    from explore.runtime import RunConfig, execute

    world, scans, strategy, settings = RUNS[tree]
    if tree in ("scene_exploration", "table_patrol"):
        settings = {**settings, "start_scene.db": str(tmp_path / "objects.db")}
    lines = ProgressLines()
    ended = {}

    def on_tick(root, context) -> None:  # noqa: ANN001
        lines(root, context)
        ended["t"] = context.elapsed()

    config = RunConfig(tree=tree, world=world, strategy=strategy, seed=0, max_scans=scans, settings=settings,
                       out=tmp_path / "run", threads=1)
    execute(config, registry, on_tick)
    assert lines.times, "no progress line at all"
    assert lines.longest_silence(ended["t"]) < SILENCE_S, lines.times
