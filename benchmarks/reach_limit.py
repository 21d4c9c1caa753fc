"""The reach limit of a robot: the share of the observable surface that any reachable sensor pose sees.

c_a (thesis Sec. 4.7) counts the object's surface that some view of a dense view sphere around the
object sees; a robot whose arm or base cannot reach those views cannot cover it, whatever its
planner does. This script samples configurations uniformly within the robot's joint limits (a
mobile base within ``--base-radius`` of the object, any heading), keeps those that aim the sensor at
the object and are free of collision with the whole world (the object too) at the robot's planning
clearance, and counts an observable
surface sample as reachable-visible when, from one of them, it lies within the sensor's working
range, inside the cone of the sensor's beams (half angle: the widest beam's angle from their mean
direction; a striper's fan is assumed turnable about its axis, as the wrist turns it), at an
incidence below the sensor's limit, and nothing lies in between. The result is an upper bound of
the c_a the robot can reach: a run within a few points of it is limited by the robot, not the
planner (issue 20, item 5)::

    .venv/bin/python benchmarks/reach_limit.py --world workcell --samples 40000 \\
        --plot docs/images/reach_workcell.png
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np


def sensor_cone(sensor: Any) -> tuple[np.ndarray, float]:
    """Mean beam direction (sensor frame) and the widest beam's angle from it (rad)."""
    directions = np.asarray(sensor.local_directions(), dtype=float).reshape(-1, 3)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    axis = directions.mean(axis=0)
    axis /= np.linalg.norm(axis)
    return axis, float(np.arccos(np.clip(directions @ axis, -1.0, 1.0)).max())


def sample_configurations(robot: Any, centre: np.ndarray, n: int, base_radius: float,
                          rng: np.random.Generator) -> np.ndarray:
    """(n, dof) configurations uniform within the joint limits; a mobile base uniform over the disc
    of ``base_radius`` around ``centre`` (clipped to its limits) with any heading."""
    lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    q = lower + rng.random((n, robot.dof)) * (upper - lower)
    base = list(robot.base_dofs)
    if base:
        ix, iy, ith = base
        r, phi = base_radius * np.sqrt(rng.random(n)), rng.random(n) * 2.0 * math.pi
        q[:, ix] = np.clip(centre[0] + r * np.cos(phi), lower[ix], upper[ix])
        q[:, iy] = np.clip(centre[1] + r * np.sin(phi), lower[iy], upper[iy])
        q[:, ith] = rng.random(n) * 2.0 * math.pi - math.pi
    return q


def visible_from(pose: np.ndarray, points: np.ndarray, normals: np.ndarray, sensor: Any, raycaster: Any,
                 axis: np.ndarray, half_angle: float) -> np.ndarray:
    """(n,) True where a sample is seen from the sensor pose ``pose`` (world_T_sensor), see the module."""
    from explore.mapping import seen_from

    return seen_from(pose[:3, 3], points, normals, raycaster, sensor.min_range, sensor.max_range,
                     math.cos(math.radians(float(sensor.max_incidence_deg))),
                     cone=(pose[:3, :3] @ axis, math.cos(half_angle)))


class _Viewer:
    """Tests configurations one by one and keeps the union of what they see (see the module)."""

    def __init__(self, sim: Any) -> None:
        from explore.mapping import GroundTruthMetrics

        self.sim, self.robot, self.sensor = sim, sim.robot, sim.sensor
        self.gt = GroundTruthMetrics(sim)
        self.points, self.normals = self.gt.observable, self.gt.observable_normals
        lo, hi = (np.asarray(b, dtype=float) for b in sim.object_mesh().bounds)
        self.centre, self.radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
        self.axis, self.half_angle = sensor_cone(self.sensor)
        self.seen = np.zeros(len(self.points), dtype=bool)
        self.tried = self.aimed = self.free = self.useful = 0

    def aims(self, pose: np.ndarray) -> bool:
        """Whether the object's bounding sphere can be inside the sensor's cone and range at ``pose``."""
        to_centre = self.centre - pose[:3, 3]
        distance = max(float(np.linalg.norm(to_centre)), 1e-12)
        angle = math.acos(float(np.clip(to_centre @ (pose[:3, :3] @ self.axis) / distance, -1.0, 1.0)))
        return (distance - self.radius <= self.sensor.max_range and distance + self.radius >= self.sensor.min_range
                and angle <= self.half_angle + math.asin(min(1.0, self.radius / distance)))

    def test(self, q: np.ndarray) -> int:
        """Number of samples ``q`` sees that no configuration saw before (0 if it is not collision-free)."""
        self.tried += 1
        pose = self.robot.fk(q)  # cheap: first whether the object can be in view at all, then the collision test
        if not self.aims(pose):
            return 0
        self.aimed += 1
        if self.robot.in_collision(q, "true"):
            return 0
        self.free += 1
        new = visible_from(pose, self.points, self.normals, self.sensor, self.sim.raycaster, self.axis,
                           self.half_angle) & ~self.seen
        self.useful += int(new.any())
        self.seen |= new
        return int(new.sum())


