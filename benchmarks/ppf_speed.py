"""PPF voting speed: the compiled per-reference voting against the dense accumulator, in one run.

Drost et al. 2010 vote, for every scene reference point, in an accumulator of (model point,
alpha bin) cells. Written as one NumPy array over all references (every scene pair, then a
``bincount`` over n_ref x n_m x n_alpha cells and an ``argmax``), a small model matched in a large
cluster (a 4 cm cube in the points of a teddy and a shape sorter merged from six views, the case
that made the scene runs slow) allocates hundreds of megabytes. The library
(:mod:`explore.perception.ppf_votes`) pairs each reference only with the points within the
model's diameter (a k-d tree) and votes in one reused accumulator. Both give the same cell and
votes per reference (checked here); the table gives both times and their ratio.

    python benchmarks/ppf_speed.py [--json] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from explore.core import look_at
from explore.perception import DepthProcessing, ObjectDatabase
from explore.perception.model_data import oriented
from explore.perception.ppf import _align_to_x, _alpha, _pair_features
from explore.perception.verification import o3d_cloud
from explore.runtime import Registry
from explore.sim import Simulation

WORLD = """name: ppf_speed
environment:
  - {name: table, source: table/table.urdf, position: [0.0, 0.0, 0.3125]}
objects:
  - {name: teddy, source: teddy_vhacd.urdf, size: 0.16, rpy_deg: [90, 0, 150], position: [-0.1, 0.0], on_top_of: table,
     known: true}
  - {name: sorter, source: toys/shape_sorter.obj, size: 0.10, position: [0.12, 0.0], on_top_of: table, known: true}
  - {name: cube, source: cube_small.urdf, size: 0.04, position: [0.3, 0.2], on_top_of: table, known: true}
region: {min: [-0.45, -0.32, 0.625], max: [0.45, 0.32, 0.90]}
robot: {plugin: free_flyer}
sensor: {plugin: depth_camera, params: {profile: kinect, width: 320, height: 240, min_range: 0.3, max_range: 2.0}}
overview: {eye: [0.0, -0.9, 1.35], target: [0.0, 0.0, 0.65]}
"""


def _best(fn, args: tuple, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        out = fn(*args)
        times.append(time.perf_counter() - started)
    return min(times), out


def dense_votes(recognizer, sp, sn, refs, table):
    """The reference: every scene pair, one (n_ref, n_m * n_alpha) vote array, ``argmax``."""
    na = recognizer.alpha_bins
    n_ref, n = len(refs), len(sp)
    ri, pi = np.repeat(np.arange(n_ref), n), np.tile(np.arange(n), n_ref)
    valid = refs[ri] != pi
    ri, pi = ri[valid], pi[valid]
    dist, f1, f2, f3 = _pair_features(sp[refs[ri]], sn[refs[ri]], sp[pi], sn[pi])
    close = dist <= table.diameter
    ri, pi = ri[close], pi[close]
    keys = recognizer._keys(dist[close], f1[close], f2[close], f3[close], table.distance_step)
    rot_s, trans_s = _align_to_x(sp[refs], sn[refs])
    alpha_s = _alpha(rot_s, trans_s, ri, sp[pi])
    lo, hi = np.searchsorted(table.keys, keys, "left"), np.searchsorted(table.keys, keys, "right")
    counts = hi - lo
    total = int(counts.sum())
    pair = np.repeat(np.arange(len(keys)), counts)
    entry = np.repeat(lo, counts) + (np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts))
    alpha = table.alphas[entry] - alpha_s[pair]
    abin = np.floor((alpha + math.pi) / (2.0 * math.pi) * na).astype(np.int64) % na
    n_m = len(table.cloud.points)
    flat = (ri[pair].astype(np.int64) * n_m + table.refs[entry]) * na + abin
    acc = np.bincount(flat, minlength=n_ref * n_m * na).reshape(n_ref, n_m * na)
    best = acc.argmax(axis=1)
    return best, acc[np.arange(n_ref), best], acc.nbytes, total, len(ri)


def measure(repeats: int) -> list[dict]:
    registry = Registry.load()
    folder = Path(tempfile.mkdtemp())
    world = folder / "world.yaml"
    world.write_text(WORLD)
    with Simulation(str(world), registry) as sim:
        ov = sim.spec.overview
        rng = np.random.default_rng(0)
        scans = []
        for turn in np.radians([0, 60, 120, 180, 240, 300]):  # six views around the teddy and the sorter
            c, s = math.cos(turn), math.sin(turn)
            eye = np.array([c * ov[0] - s * ov[1], s * ov[0] + c * ov[1], ov[2]])
            scans.append(DepthProcessing().apply(sim.sensor.acquire(sim, look_at(eye, ov[3:]), rng)))
        clusters = registry.create("segmenter", "plane_clusters", {"scale": "table"}).segment(scans).clusters
        with ObjectDatabase.open(folder / "objects.db") as db:
            db.seed_from_world(sim)
            models = list(db.models())
    cluster = max(clusters, key=lambda c: len(c.points))
    recognizer = registry.create("recognizer", "ppf")
    rows = []
    for model in models:
        table = recognizer.table(model)
        sp, sn = oriented(o3d_cloud(cluster.points, cluster.normals).voxel_down_sample(table.distance_step))
        refs = np.sort(np.random.default_rng(0).choice(len(sp), max(1, round(0.25 * len(sp))), replace=False))
        args = (sp, sn, refs, table)
        recognizer.vote(*args)  # compile
        ours, (best, votes, _, _, _) = _best(recognizer.vote, args, repeats)
        dense, (d_best, d_votes, nbytes, matches, pairs) = _best(dense_votes, (recognizer, *args), repeats)
        rows.append({
            "model": model.name, "model_points": len(table.cloud.points), "scene_points": len(sp),
            "references": len(refs), "pairs_within_diameter": pairs, "matches": matches,
            "dense_accumulator_mb": nbytes / 2**20, "ours_ms": 1e3 * ours, "dense_ms": 1e3 * dense,
            "speedup": dense / ours,
            "same_votes": bool(np.array_equal(best, d_best) and np.array_equal(votes, d_votes)),
        })
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rows = measure(args.repeats)
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print("| model | model points | scene points | references | pairs | matches | dense array | ours | dense "
          "| speed-up | same votes |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for r in rows:
        print(f"| {r['model']} | {r['model_points']} | {r['scene_points']} | {r['references']} | "
              f"{r['pairs_within_diameter']:,} | {r['matches']:,} | {r['dense_accumulator_mb']:.0f} MB | "
              f"{r['ours_ms']:.0f} ms | {r['dense_ms']:.0f} ms | {r['speedup']:.1f}x | {r['same_votes']} |")


if __name__ == "__main__":
    main()
