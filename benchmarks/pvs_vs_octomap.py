"""PVS vs OctoMap: integration speed, cell agreement, and entropy ray-casting throughput.

Integrates the same simulated scans (several views of pybullet_data objects: the bunny with
the laser striper, the tabletop scene with the depth camera) into our PVS and into OctoMap
(PyPI ``pyoctomap``) in one run, at 5 mm and 1 cm, and prints a table:

- beams (points) per second for OctoMap, the PVS in OctoMap-compatible mode and the PVS with
  the sensor-noise model, and the ratio PVS(octomap mode) / OctoMap. Both maps traverse the
  same voxels: the PVS grid covers the region of interest *and* every sensor origin.
  "PVS roi" is the normal use, a grid over the region of interest only.
- cell-state agreement (free / occupied / unknown) between OctoMap and the OctoMap-compatible
  PVS over the cells either map has observed, and the largest log-odds difference there.
- entropy (IG, IROS 2012 Eq. 1-2) ray casting over candidate views, in voxel visits per
  second: per candidate with visited marking (thesis Eq. 4.32; serial, deterministic; the
  headline ``ig_voxel_visits_per_s``), per candidate without it ("plain", Eq. 2), and all
  candidates' beams in one parallel batch.

OctoMap is used at its fastest: ``insertPointCloud(..., lazy_eval=True)`` per cloud (one per
sensor frame), ``updateInnerOccupancy()`` once per scan, hit 0.7 / miss 0.4, clamping
0.12-0.97; beams without a return are passed as max-range rays (points beyond ``max_range``).

Usage: ``python benchmarks/pvs_vs_octomap.py [--json] [--views N] [--repeats R] [--quick]``.
With ``--json`` exactly one JSON object goes to stdout (everything else to stderr).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from collections.abc import Iterator

import numpy as np

from explore.mapping import PVS
from explore.runtime import Registry
from explore.sim import Scan, Simulation, target_for

SCENES = (
    # world, distance of the views (m), resolutions
    ("bunny_pedestal", 0.325, (0.005, 0.01)),
    ("tabletop", 0.85, (0.01,)),
)


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
    """Send everything written to file descriptor 1 (also from C code) to stderr."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def view_eyes(center: np.ndarray, distance: float, views: int) -> np.ndarray:
    """Eyes on a ring around ``center``, alternating 25 and 45 degrees of elevation."""
    azimuth = np.linspace(0.0, 2.0 * np.pi, views, endpoint=False) + 0.3
    elevation = np.deg2rad(np.where(np.arange(views) % 2 == 0, 25.0, 45.0))
    offset = np.column_stack(
        [np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation), np.sin(elevation)]
    )
    return center + distance * offset


def acquire(world: str, distance: float, views: int) -> tuple[Simulation, list[Scan], np.ndarray]:
    sim = Simulation(world, Registry.load())
    center = sim.spec.region_center
    rng = np.random.default_rng(0)
    eyes = view_eyes(center, distance, views)
    scans = [sim.sensor.acquire(sim, target_for(sim.sensor, eye, center, 0.25), rng) for eye in eyes]
    return sim, scans, center


