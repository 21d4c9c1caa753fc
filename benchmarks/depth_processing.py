"""Depth processing with and without: flying pixels, normals from the organised image, ICP.

For each sensor profile (the depth camera's ``ideal``, ``kinect`` and ``tof``, the striper's
``ideal`` and ``triangulation``) a few views of ``--world`` (default ``scene_small``, the
striper on ``bunny_pedestal``) measure:

* ``floating``: returns farther than 1 cm from every true surface (flying pixels, mixed depths)
  per 1000 returns, before and after ``explore.perception.filter_depth_scan``, and the share of
  returns the filter keeps;
* ``normal_deg``: median angle between the estimated and the true normals (ray-cast), for
  normals from the organised image (``organised_normals``, 5 x 5) and from a 1 cm neighbour
  search (``estimate_normals``), with the time each took and the share the organised one gives;
* ``icp_*_mm`` / ``icp_*_deg``: the true surface under the view's beams, moved by 5 mm / 2 degrees,
  registered back onto the measured points with point-to-plane ICP (``icp_local``, 1 cm radius)
  using each kind of normals of the measured points: the remaining pose error.

    .venv/bin/python benchmarks/depth_processing.py [--views 5] [--json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from typing import Any

import numpy as np

CASES = (("scene_small", "depth_camera", "ideal"), ("scene_small", "depth_camera", "kinect"),
         ("scene_small", "depth_camera", "tof"), ("bunny_pedestal", "laser_striper", "ideal"),
         ("bunny_pedestal", "laser_striper", "triangulation"))


def _targets(sim: Any, count: int, rng: np.random.Generator) -> list[Any]:
    """``count`` views of the region's centre from random directions above it."""
    from explore.core import look_at
    from explore.sim import target_for

    centre = 0.5 * (sim.spec.region_min + sim.spec.region_max)
    distance = sim.sensor.optimal_distance
    out = []
    for _ in range(count):
        azimuth, elevation = rng.uniform(-math.pi, math.pi), rng.uniform(0.5, 1.2)
        eye = centre + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                            math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
        out.append(target_for(sim.sensor, eye, centre) if sim.sensor.geometry == "line" else look_at(eye, centre))
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", a, b)), -1.0, 1.0)))


def measure(world: str, sensor: str, profile: str, views: int, registry: Any) -> dict[str, Any]:
    from scipy.spatial.transform import Rotation

    from explore.core import pose_error
    from explore.perception import estimate_normals, filter_depth_scan, icp_local, organised_normals
    from explore.sim import Simulation, load_world_spec

    spec = load_world_spec(world)
    spec = dataclasses.replace(spec, sensor=dataclasses.replace(
        spec.sensor, plugin=sensor, params={**spec.sensor.params, "profile": profile}))
    rng = np.random.default_rng(0)
    out: dict[str, list[float]] = {}
    with Simulation(spec, registry) as sim:
        for target in _targets(sim, views, rng):
            scan = sim.sensor.acquire(sim, target, rng)
            hits = scan.hits
            if hits.sum() < 500:
                continue
            points = scan.points()
            t_true, _, n_true = sim.raycaster.cast(scan.origins[hits], scan.directions[hits])
            distance = np.abs(scan.ranges[hits] - t_true)  # along the beam: an upper bound of the distance
            clean = filter_depth_scan(scan)
            t_clean, _, _ = sim.raycaster.cast(clean.origins[clean.hits], clean.directions[clean.hits])
            out.setdefault("floating_per_1000", []).append(1e3 * float(np.mean(distance > 0.01)))
            out.setdefault("floating_filtered_per_1000", []).append(
                1e3 * float(np.mean(np.abs(clean.ranges[clean.hits] - t_clean) > 0.01)))
            out.setdefault("kept_share", []).append(float(clean.hits.sum() / hits.sum()))
            true_surface = distance < 0.005
            started = time.perf_counter()
            organised = organised_normals(scan)
            out.setdefault("organised_ms", []).append(1e3 * (time.perf_counter() - started))
            started = time.perf_counter()
            knn = estimate_normals(points, 0.01, scan.origins[hits])
            out.setdefault("knn_ms", []).append(1e3 * (time.perf_counter() - started))
            given = np.isfinite(organised[:, 0])
            out.setdefault("organised_share", []).append(float(given.mean()))
            out.setdefault("organised_deg", []).append(float(np.median(_angle(organised[given & true_surface],
                                                                               n_true[given & true_surface]))))
            out.setdefault("knn_deg", []).append(float(np.median(_angle(knn[true_surface], n_true[true_surface]))))
            truth = (scan.origins[hits] + scan.directions[hits] * t_true[:, None])[true_surface]
            moved = np.eye(4)
            moved[:3, :3] = Rotation.from_rotvec(math.radians(2.0) * _unit(rng.normal(size=3))).as_matrix()
            moved[:3, 3] = 0.005 * _unit(rng.normal(size=3))
            source = truth @ moved[:3, :3].T + moved[:3, 3]
            for name, normals in (("organised", np.where(given[:, None], organised, knn)), ("knn", knn)):
                result = icp_local(source, n_true[true_surface] @ moved[:3, :3].T, points, normals, radius=0.01,
                                   iterations=30, method="point_to_plane")
                t_err, r_err = pose_error(result.transformation @ moved, np.eye(4))
                out.setdefault(f"icp_{name}_mm", []).append(1e3 * t_err)
                out.setdefault(f"icp_{name}_deg", []).append(math.degrees(r_err))
    views_used = len(out.get("kept_share", []))
    row: dict[str, Any] = {"world": world, "sensor": sensor, "profile": profile, "views": views_used}
    row.update({k: round(float(np.median(v)), 3) for k, v in out.items()})
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=5, help="views per sensor profile")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON only")
    args = parser.parse_args(argv)
    if args.views < 1:
        print("depth_processing.py: --views: must be at least 1", file=sys.stderr)
        return 2
    from explore.runtime import Registry

    registry = Registry.load()
    rows = [measure(world, sensor, profile, args.views, registry) for world, sensor, profile in CASES]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    columns = list(dict.fromkeys(k for r in rows for k in r))
    print(" | ".join(columns))
    for r in rows:
        print(" | ".join(str(r.get(c, "")) for c in columns))
    return 0


if __name__ == "__main__":
    sys.exit(main())