def reach_limit(world: str, samples: int, rounds: int, seed: int, base_radius: float, log: Any) -> dict[str, Any]:
    """Uniform samples, then ``rounds`` rounds of samples around the configurations that saw something new
    (see the module); the union only grows, so each round's value is a lower bound of the limit."""
    from explore.runtime import Registry
    from explore.sim import Simulation

    rng = np.random.default_rng(seed)
    with Simulation(world, Registry.load()) as sim:
        viewer = _Viewer(sim)
        robot = viewer.robot
        lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
        spread = 0.05 * np.where(np.isfinite(upper - lower), upper - lower, 1.0)
        if robot.base_dofs:
            spread[list(robot.base_dofs)] = (0.05, 0.05, 0.1)
        history = []
        seeds = sample_configurations(robot, viewer.centre, samples, base_radius, rng)
        for round_ in range(rounds + 1):
            fruitful = [q for q in seeds if viewer.test(q) > 0]
            history.append({"round": round_, "configurations": viewer.tried, "reach_limit": float(viewer.seen.mean())})
            log(f"{world}: round {round_}: {viewer.tried} configurations, {viewer.aimed} aimed at the object, "
                f"{viewer.free} of them collision-free, {viewer.useful} saw something new; "
                f"reach limit {viewer.seen.mean():.1%}")
            if not fruitful:
                break
            per = max(1, samples // len(fruitful))
            seeds = np.clip(np.repeat(np.asarray(fruitful), per, axis=0)
                            + rng.normal(size=(per * len(fruitful), robot.dof)) * spread, lower, upper)
        return {"world": world, "robot": robot.name, "sensor": viewer.sensor.name, "samples": samples,
                "rounds": rounds, "seed": seed, "configurations": viewer.tried, "aimed_at_the_object": viewer.aimed,
                "collision_free": viewer.free, "seeing_something_new": viewer.useful,
                "observable_points": int(len(viewer.points)), "observable_share": viewer.gt.observable_share,
                "reach_limit": float(viewer.seen.mean()), "history": history,
                "cone_half_angle_deg": math.degrees(viewer.half_angle), "_points": viewer.points,
                "_seen": viewer.seen}


def plot(result: dict[str, Any], path: str) -> None:
    """The observable surface from two sides, reachable-visible samples green, the others red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points, seen = result["_points"], result["_seen"]
    fig = plt.figure(figsize=(10, 5))
    for i, azimuth in enumerate((30, 210)):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        for mask, colour, label in ((seen, "tab:green", "seen from a reachable pose"),
                                    (~seen, "tab:red", "seen from no reachable pose")):
            ax.scatter(*points[mask].T, s=0.5, c=colour, label=label)
        ax.view_init(elev=25, azim=azimuth)
        ax.set_axis_off()
        ax.set_box_aspect(np.ptp(points, axis=0) + 1e-9)
    fig.legend(*fig.axes[0].get_legend_handles_labels(), loc="lower center", markerscale=12, ncol=2)
    fig.suptitle(f"{result['world']} ({result['robot']}): reach limit {result['reach_limit']:.1%} of the observable "
                 f"surface ({result['configurations']} configurations tried)",
                 fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="workcell", help="world name or file (workcell)")
    parser.add_argument("--samples", type=int, default=40000, help="configurations per round (40000)")
    parser.add_argument("--rounds", type=int, default=4,
                        help="rounds of samples around the configurations that saw something new (4)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--base-radius", type=float, default=1.5,
                        help="a mobile base is sampled within this many metres of the object (1.5)")
    parser.add_argument("--plot", default=None, help="write the picture to this PNG")
    parser.add_argument("--json", action="store_true", help="print the result as JSON only")
    args = parser.parse_args(argv)
    if args.samples < 1:
        parser.error(f"--samples: must be at least 1, got {args.samples}")
    if args.rounds < 0:
        parser.error(f"--rounds: must be at least 0, got {args.rounds}")
    if not args.base_radius > 0.0:
        parser.error(f"--base-radius: must be positive, got {args.base_radius}")
    from explore.core import BadInput
    from explore.sim import find_world

    try:
        find_world(args.world)
    except BadInput as error:
        parser.error(f"--world: {error}")

    def log(line: str) -> None:
        if not args.json:
            print(line, file=sys.stderr, flush=True)

    result = reach_limit(args.world, args.samples, args.rounds, args.seed, args.base_radius, log)
    public = {k: v for k, v in result.items() if not k.startswith("_")}
    print(json.dumps(public, indent=1) if args.json else
          f"{public['world']}: reach limit {public['reach_limit']:.1%} of the observable surface "
          f"({public['observable_points']} samples, {public['observable_share']:.1%} of the whole surface); "
          f"of {public['configurations']} configurations {public['aimed_at_the_object']} aim at the object, "
          f"{public['collision_free']} of them collision-free, {public['seeing_something_new']} saw something new")
    if args.plot:
        plot(result, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
