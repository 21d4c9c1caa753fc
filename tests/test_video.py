"""Run videos (explore.runtime.video): one frame per scan, read back; a video changes no result."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explore.runtime import RunConfig, execute, run_differences
from explore.runtime.video import BANNER, PANEL, read_frames

EXPLORE = Path(sys.executable).parent / "explore"


@pytest.mark.parametrize("tree, world, extra", [
    ("model_object", "bunny_pedestal", {}),  # the laser striper: a sweep's stripes as the image
    ("scene_exploration", "scene_small", {"start_scene.max_views": 4}),  # the depth camera
])
def test_a_run_video_has_a_frame_per_scan_and_changes_no_result(registry, tmp_path, tree, world, extra) -> None:
    runs = {}
    for video in (True, False):
        settings = {**extra, **({"start_scene.db": str(tmp_path / f"db{video}" / "o.db")} if "scene" in tree else {})}
        config = RunConfig(tree=tree, world=world, seed=2, max_scans=3 if tree == "model_object" else None,
                           settings=settings, out=tmp_path / f"video{video}", video=video)
        runs[video] = execute(config, registry)
    assert not (runs[False].out_dir / "run.mp4").exists()
    differences = run_differences(runs[True].out_dir, runs[False].out_dir)
    assert not differences, "\n".join(differences[:20])
    frames = read_frames(runs[True].out_dir / "run.mp4")
    metrics = runs[True].metrics
    assert len(frames) == metrics.get("views", metrics.get("scans")) >= 2
    assert frames[0].shape == (PANEL[1] + BANNER, 3 * PANEL[0], 3)
    for frame in frames:
        panels = [frame[BANNER:, i * PANEL[0]:(i + 1) * PANEL[0]] for i in range(3)]
        assert all(p.std() > 10 for p in panels[:1]) and panels[2].std() > 10  # depth image and PVS slice drawn
    first, last = (f[BANNER:].astype(float) for f in (frames[0], frames[-1]))
    assert np.abs(first - last).mean() > 2 and (last[:, PANEL[0]:2 * PANEL[0]] < 240).sum() > 1000  # a model drawn


@pytest.mark.slow
def test_compare_puts_one_video_per_method_in_the_report(tmp_path) -> None:
    out = tmp_path / "cmp"
    args = [str(EXPLORE), "compare", "--tree", "model_object", "--worlds", "bunny_pedestal",
            "--strategies", "ig_quality/bs_hr,random/sphere", "--seeds", "2", "--max-scans", "2", "--jobs", "2",
            "--video", "--out", str(out)]
    done = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    videos = sorted(p.relative_to(out).as_posix() for p in (out / "runs").glob("*/run.mp4"))
    assert len(videos) == 2 and all("seed000" in v for v in videos)  # one per method: its first seed
    for video in videos:
        assert len(read_frames(out / video)) == 2
    summary, page = (out / "summary.md").read_text(), (out / "report.html").read_text()
    assert all(v in summary and f"src='{v}'" in page for v in videos)
