"""Room-scale PVS vs OctoMap: the sparse PVS on a 5 x 5 x 2 m room at 5 mm, in one run.

A depth camera (Kinect-like, 320 x 240, 0.4-4.5 m) on the mast of a mobile base (1.3 m) takes
views from a tour of base positions through a room with two tables and objects from
``pybullet_data``. The same scans go into OctoMap (PyPI ``pyoctomap``, ``insertPointCloud`` with
lazy evaluation and one ``updateInnerOccupancy`` per scan, its fastest; and again without lazy
evaluation, so that it prunes equal children as it goes, its smallest probabilistic tree; hit 0.7 /
miss 0.4, clamping 0.12-0.97) and into our PVS:

- **sparse, OctoMap-compatible mode**: points per second, memory (blocks and hash table, the
  allocated capacity) and cell agreement with OctoMap: both maps are written as ``.bt`` files
  and read back (pruned leaves expanded to 5 mm voxels); agreement is the share of voxels either
  map observed that both call free or both occupied (maximum likelihood);
- **sparse, sensor-noise model** (the PVS's default): points per second, memory;
- **dense** (optional, ``--dense``): the same room as one flat grid, 400 M voxels;
- entropy ray casting (IG, IROS 2012 Eq. 1-2, with visited marking, thesis Eq. 4.32) on the sparse
  map over candidate views of the room, voxel visits per second.

OctoMap's speed is the faster of its two runs, its memory (its own ``memoryUsage()``) the smaller;
each runs in a child process so that its memory goes back to the system.

Usage: ``python benchmarks/pvs_room.py [--views N] [--resolution R] [--dense] [--json]``.
With ``--json`` exactly one JSON object goes to stdout (everything else to stderr).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import resource
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from pvs_vs_octomap import run_octomap, stdout_to_stderr

from explore.mapping import PVS
from explore.mapping.octomap_bt import DEPTH, expand_leaves, read_bt_leaves
from explore.mapping.sparse_pvs import SparsePVS
from explore.runtime import Registry
from explore.sim import Scan, Simulation, target_for

ROOM = """\
name: room5x5
description: A 5 x 5 x 2 m room with two tables and five objects (benchmarks/pvs_room.py).
environment:
  - {name: floor, box: [5.0, 5.0, 0.02], position: [0.0, 0.0, -0.01]}
  - {name: wall_north, box: [5.0, 0.1, 2.0], position: [0.0, 2.45, 1.0]}
  - {name: wall_south, box: [5.0, 0.1, 2.0], position: [0.0, -2.45, 1.0]}
  - {name: wall_east, box: [0.1, 4.8, 2.0], position: [2.45, 0.0, 1.0]}
  - {name: wall_west, box: [0.1, 4.8, 2.0], position: [-2.45, 0.0, 1.0]}
  - {name: table_a, box: [1.0, 0.6, 0.72], position: [-1.3, 1.4, 0.36]}
  - {name: table_b, box: [0.8, 0.8, 0.72], position: [1.4, -1.2, 0.36]}
objects:
  - {name: bunny, source: bunny.obj, size: 0.15, rpy_deg: [90, 0, 0], position: [-1.5, 1.35], on_top_of: table_a}
  - {name: mug, source: objects/mug.urdf, size: 0.11, position: [-1.05, 1.5], on_top_of: table_a}
  - {name: duck, source: duck.obj, size: 0.12, rpy_deg: [90, 0, 45], position: [1.25, -1.1], on_top_of: table_b}
  - {name: teddy, source: teddy_vhacd.urdf, size: 0.15, rpy_deg: [90, 0, 0], position: [1.55, -1.35],
     on_top_of: table_b}
  - {name: sorter, source: toys/shape_sorter.obj, size: 0.10, position: [1.55, -0.95], on_top_of: table_b}
region:
  min: [-2.5, -2.5, 0.0]
  max: [2.5, 2.5, 2.0]
robot:
  plugin: mobile_base
  base: [0.0, 0.0, 0.0, 0.0]
sensor:
  plugin: depth_camera
  params: {profile: kinect, width: 320, height: 240, min_range: 0.4, max_range: 4.5}
