"""View candidates for scene exploration: overview, views around a cluster, Görner's surround poses.

All functions return world_T_sensor poses (OpenCV frame: z = viewing direction) or, for line
sensors, :class:`~explore.sim.scan.ScanPath` targets sweeping across the region of interest.
Nothing here reads the ground truth.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, look_at
from explore.nbv import frame_from, make_target, path_over
from explore.sim import ScanPath

Target = Pose | ScanPath


def viewing_distance(sensor: Any, extent: float = 0.15, far: float = 0.8) -> float:
    """A distance to look at an object of size ``extent`` from: the middle of the working range,
    but no farther than ``far`` (depth noise grows with the square of the distance) and far
    enough to see the whole object in a 58 deg field of view."""
    near = max(float(sensor.min_range) + 0.05, 1.2 * extent / (2.0 * math.tan(math.radians(29.0))))
    return float(np.clip(float(sensor.optimal_distance), near, max(near, far)))


def overview_targets(spec: Any, sensor: Any, robot: Any = None) -> list[Target]:
    """First look at the scene: the world's ``overview`` pose, else views of the region centre.

    Area sensors get one view (the world's, or from the front and above); line sensors get
    parallel scan paths ("lawn mower" rows) over the region from above at the sensor's
    optimal distance. Robots with a fixed camera height (mobile base) get views at that height.
    """
    lo, hi = np.asarray(spec.region_min, dtype=float), np.asarray(spec.region_max, dtype=float)
    centre = 0.5 * (lo + hi)
    if sensor.geometry == "line":
        view = np.array([0.0, 0.0, -1.0])
        if spec.overview is not None:
            view = np.asarray(spec.overview[3:], dtype=float) - np.asarray(spec.overview[:3], dtype=float)
        return _lawn_mower(lo, hi, sensor, view / np.linalg.norm(view))
    if spec.overview is not None:
        eye, target = np.asarray(spec.overview[:3]), np.asarray(spec.overview[3:])
        return [look_at(eye, target)]
    target = np.array([centre[0], centre[1], lo[2]])
    size = float(np.linalg.norm(hi[:2] - lo[:2]))
    height = robot.camera_height
    out = []
    for azimuth in (-90.0, 180.0, 0.0, 90.0):
        a = math.radians(azimuth)
        direction = np.array([math.cos(a), math.sin(a)])
        if height is not None:
            eye = np.array([*(target[:2] + direction * max(0.7, 0.6 * size)), float(height)])
        else:
            distance = min(float(sensor.max_range) * 0.7, max(0.8, 0.9 * size))
            eye = target + distance * np.array([*(direction * math.cos(math.radians(50))), math.sin(math.radians(50))])
        out.append(look_at(eye, target))
    return out


def _lawn_mower(lo: Array, hi: Array, sensor: Any, view: Array, overlap: float = 0.2) -> list[ScanPath]:
    """Parallel scan paths over the region box, the sensor looking along ``view``.

    Each path sweeps horizontally across ``view`` at the sensor's optimal distance from the
    middle height of the region; the rows step along the horizontal part of ``view`` so that
    neighbouring stripes overlap by ``overlap`` on the region's floor.
    """
    standoff = float(sensor.optimal_distance)
    sweep = np.cross(view, [0.0, 0.0, 1.0])
    if np.linalg.norm(sweep) < 1e-6:  # looking straight down: sweep along x, rows along y
        sweep, across = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    else:
        sweep /= np.linalg.norm(sweep)
        across = np.cross([0.0, 0.0, 1.0], sweep)
    elevation = math.asin(min(1.0, abs(float(view[2]))))
    width = 2.0 * standoff * math.tan(math.radians(float(getattr(sensor, "fan_deg", 24.0))) / 2.0)
    step = width * (1.0 - overlap) / max(math.sin(elevation), 0.3)
    corners = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
    span = corners @ across[:2]
    rows = max(1, int(math.ceil((span.max() - span.min()) / step)))
    middle = np.array([*(0.5 * (lo[:2] + hi[:2])), 0.5 * (lo[2] + hi[2])])
    length = float(np.ptp(corners @ sweep[:2])) + 0.04
    out = []
    for k in range(rows):
        offset = span.min() + (k + 0.5) * (span.max() - span.min()) / rows - float(middle[:2] @ across[:2])
        focus = middle + offset * across
        pose = frame_from(view, sweep, focus - standoff * view)
        ends = np.array([focus - 0.5 * length * sweep, focus + 0.5 * length * sweep])
        out.append(path_over(pose, ends, standoff, getattr(sensor, "speed", 0.05), margin=0.0, max_length=length))
    return out


def views_around(
    centre: Array,
    distance: float,
    elevations_deg: tuple[float, ...] = (35.0, 55.0, 20.0, 70.0),
    azimuths: int = 12,
    camera_height: float | None = None,
) -> tuple[list[Pose], Array]:
    """Poses looking at ``centre`` from a ring of azimuths (and elevations), with their azimuths.

    With ``camera_height`` (a camera on a mast) the eyes sit at that height, at the horizontal
    distance that keeps ``distance`` to the centre (or at least 0.3 m).
    """
    centre = np.asarray(centre, dtype=float)
    poses, angles = [], []
    for elevation in elevations_deg if camera_height is None else (None,):
        for k in range(azimuths):
            a = 2.0 * math.pi * k / azimuths
            direction = np.array([math.cos(a), math.sin(a), 0.0])
            if camera_height is None:
                e = math.radians(elevation)
                eye = centre + distance * (math.cos(e) * direction + np.array([0.0, 0.0, math.sin(e)]))
            else:
                dz = float(camera_height) - centre[2]
                horizontal = math.sqrt(max(distance**2 - dz**2, 0.09))
                eye = np.array([*(centre[:2] + horizontal * direction[:2]), float(camera_height)])
            poses.append(look_at(eye, centre))
            angles.append(a)
    return poses, np.asarray(angles)


def order_by_novelty(poses: list[Pose], seen_from: Points3, centre: Array) -> list[int]:
    """Indices of ``poses`` ordered by the largest angle (at ``centre``) to the closest earlier view."""
    if len(seen_from) == 0:
        return list(range(len(poses)))
    centre = np.asarray(centre, dtype=float)
    old = np.asarray(seen_from, dtype=float) - centre
    old /= np.maximum(np.linalg.norm(old, axis=1, keepdims=True), 1e-12)
    new = np.array([p[:3, 3] for p in poses]) - centre
    new /= np.maximum(np.linalg.norm(new, axis=1, keepdims=True), 1e-12)
    closest = np.max(new @ old.T, axis=1)  # cosine to the closest earlier view
    return [int(i) for i in np.argsort(closest, kind="stable")]


def as_target(sensor: Any, pose: Pose, points: Points3 | None, distance: float) -> Target:
    """A single view for area sensors, a scan path across ``points`` for line sensors."""
    return make_target(sensor, pose, points, distance, path_margin=0.02)


def surround_poses(
    focus: Array,
    camera_height: float,
    d_min: float = 0.7,
    d_max: float = 1.5,
    step_rad: float = 0.5,
    start_angle: float = 0.0,
    distances: int = 10,
) -> list[list[Pose]]:
    """Görner's observation poses p_θ^d(c) = (c_x + d cos θ, c_y + d sin θ, θ + π) around focus c.

    Angles start at ``start_angle`` (the robot's bearing from c) and go counter-clockwise in
    ``int(2π/step)`` equal steps (Görner's code); per angle the candidate distances run from
    near (``d_min``) to far (``d_max``) in ``distances`` steps, so the caller takes the first
    reachable (Görner: the closest plannable distance). Returns one list per angle.
    """
    focus = np.asarray(focus, dtype=float)
    count = max(1, int(2.0 * math.pi / step_rad))
    angles = start_angle + np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    out = []
    for theta in angles:
        ring = []
        for d in np.linspace(d_min, d_max, distances):
            eye = np.array([focus[0] + d * math.cos(theta), focus[1] + d * math.sin(theta), camera_height])
            ring.append(look_at(eye, focus))
        out.append(ring)
    return out
