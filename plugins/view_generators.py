"""Built-in view generators: the sphere and random views (the thesis' baselines).

A view generator's ``generate(ctx)`` returns new :class:`~explore.nbv.candidates.Candidate`
objects for the candidate stack, given the :class:`~explore.nbv.candidates.PlanningContext`
(PVS, surface model, sensor, history; never the ground truth). Candidates are scan paths for
line sensors and single views for area sensors. Boundary Search and Hole Rescan are in
:mod:`explore_plugins.boundary_hole`.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any

import numpy as np

from explore.api import ViewGenerator
from explore.core import Array, Param, fibonacci_sphere
from explore.nbv import (
    Candidate,
    PlanningContext,
    any_sweep,
    clip_above,
    frame_from,
    in_environment_boxes,
    standoff_for,
)
from explore.sim import ScanPath


def sweep_target(ctx: PlanningContext, pose: Array, path_length: float) -> Any:
    """The view ``pose`` for an area sensor; for a line sensor a scan path of ``path_length`` centred on it
    along its y axis (the sweep direction); None when it dips below the support plane."""
    target: Any = pose
    if ctx.sensor.geometry == "line":
        half = 0.5 * path_length * pose[:3, 1]
        start, end = pose.copy(), pose.copy()
        start[:3, 3] -= half
        end[:3, 3] += half
        target = ScanPath(start, end, getattr(ctx.sensor, "speed", 0.05))
    return clip_above(target, ctx.lowest_sensor_z)  # objects cannot be viewed from below


class _OncePerRun(ViewGenerator):
    """A fixed search space: its candidates are made once per run and never dropped as stale."""

    persistent = True

    def reset(self) -> None:
        self._done = False

    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        if self._done:
            return []
        self._done = True
        return self.candidates(ctx)

    @abstractmethod
    def candidates(self, ctx: PlanningContext) -> list[Candidate]:
        """The whole search space, made on the first call of a run."""


# ---------------------------------------------------------------------------------------
# sphere
# ---------------------------------------------------------------------------------------
class Sphere(_OncePerRun):
    """Fixed search space around the region: inclination x azimuth grid of scan paths, or N views."""

    name = "sphere"
    params = (
        Param("n_inclination", int, 9, "", "inclination steps of the path grid (thesis: 9 x 9 = 81 paths)", low=1),
        Param("n_azimuth", int, 9, "", "azimuth steps of the path grid", low=1),
        Param("n_views", int, 121, "", "views for area sensors (IROS 2012: 121)", low=1),
        Param("min_elevation_deg", float, -20.0, "deg", "lowest elevation (the pedestal hides the bottom)"),
        Param("max_elevation_deg", float, 80.0, "deg", "highest elevation"),
        Param("radius", float, 0.0, "m", "distance from the region centre; 0 = the modelling standoff + 1/4 region",
              low=0.0),
        Param("path_length", float, 0.3, "m", "scan path length (thesis: ~300 mm, covers the object)", low=0.01),
        Param("lines", bool, True, "", "paths for line sensors (False: single views on a dome)"),
    )

    def views(self, ctx: PlanningContext) -> list[tuple[Array, Array]]:
        """(eye, view direction) pairs of the search space."""
        centre = ctx.region_centre
        radius = self.radius or float(standoff_for(ctx) + 0.25 * np.max(ctx.region_max - ctx.region_min))
        out = []
        if ctx.sensor.geometry == "line" and self.lines:
            elev = np.deg2rad(np.linspace(self.min_elevation_deg, self.max_elevation_deg, self.n_inclination))
            azim = np.linspace(0.0, 2.0 * np.pi, self.n_azimuth, endpoint=False)
            for i, e in enumerate(elev):
                for a in azim + (np.pi / self.n_azimuth) * (i % 2):
                    d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
                    out.append((centre + radius * d, -d))
        else:
            dirs = fibonacci_sphere(2 * self.n_views)
            low = np.sin(np.deg2rad(self.min_elevation_deg))
            dirs = dirs[dirs[:, 2] >= low][: self.n_views]
            out = [(centre + radius * d, -d) for d in dirs]
        return out

    def candidates(self, ctx: PlanningContext) -> list[Candidate]:
        out = []
        turns = self.turns(ctx)
        for index, (eye, view) in enumerate(self.views(ctx)):
            if in_environment_boxes(ctx, eye[None])[0]:
                continue
            up = any_sweep(view)
            for turn in turns:
                sweep = np.cos(turn) * up + np.sin(turn) * np.cross(view, up)
                pose = frame_from(view, sweep, eye)
                target = None if pose is None else sweep_target(ctx, pose, self.path_length)
                if target is None:
                    continue
                info = {"kind": "sphere", "index": index}
                if len(turns) > 1:
                    info["turn_deg"] = round(float(np.rad2deg(turn)))
                out.append(Candidate(target, self.name, info, None, ctx.iteration))
        return out

    @staticmethod
    def turns(ctx: PlanningContext) -> Array:
        """Turns of the sweep about the view axis: one for most sensors; four for a line sensor whose camera sits
        beside the stripe (``shadow_offset``), so that each view is offered with the camera above, beside and below
        the laser (what the laser lights only a camera on the right side sees)."""
        if ctx.sensor.geometry == "line" and getattr(ctx.sensor, "shadow_offset", None) is not None:
            return np.deg2rad([0.0, 90.0, 180.0, 270.0])
        return np.zeros(1)


class RandomViews(ViewGenerator):
    """Random views around the region at the modelling standoff (a baseline)."""

    name = "random"
    params = (
        Param("count", int, 20, "", "candidates per iteration", low=1),
        Param("min_elevation_deg", float, -20.0, "deg", "lowest elevation"),
        Param("path_length", float, 0.3, "m", "scan path length for line sensors", low=0.01),
    )

    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        centre = ctx.region_centre
        radius = float(standoff_for(ctx) + 0.25 * np.max(ctx.region_max - ctx.region_min))
        low = np.sin(np.deg2rad(self.min_elevation_deg))
        out = []
        while len(out) < self.count:
            d = ctx.rng.normal(size=3)
            d /= np.linalg.norm(d)
            if d[2] < low:
                continue
            eye = centre + radius * d
            sweep = ctx.rng.normal(size=3)
            pose = frame_from(-d, sweep, eye)
            if pose is None or in_environment_boxes(ctx, eye[None])[0]:
                continue
            target = sweep_target(ctx, pose, self.path_length)
            if target is None:
                continue
            out.append(Candidate(target, self.name, {"kind": "random"}, None, ctx.iteration))
        return out


# ---------------------------------------------------------------------------------------
# reachable views
# ---------------------------------------------------------------------------------------
class ReachableViews(_OncePerRun):
    """Views the robot can take: sensor poses of random configurations within its joint limits that
    look at the region at the modelling standoff, spread over positions and directions.

    The sphere and the boundary candidates are placed for the object, not for the robot: a
    fixed-base arm reaches few of them (in ``workcell`` about one in seven views along a surface
    normal at the optimal distance), while the surface it can see from some reachable pose is far
    larger (``benchmarks/reach_limit.py``). These candidates are reachable by construction (the
    planner still checks the scan path, collisions and the approach), in the spirit of a capability
    map (Zacharias et al. 2007); the fallback of an arm on a fixed base (``start_modelling.fallback``).
    """

    name = "reachable"
    params = (
        Param("samples", int, 20000, "", "random configurations tried", low=1),
        Param("count", int, 243, "", "candidates kept, spread over positions and view directions", low=1),
        Param("path_length", float, 0.3, "m", "scan path length for line sensors", low=0.01),
        Param("direction_weight", float, 0.2, "m/rad", "metres a radian of view direction counts as when "
              "spreading the candidates", low=0.0),
    )

    def poses(self, ctx: PlanningContext) -> np.ndarray:
        """(n, 4, 4) sensor poses of random configurations whose optical axis meets the region at the
        modelling standoff, outside the known environment."""
        robot = ctx.robot
        lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
        configs = lower + ctx.rng.random((self.samples, len(lower))) * (upper - lower)
        poses = np.array([robot.fk(q) for q in configs])
        if hasattr(robot, "set_config"):
            robot.set_config(robot.q)
        aim = poses[:, :3, 3] + standoff_for(ctx) * poses[:, :3, 2]
        inside = np.all((aim >= ctx.region_min) & (aim <= ctx.region_max), axis=1)
        inside &= ~in_environment_boxes(ctx, poses[:, :3, 3])
        return poses[inside]

    def candidates(self, ctx: PlanningContext) -> list[Candidate]:
        poses = self.poses(ctx)
        if len(poses) == 0:
            return []
        features = np.hstack([poses[:, :3, 3], self.direction_weight * poses[:, :3, 2]])
        chosen = [0]  # farthest-point spreading: each next pose the farthest from those chosen
        gap = np.linalg.norm(features - features[0], axis=1)
        while len(chosen) < min(self.count, len(poses)):
            chosen.append(int(np.argmax(gap)))
            gap = np.minimum(gap, np.linalg.norm(features - features[chosen[-1]], axis=1))
        out = []
        for index in chosen:
            target = sweep_target(ctx, poses[index], self.path_length)
            if target is not None:
                out.append(Candidate(target, self.name, {"kind": "reachable", "index": index}, None, ctx.iteration))
        return out


PLUGINS = [Sphere, RandomViews, ReachableViews]