"""

MAST = 1.3  # camera height on the base's mast (m)


def tour(views: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(eye, look-at point) per view: base positions on a loop through the room, the camera looking
    outwards past the room's centre and down at table height."""
    angle = np.linspace(0.0, 2.0 * np.pi, views, endpoint=False)
    radius = np.where(np.arange(views) % 2 == 0, 0.6, 1.3)
    eyes = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(views, MAST)])
    look = angle + np.pi * 0.75
    targets = eyes + np.column_stack([np.cos(look), np.sin(look), np.full(views, -0.35)])
    return list(zip(eyes, targets, strict=True))


def acquire(world: Path, views: int) -> tuple[list[Scan], list[tuple[np.ndarray, np.ndarray]]]:
    with Simulation(str(world), Registry.load()) as sim:
        rng = np.random.default_rng(0)
        poses = tour(views)
        return [sim.sensor.acquire(sim, target_for(sim.sensor, eye, at), rng) for eye, at in poses], poses


def octomap_to_bt(scans: list[Scan], resolution: float, path: Path, lazy: bool) -> tuple[float, int, int]:
    """OctoMap's seconds, bytes (``memoryUsage`` of the probabilistic tree) and leaves; with ``lazy`` its
    maximum-likelihood tree is written to ``path``."""
    tree, seconds = run_octomap(scans, resolution, lazy)
    result = seconds, int(tree.memoryUsage()), int(tree.getNumLeafNodes())
    if lazy:
        tree.writeBinary(str(path))  # turns the tree to maximum likelihood and prunes it
    return result


def integrate(pvs: PVS, scans: list[Scan]) -> float:
    start = time.perf_counter()
    for scan in scans:
        pvs.integrate(scan)
    return time.perf_counter() - start


def packed(keys: np.ndarray) -> np.ndarray:
    return (keys[:, 0] << 42) | (keys[:, 1] << 21) | keys[:, 2]


def agreement(ours: Path, theirs: Path, slab: int = 64) -> dict[str, float]:
    """Maximum-likelihood agreement of two ``.bt`` files over the voxels either observed, compared in slabs of
    ``slab`` voxels along x (a room at 5 mm has hundreds of millions of observed voxels)."""
    leaves = [read_bt_leaves(ours)[:3], read_bt_leaves(theirs)[:3]]
    spans = [(prefix[:, 0] << (DEPTH - depth), (prefix[:, 0] + 1) << (DEPTH - depth)) for depth, prefix, _ in leaves]
    lo = min(int(first.min()) for first, _ in spans)
    hi = max(int(end.max()) for _, end in spans)
    union = same = only_ours = only_theirs = occ_ours = occ_theirs = 0
    for x0 in range(lo, hi, slab):
        sides = []
        for (depth, prefix, state), (first, end) in zip(leaves, spans, strict=True):
            pick = (end > x0) & (first < x0 + slab)
            keys, occupied = expand_leaves(depth[pick], prefix[pick], state[pick])
            inside = (keys[:, 0] >= x0) & (keys[:, 0] < x0 + slab)
            key = packed(keys[inside])
            order = np.argsort(key)
            sides.append((key[order], occupied[inside][order]))
        (a, occ_a), (b, occ_b) = sides
        common, ia, ib = np.intersect1d(a, b, assume_unique=True, return_indices=True)
        union += len(a) + len(b) - len(common)
        same += int(np.count_nonzero(occ_a[ia] == occ_b[ib]))
        only_ours += len(a) - len(common)
        only_theirs += len(b) - len(common)
        occ_ours += int(occ_a.sum())
        occ_theirs += int(occ_b.sum())
    return {"agreement": same / max(union, 1), "voxels_observed": union, "voxels_disagree": union - same,
            "observed_only_by_pvs": only_ours, "observed_only_by_octomap": only_theirs,
            "octomap_occupied": occ_theirs, "pvs_occupied": occ_ours}


