"""Simulated sensor throughput: beams per second of each sensor on a shipped world.

The reference in the same run is Open3D's bare ``RaycastingScene.cast_rays`` on the same
rays, so the ratio shows what our acquisition (beam generation, noise, bookkeeping) costs.
Target (issue A): >= 5 M beams/s for the depth camera on this 2-core machine.

    python benchmarks/sensor_speed.py [--json] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from explore.runtime import Registry
from explore.sim import Simulation, target_for


def _best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        times.append(time.perf_counter() - started)
    return min(times)


def measure(repeats: int) -> list[dict]:
    registry = Registry.load()
    rows = []
    cases = [
        ("tabletop", "depth_camera", {"width": 640, "height": 480}, ([0.0, -0.9, 1.35], [0.0, 0.0, 0.65])),
        ("bunny_pedestal", "laser_striper", {}, ([0.3, 0.0, 0.6], [0.0, 0.0, 0.56])),
    ]
    for world, sensor_name, params, (eye, at) in cases:
        with Simulation(world, registry) as sim:
            sensor = registry.create("sensor", sensor_name, params)
            target = target_for(sensor, np.array(eye), np.array(at), 0.3)
            rng = np.random.default_rng(0)
            scan = sensor.acquire(sim, target, rng)
            ours = _best(lambda s=sensor, t=target, r=rng: s.acquire(sim, t, r), repeats)
            origins, directions, _ = sensor.beams(target)
            bare = _best(lambda o=origins, d=directions: sim.raycaster.cast(o, d), repeats)
            rows.append(
                {
                    "world": world,
                    "sensor": sensor_name,
                    "beams": len(scan),
                    "returns": int(scan.hits.sum()),
                    "beams_per_s": len(scan) / ours,
                    "raycast_only_beams_per_s": len(scan) / bare,
                    "ratio_to_raycast": bare / ours,
                }
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the rows as one JSON object")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows = measure(args.repeats)
    if args.json:
        print(json.dumps({"rows": rows}))
        return
    print(f"{'world':16} {'sensor':14} {'beams':>8} {'M beams/s':>10} {'raycast M/s':>12} {'ratio':>6}")
    for r in rows:
        print(
            f"{r['world']:16} {r['sensor']:14} {r['beams']:8d} {r['beams_per_s'] / 1e6:10.2f} "
            f"{r['raycast_only_beams_per_s'] / 1e6:12.2f} {r['ratio_to_raycast']:6.2f}"
        )


if __name__ == "__main__":
    main()