def octomap_clouds(scan: Scan) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per sensor frame: (points, origin) as OctoMap gets them; no-returns as max-range rays."""
    ends = scan.origins + scan.directions * np.where(
        scan.hits, scan.ranges, 2.0 * scan.max_range if scan.no_return_clears else np.nan
    )[:, None]
    keep = np.all(np.isfinite(ends), axis=1)
    clouds = []
    for frame in np.unique(scan.frame_of_beam):
        mask = keep & (scan.frame_of_beam == frame)
        if mask.any():
            origin = scan.sensor_poses[frame, :3, 3].astype(np.float64)
            clouds.append((np.ascontiguousarray(ends[mask], dtype=np.float64), origin))
    return clouds


def run_octomap(scans: list[Scan], resolution: float, lazy: bool = True):  # -> pyoctomap.OcTree, seconds
    """OctoMap over the scans, one cloud per sensor frame; ``lazy``: inner nodes updated once per scan (its
    fastest), else after every cloud, pruning equal children as it goes (its smallest tree)."""
    import pyoctomap

    clouds = [octomap_clouds(scan) for scan in scans]
    tree = pyoctomap.OcTree(resolution)
    tree.setProbHit(0.7)
    tree.setProbMiss(0.4)
    tree.setClampingThresMin(0.12)
    tree.setClampingThresMax(0.97)
    start = time.perf_counter()
    for scan, per_frame in zip(scans, clouds, strict=True):
        for points, origin in per_frame:
            tree.insertPointCloud(points, origin, max_range=float(scan.max_range), lazy_eval=lazy)
        if lazy:
            tree.updateInnerOccupancy()
    return tree, time.perf_counter() - start


def run_pvs(scans: list[Scan], lo: np.ndarray, hi: np.ndarray, resolution: float, mode: str) -> tuple[PVS, float]:
    pvs = PVS(lo, hi, resolution, mode=mode)
    start = time.perf_counter()
    for scan in scans:
        pvs.integrate(scan)
    return pvs, time.perf_counter() - start


def best_of(repeats: int, fn, *args):  # noqa: ANN001, ANN202
    best = None
    for _ in range(repeats):
        result = fn(*args)
        if best is None or result[1] < best[1]:
            best = result
    return best


def octomap_grid(tree, pvs: PVS) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """OctoMap leaves inside the PVS box as (state grid -1/0/1, log-odds grid)."""
    states = np.full(pvs.shape, -1, dtype=np.int8)
    values = np.full(pvs.shape, np.nan, dtype=np.float32)
    res = pvs.resolution
    eps = 0.25 * res
    lo = pvs.min_corner + eps
    hi = pvs.max_corner - eps
    shape = np.asarray(pvs.shape)
    for leaf in tree.begin_leafs_bbx(lo, hi):
        coord = np.asarray(leaf.getCoordinate())
        size = leaf.getSize()
        node = tree.search(coord)
        if node is None:
            continue
        value = node.getLogOdds()
        first = np.floor((coord - 0.5 * size) / res + 0.5).astype(np.int64) - pvs.lattice
        count = max(1, int(round(size / res)))
        a = np.clip(first, 0, shape)
        b = np.clip(first + count, 0, shape)
        if np.any(b <= a):
            continue
        window = (slice(a[0], b[0]), slice(a[1], b[1]), slice(a[2], b[2]))
        values[window] = value
        states[window] = 1 if value > tree.getOccupancyThresLog() else 0
    return states, values


def agreement(tree, pvs: PVS) -> dict[str, float]:  # noqa: ANN001
    """Cell-state agreement over cells either map observed, and log-odds differences."""
    theirs, their_values = octomap_grid(tree, pvs)
    ours = pvs.states("octomap")  # 0 free, 1 unknown, 2 occupied
    ours = np.where(ours == 1, -1, np.where(ours == 2, 1, 0)).astype(np.int8)
    observed = (theirs >= 0) | (ours >= 0)
    same = (theirs == ours) & observed
    both = (theirs >= 0) & (ours >= 0)
    diff = np.abs(their_values[both] - pvs.log_odds[both])
    return {
        "agreement": float(same.sum() / max(observed.sum(), 1)),
        "cells_observed": int(observed.sum()),
        "cells_disagree": int(observed.sum() - same.sum()),
        "max_abs_log_odds_diff": float(diff.max()) if len(diff) else 0.0,
        "octomap_occupied": int((theirs == 1).sum()),
        "pvs_occupied": int((ours == 1).sum()),
    }


def ig_throughput(
    sim: Simulation, pvs: PVS, center: np.ndarray, distance: float, candidates: int, repeats: int
) -> dict:
    """Entropy ray casting over candidate views: voxel visits per second."""
    sensor = sim.sensor
    eyes = view_eyes(center, distance, candidates)
    eyes[:, 2] += 0.02 * np.sin(np.arange(candidates))  # not the integrated views
    beams = []
    for eye in eyes:
        target = target_for(sensor, eye, center, 0.25)
        stride = (4, 4) if sensor.geometry == "line" else (16, 1)
        origins, directions, _ = sensor.beams(target, beam_stride=stride[0], frame_stride=stride[1])
        beams.append((origins, directions))
    for visited in (True, False):  # warm-up: load the cached kernels, start the thread pool
        pvs.entropy_gain(*beams[0], sensor.max_range, visited=visited)
    all_origins = np.vstack([o for o, _ in beams])
    all_directions = np.vstack([d for _, d in beams])
    pvs.cast(all_origins[:100], all_directions[:100], sensor.max_range, parallel=True)
    out = {}
    for key in ("visited", "plain", "parallel"):
        best = np.inf
        for _ in range(repeats):
            visits = 0
            start = time.perf_counter()
            if key == "parallel":  # every candidate's beams in one batch on all cores
                visits = int(pvs.cast(all_origins, all_directions, sensor.max_range, parallel=True).visits.sum())
            else:
                for origins, directions in beams:
                    _, stats = pvs.entropy_gain(
                        origins, directions, sensor.max_range, visited=key == "visited", return_stats=True
                    )
                    visits += stats["visits"]
            best = min(best, time.perf_counter() - start)
        out[f"ig_{key}_visits_per_s"] = visits / best
        out[f"ig_{key}_visits"] = visits
    out["ig_candidates"] = candidates
    out["ig_beams_per_candidate"] = int(np.mean([len(o) for o, _ in beams]))
    return out


def benchmark(views: int, repeats: int, candidates: int, quick: bool) -> dict:
    rows = []
    scenes = SCENES[:1] if quick else SCENES
    for world, distance, resolutions in scenes:
        sim, scans, center = acquire(world, distance, views)
        try:
            beams = sum(len(s) for s in scans)
            origins = np.vstack([s.sensor_poses[:, :3, 3] for s in scans])
            for resolution in resolutions:
                region_lo, region_hi = sim.spec.region_min, sim.spec.region_max
                lo = np.minimum(region_lo, origins.min(axis=0)) - 2 * resolution
                hi = np.maximum(region_hi, origins.max(axis=0)) + 2 * resolution
                run_pvs(scans[:1], lo, hi, resolution, "octomap")  # warm-up (cached compile)
                run_pvs(scans[:1], lo, hi, resolution, "sensor_model")
                tree, t_octomap = best_of(repeats, run_octomap, scans, resolution)
                pvs_om, t_om = best_of(repeats, run_pvs, scans, lo, hi, resolution, "octomap")
                _, t_sm = best_of(repeats, run_pvs, scans, lo, hi, resolution, "sensor_model")
                roi_lo, roi_hi = region_lo - 2 * resolution, region_hi + 2 * resolution
                pvs_roi, t_roi = best_of(repeats, run_pvs, scans, roi_lo, roi_hi, resolution, "sensor_model")
                row = {
                    "world": world,
                    "sensor": sim.sensor.name,
                    "resolution": resolution,
                    "views": views,
                    "beams": beams,
                    "grid_shape": list(pvs_om.shape),
                    "octomap_points_per_s": beams / t_octomap,
                    "pvs_octomap_mode_points_per_s": beams / t_om,
                    "pvs_sensor_model_points_per_s": beams / t_sm,
                    "pvs_roi_sensor_model_points_per_s": beams / t_roi,
                    "speed_ratio": t_octomap / t_om,
                    "speed_ratio_sensor_model": t_octomap / t_sm,
                }
                row.update(agreement(tree, pvs_om))
                row.update(ig_throughput(sim, pvs_roi, center, distance, candidates, repeats))
                rows.append(row)
                print(f"done {world} {resolution * 1000:.0f} mm", file=sys.stderr)
        finally:
            sim.close()
    return {
        "speed_ratio": min(r["speed_ratio"] for r in rows),
        "agreement": min(r["agreement"] for r in rows),
        "ig_voxel_visits_per_s": min(r["ig_visited_visits_per_s"] for r in rows),
        "ig_plain_voxel_visits_per_s": min(r["ig_plain_visits_per_s"] for r in rows),
        "ig_parallel_voxel_visits_per_s": min(r["ig_parallel_visits_per_s"] for r in rows),
        "targets": {"speed_ratio": 2.0, "agreement": 0.98, "ig_voxel_visits_per_s": 20e6},
        "cpu_count": os.cpu_count(),
        "scenes": rows,
    }


def table(result: dict) -> str:
    head = (
        f"{'scene':<30} {'res':>6} {'beams':>8} {'OctoMap':>9} {'PVS om':>9} {'PVS sm':>9} "
        f"{'PVS roi':>9} {'ratio':>6} {'agree':>7} {'max|dl|':>8} {'IG vis/s':>9} {'IG plain':>9} "
        f"{'IG par/s':>9}"
    )
    lines = ["points (beams) per second; ratio = PVS octomap-mode / OctoMap", head, "-" * len(head)]
    for r in result["scenes"]:
        lines.append(
            f"{r['world'] + ' ' + r['sensor']:<30} {r['resolution'] * 1000:>4.0f}mm {r['beams']:>8} "
            f"{r['octomap_points_per_s'] / 1e6:>8.2f}M {r['pvs_octomap_mode_points_per_s'] / 1e6:>8.2f}M "
            f"{r['pvs_sensor_model_points_per_s'] / 1e6:>8.2f}M {r['pvs_roi_sensor_model_points_per_s'] / 1e6:>8.2f}M "
            f"{r['speed_ratio']:>6.1f} {100 * r['agreement']:>6.2f}% {r['max_abs_log_odds_diff']:>8.1e} "
            f"{r['ig_visited_visits_per_s'] / 1e6:>8.1f}M {r['ig_plain_visits_per_s'] / 1e6:>8.1f}M "
            f"{r['ig_parallel_visits_per_s'] / 1e6:>8.1f}M"
        )
    lines.append(
        f"headline (worst scene): speed_ratio {result['speed_ratio']:.2f} (target 2), agreement "
        f"{100 * result['agreement']:.2f}% (target 98%), IG {result['ig_voxel_visits_per_s'] / 1e6:.1f} M "
        "visits/s (target 20 M)"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--views", type=int, default=6, help="views per scene")
    parser.add_argument("--repeats", type=int, default=3, help="timing repeats (best is kept)")
    parser.add_argument("--candidates", type=int, default=24, help="candidate views for the IG timing")
    parser.add_argument("--quick", action="store_true", help="only the first scene")
    args = parser.parse_args(argv)
    if args.json:
        with stdout_to_stderr():
            result = benchmark(args.views, args.repeats, args.candidates, args.quick)
        sys.stdout.write(json.dumps(result) + "\n")
    else:
        result = benchmark(args.views, args.repeats, args.candidates, args.quick)
        print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