def ig_throughput(pvs: PVS, scans: list[Scan], poses: list, candidates: int) -> dict[str, float]:
    """Entropy casting over candidate views (the tour's eyes turned by half a view): voxel visits/s."""
    scan = scans[0]
    stride = max(1, len(scan) // 4800)  # about 4800 beams per candidate, as the NBVS utilities cast
    beams = []
    for i in range(candidates):
        eye, at = poses[i % len(poses)]
        turn = np.deg2rad(25.0 * (i + 1))
        rot = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0.0, 0.0, 1.0]])
        directions = scans[i % len(scans)].directions[::stride] @ rot.T
        beams.append((np.broadcast_to(eye, directions.shape).copy(), directions))
    pvs.entropy_gain(*beams[0], scan.max_range)  # warm-up
    visits = 0
    start = time.perf_counter()
    for origins, directions in beams:
        visits += pvs.entropy_gain(origins, directions, scan.max_range, return_stats=True)[1]["visits"]
    visited = visits / (time.perf_counter() - start)
    origins = np.vstack([o for o, _ in beams])
    directions = np.vstack([d for _, d in beams])
    pvs.cast(origins[:100], directions[:100], scan.max_range, parallel=True)
    start = time.perf_counter()
    total = int(pvs.cast(origins, directions, scan.max_range, parallel=True).visits.sum())
    parallel = total / (time.perf_counter() - start)
    return {"ig_visited_visits_per_s": visited, "ig_parallel_visits_per_s": parallel,
            "ig_candidates": candidates, "ig_beams_per_candidate": len(beams[0][0])}


def free_space_test(pvs: PVS, poses: int = 200, seed: int = 0) -> dict[str, float]:
    """The planners' free-space test (``probability_below(points, 0.75)``, a block bitmap before the hash
    table) against a lookup of every point (``probability(points) < 0.75``): 17 115 points of a robot-sized
    box (0.6 x 0.6 x 1.2 m, as the mobile manipulator's surface samples) at random base poses in the room."""
    rng = np.random.default_rng(seed)
    robot = rng.uniform([-0.3, -0.3, 0.0], [0.3, 0.3, 1.2], (17_115, 3))
    sets = [robot + (*rng.uniform(-2.2, 2.2, 2), 0.0) for _ in range(poses)]
    same = all(np.array_equal(pvs.probability_below(s, 0.75), pvs.probability(s) < 0.75) for s in sets[:20])
    start = time.perf_counter()
    for points in sets:
        _ = pvs.probability(points) < 0.75
    every = (time.perf_counter() - start) / poses
    start = time.perf_counter()
    for points in sets:
        pvs.probability_below(points, 0.75)
    bitmap = (time.perf_counter() - start) / poses
    return {"free_test_every_point_ms": 1e3 * every, "free_test_bitmap_ms": 1e3 * bitmap,
            "free_test_ratio": every / bitmap, "free_test_same": same}


def benchmark(views: int, resolution: float, dense: bool, candidates: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        world = Path(tmp) / "room5x5.yaml"
        world.write_text(ROOM)
        scans, poses = acquire(world, views)
        beams = sum(len(s) for s in scans)
        lo, hi = np.array([-2.6, -2.6, -0.1]), np.array([2.6, 2.6, 2.1])  # the room and 10 cm around it
        warm = SparsePVS(lo, hi, resolution, mode="octomap")
        integrate(warm, scans[:1])  # load the cached kernels
        integrate(SparsePVS(lo, hi, resolution), scans[:1])
        print("OctoMap ...", file=sys.stderr)
        octomap = {}
        for lazy in (True, False):  # lazy: fastest; not lazy: pruned as it goes, its smallest probabilistic tree
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:  # memory goes back
                octomap[lazy] = pool.submit(octomap_to_bt, scans, resolution, Path(tmp) / "octomap.bt", lazy).result()
        t_octomap = min(octomap[True][0], octomap[False][0])
        octomap_bytes = min(octomap[True][1], octomap[False][1])
        leaves = octomap[False][2]
        print("sparse PVS ...", file=sys.stderr)
        om = SparsePVS(lo, hi, resolution, mode="octomap")
        t_om = integrate(om, scans)
        om.save_octomap(Path(tmp) / "pvs.bt")
        row = {"views": views, "beams": beams, "resolution": resolution, "room": [5.0, 5.0, 2.0],
               "octomap_points_per_s": beams / t_octomap, "octomap_bytes": octomap_bytes, "octomap_leaves": leaves,
               "octomap_lazy": {"seconds": octomap[True][0], "bytes": octomap[True][1]},
               "octomap_pruning": {"seconds": octomap[False][0], "bytes": octomap[False][1]},
               "sparse_om_points_per_s": beams / t_om, "sparse_om_bytes": om.nbytes, "sparse_om_blocks": om.blocks}
        row.update(agreement(Path(tmp) / "pvs.bt", Path(tmp) / "octomap.bt"))
        del om
        sm = SparsePVS(lo, hi, resolution)
        t_sm = integrate(sm, scans)
        row.update({"sparse_sm_points_per_s": beams / t_sm, "sparse_sm_bytes": sm.nbytes,
                    "sparse_sm_blocks": sm.blocks})
        row.update(ig_throughput(sm, scans, poses, candidates))
        row.update(free_space_test(sm))
        del sm
        if dense:
            print("dense PVS ...", file=sys.stderr)
            start = time.perf_counter()
            grid = PVS(lo, hi, resolution)
            t_alloc = time.perf_counter() - start
            t_dense = integrate(grid, scans)
            row.update({"dense_points_per_s": beams / (t_alloc + t_dense),
                        "dense_bytes": int(grid.log_odds.nbytes + grid._mark.nbytes)})
            del grid
    row["speed_ratio"] = row["sparse_om_points_per_s"] / row["octomap_points_per_s"]
    row["speed_ratio_sensor_model"] = row["sparse_sm_points_per_s"] / row["octomap_points_per_s"]
    row["memory_ratio"] = row["sparse_om_bytes"] / row["octomap_bytes"]
    row["memory_ratio_sensor_model"] = row["sparse_sm_bytes"] / row["octomap_bytes"]
    row["peak_rss_bytes"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    row["octomap_peak_rss_bytes"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    row["targets"] = {"speed_ratio": 5.0, "agreement": 0.98, "memory_ratio": 2.0}
    row["cpu_count"] = os.cpu_count()
    return row


def table(r: dict) -> str:
    mb = 1.0 / 2**20
    lines = [
        f"room 5 x 5 x 2 m at {r['resolution'] * 1e3:g} mm, {r['views']} depth-camera views, {r['beams']} points",
        f"{'map':<28} {'points/s':>10} {'ratio':>6} {'memory':>10} {'ratio':>6}",
        f"{'OctoMap (pyoctomap)':<28} {r['octomap_points_per_s']:>10,.0f} {1.0:>6.1f} "
        f"{r['octomap_bytes'] * mb:>8.0f}MB {1.0:>6.2f}",
        f"{'sparse PVS, OctoMap mode':<28} {r['sparse_om_points_per_s']:>10,.0f} {r['speed_ratio']:>6.1f} "
        f"{r['sparse_om_bytes'] * mb:>8.0f}MB {r['memory_ratio']:>6.2f}",
        f"{'sparse PVS, sensor model':<28} {r['sparse_sm_points_per_s']:>10,.0f} "
        f"{r['speed_ratio_sensor_model']:>6.1f} {r['sparse_sm_bytes'] * mb:>8.0f}MB "
        f"{r['memory_ratio_sensor_model']:>6.2f}",
    ]
    if "dense_points_per_s" in r:
        lines.append(f"{'dense PVS, sensor model':<28} {r['dense_points_per_s']:>10,.0f} "
                     f"{r['dense_points_per_s'] / r['octomap_points_per_s']:>6.1f} {r['dense_bytes'] * mb:>8.0f}MB "
                     f"{r['dense_bytes'] / r['octomap_bytes']:>6.2f}")
    lines += [
        f"agreement with OctoMap: {100 * r['agreement']:.2f} % of {r['voxels_observed']} observed voxels "
        f"({r['voxels_disagree']} differ)",
        f"entropy casting on the sparse map: {r['ig_visited_visits_per_s'] / 1e6:.1f} M voxel visits/s with visited "
        f"marking, {r['ig_parallel_visits_per_s'] / 1e6:.1f} M/s parallel",
        f"planners' free-space test of 17 115 robot points: {r['free_test_bitmap_ms']:.2f} ms per pose with the "
        f"block bitmap, {r['free_test_every_point_ms']:.2f} ms looking up every point "
        f"({r['free_test_ratio']:.1f}x, {'the same' if r['free_test_same'] else 'DIFFERENT'} answers)",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=6, help="depth-camera views")
    parser.add_argument("--resolution", type=float, default=0.005, help="voxel edge (m)")
    parser.add_argument("--candidates", type=int, default=12, help="candidate views for the IG timing")
    parser.add_argument("--dense", action="store_true", help="also the dense grid (400 M voxels at 5 mm)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.json:
        with stdout_to_stderr():
            result = benchmark(args.views, args.resolution, args.dense, args.candidates)
        sys.stdout.write(json.dumps(result) + "\n")
    else:
        print(table(benchmark(args.views, args.resolution, args.dense, args.candidates)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
