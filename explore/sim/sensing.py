"""Simulated range sensors: beam geometry, noise models and acquisition by ray casting.

Sensor plugins subclass :class:`RaySensor` and define the beam directions in the sensor
frame (OpenCV convention) and how a target (a pose, or a :class:`~explore.sim.scan.ScanPath`
for line sensors) becomes sensor frames. Acquisition casts every beam of every frame at once
against the ground truth with Open3D's ``RaycastingScene``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np

from explore.core import Array, Plugin, Points3, Pose
from explore.sim.artefacts import (
    dark_return_probability,
    grazing_return_probability,
    highlight_return_probability,
    mirror_deviation,
)
from explore.sim.scan import Scan, ScanPath

if TYPE_CHECKING:
    from explore.sim.simulation import Simulation

NOISE_MODELS = ("none", "kinect", "tof", "laser_poly")


def sigma_kinect(d: Array) -> Array:
    """Depth noise of a structured-light camera, sigma = 1.425e-3 d^2 (Khoshelham 2012), m."""
    return 1.425e-3 * np.square(d)


def sigma_tof(d: Array) -> Array:
    """Axial noise of a time-of-flight camera (Kinect v2) facing a surface, sigma = 1.5 - 0.5 d
    + 0.3 d^2 mm for d in m (Fankhauser et al. 2015, the frontal term): about 1.3 mm at 1 m and
    nearly flat over the working range, where a structured-light camera's grows with d^2."""
    d = np.asarray(d, dtype=float)
    return (1.5 - 0.5 * d + 0.3 * np.square(d)) * 1e-3


def sigma_laser_poly(d: Array) -> Array:
    """Laser-stripe-profiler noise polynomial, Kriegel thesis Eq. 4.39 (d and sigma in mm)."""
    mm = np.asarray(d) * 1000.0
    s = 0.005 + 0.0005 * mm + 1.026e-5 * mm**2 + 1.9979e-9 * mm**3 + 1.2655e-12 * mm**4
    return s / 1000.0


def noise_sigma(model: str, d: Array, scale: float = 1.0) -> Array:
    """Standard deviation of the measured range for noise ``model`` at range ``d`` (m)."""
    d = np.asarray(d, dtype=float)
    if model == "none":
        return np.zeros_like(d)
    if model == "kinect":
        return scale * sigma_kinect(d)
    if model == "tof":
        return scale * sigma_tof(d)
    if model == "laser_poly":
        return scale * sigma_laser_poly(d)
    raise ValueError(f"unknown noise model {model!r} (valid: {', '.join(NOISE_MODELS)})")


class RaySensor(Plugin, ABC):
    """Contract of kind ``sensor``: a simulated range sensor.

    Subclasses set ``geometry`` ("area": one frame per view; "line": a stripe swept along a
    :class:`~explore.sim.scan.ScanPath`), the working range ``min_range``/``max_range`` (m), the
    beam directions (:meth:`local_directions`, unit vectors in the sensor frame: OpenCV, z along
    the optical axis) and ``rate_hz``. The noise model is theirs to choose: :meth:`sigma` (the
    range standard deviation the PVS assumes) and :meth:`measure` (the measured ranges from the
    true ones). Acquisition (:meth:`acquire`) casts every beam against the ground truth.
    """

    kind = "sensor"
    geometry = "area"

    min_range: float
    max_range: float
    noise: str = "none"
    noise_scale: float = 1.0
    max_incidence_deg: float = 85.0
    grazing_from_deg: float = 90.0  # returns thin out from this incidence angle (>= max: a hard cut)
    dark_level: float = 0.0  # grey level of albedo x cos(incidence) below which returns thin out (0: off)
    highlight_deg: float = 0.0  # a glossy surface's highlight within this of the receiver saturates (0: off)
    rate_hz: float = 30.0
    clear_from_origin: bool = True
    no_return_clears: bool = True
    model_sigma_floor: float = 1e-3  # m: smallest sigma the PVS assumes (voxel scale)

    @abstractmethod
    def local_directions(self) -> Points3:
        """Unit beam directions (k, 3) in the sensor frame."""

    @property
    def optimal_distance(self) -> float:
        """Distance at which the sensor measures best: the middle of its working range."""
        return 0.5 * (self.min_range + self.max_range)

    def sigma(self, d: Array) -> Array:
        """Range standard deviation at range ``d`` (m)."""
        return noise_sigma(self.noise, d, self.noise_scale)

    def frames(self, target: Pose | ScanPath) -> tuple[np.ndarray, Array]:
        """Sensor poses (m, 4, 4) and timestamps (m,) for a target."""
        if isinstance(target, ScanPath):
            return target.poses(self.rate_hz)
        pose = np.asarray(target, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise ValueError("a sensor target must be a finite 4x4 pose or a ScanPath")
        return pose[None], np.zeros(1)

    def beams(
        self, target: Pose | ScanPath, beam_stride: int = 1, frame_stride: int = 1
    ) -> tuple[Points3, Points3, np.ndarray]:
        """World origins, directions and frame index of every beam for ``target``.

        The strides keep every n-th beam and frame, to simulate candidates cheaply (the
        thesis subsamples area sensors to every 4th row and column).
        """
        poses, _ = self.frames(target)
        poses = poses[::frame_stride]
        local = self.local_directions()[::beam_stride]
        return self._world_beams(poses, local)

    @staticmethod
    def _world_beams(poses: np.ndarray, local: Points3) -> tuple[Points3, Points3, np.ndarray]:
        directions = np.einsum("mij,kj->mki", poses[:, :3, :3], local).reshape(-1, 3)
        origins = np.repeat(poses[:, :3, 3], len(local), axis=0)
        frame = np.repeat(np.arange(len(poses)), len(local))
        return origins, directions, frame

    def acquire(self, sim: Simulation, target: Pose | ScanPath, rng: np.random.Generator) -> Scan:
        """Simulate one acquisition against the ground truth of ``sim``: cast every beam, drop
        the returns the sensor would not get (working range, grazing incidence, shadows of the
        second viewpoint, dark surfaces, glossy highlights), then :meth:`measure` the rest."""
        poses, timestamps = self.frames(target)
        origins, directions, frame = self._world_beams(poses, self.local_directions())
        t_hit, body, normals = sim.raycaster.cast(origins, directions)
        cos_incidence = np.abs(np.einsum("ij,ij->i", normals, directions))
        grazing = cos_incidence < np.cos(np.deg2rad(self.max_incidence_deg))
        valid = np.isfinite(t_hit) & (t_hit >= self.min_range) & (t_hit <= self.max_range) & ~grazing
        if self.grazing_from_deg < self.max_incidence_deg:
            p = grazing_return_probability(cos_incidence, self.grazing_from_deg, self.max_incidence_deg)
            valid &= rng.random(len(valid)) < p
        if self.shadow_offset is not None and valid.any():
            points = origins[valid] + directions[valid] * t_hit[valid, None]
            valid[np.flatnonzero(valid)[~self.lit(sim, poses, frame[valid], points)]] = False
        # the mirror share of the surface each beam meets (a matte world: 0, no per-beam array)
        specular = np.where(body >= 0, sim.specular[body], 0.0) if np.any(sim.specular) else 0.0
        if self.dark_level > 0 and (albedo := self.albedo(sim, poses)) is not None:
            p = dark_return_probability(albedo * (1.0 - specular) * cos_incidence, self.dark_level)
            valid &= rng.random(len(valid)) < p
        if self.highlight_deg > 0 and np.any(specular) and (glossy := valid & (specular > 0)).any():
            p = np.ones(len(valid))
            p[glossy] = self.highlight(poses, frame[glossy], origins[glossy], directions[glossy], t_hit[glossy],
                                       normals[glossy], specular[glossy])
            valid &= rng.random(len(valid)) < p
        ranges = self.measure(np.where(valid, t_hit, np.nan), cos_incidence, rng)
        sigmas = np.where(np.isfinite(ranges), self.sigma(np.nan_to_num(ranges)), np.nan)
        return Scan(
            origins=origins,
            directions=directions,
            ranges=ranges,
            sigmas=sigmas,
            sensor_poses=poses,
            timestamps=timestamps,
            frame_of_beam=frame,
            min_range=self.min_range,
            max_range=self.max_range,
            clear_from_origin=self.clear_from_origin,
            no_return_clears=self.no_return_clears,
            sensor=self.name,
            colors=self.colors(sim, poses) if getattr(self, "color", False) else None,
            image_shape=self.organised_shape(len(poses)),
            seen_from=self.seen_from,
        )

    def organised_shape(self, frames: int) -> tuple[int, int, int]:
        """(images, rows, columns) of the beams of ``frames`` frames: an area sensor's default is
        one row of beams per frame; a line sensor's sweep is one image, a stripe per row."""
        beams = len(self.local_directions())
        return (1, frames, beams) if self.geometry == "line" else (frames, 1, beams)

    @property
    def shadow_offset(self) -> Points3 | None:
        """Where the triangulation's second viewpoint (the projector of a structured-light camera,
        the camera of a laser striper) sits in the sensor frame (3,), when its shadows are
        simulated; None: an emitter at the sensor's centre, no shadows."""
        return None

    @property
    def seen_from(self) -> Points3 | None:
        """Where the second viewpoint sits (sensor frame, (3,)) when a beam without a return may free what that
        viewpoint saw of it (``Scan.seen_from``); None (default): a missing return proves nothing."""
        return None

    def lit(self, sim: Simulation, poses: np.ndarray, frame: np.ndarray, points: Points3) -> np.ndarray:
        """Which surface ``points`` (n, 3, world; seen in frame ``frame`` (n,) of ``poses``) the
        second viewpoint at :attr:`shadow_offset` sees too (n,) bool: nothing closer on the line
        from it to the point."""
        offset = self.shadow_offset
        if offset is None:
            return np.ones(len(points), dtype=bool)
        viewpoint = poses[frame, :3, 3] + np.einsum("nij,j->ni", poses[frame, :3, :3], offset)
        towards = points - viewpoint
        distance = np.linalg.norm(towards, axis=1)
        t_hit, _, _ = sim.raycaster.cast(viewpoint, towards / distance[:, None])
        return t_hit >= distance - max(2e-3, 1e-3 * float(np.max(distance, initial=0.0)))

    def highlight(self, poses: np.ndarray, frame: np.ndarray, origins: Points3, directions: Points3, t_hit: Array,
                  normals: Points3, specular: Array) -> Array:
        """Return probability (n,) of beams on glossy surfaces (``specular`` > 0, each with a hit in frame
        ``frame`` of ``poses``) under their highlights: the receiver is the second viewpoint
        (:attr:`shadow_offset`) when the sensor has one, else the beam's own origin (coaxial)."""
        points = origins + directions * t_hit[:, None]
        offset = self.shadow_offset
        receivers = origins if offset is None else poses[frame, :3, 3] + np.einsum("nij,j->ni", poses[frame, :3, :3],
                                                                                    offset)
        return highlight_return_probability(specular, mirror_deviation(directions, normals, points, receivers),
                                            self.highlight_deg)

    def measure(self, ranges: Array, cos_incidence: Array, rng: np.random.Generator) -> Array:
        """Measured ranges (n,) from the true ones (NaN: no return) and |cos| of the incidence
        angles (n,); NaN where the measurement leaves the working range. Default: independent
        Gaussian noise of the ``noise`` model times ``noise_scale``."""
        if self.noise == "none":
            return ranges
        sig = noise_sigma(self.noise, np.nan_to_num(ranges), self.noise_scale)
        ranges = ranges + rng.normal(0.0, 1.0, size=ranges.shape) * sig
        ranges[(ranges < self.min_range) | (ranges > self.max_range)] = np.nan
        return ranges

    def colors(self, sim: Simulation, poses: np.ndarray) -> np.ndarray | None:
        """Per-beam RGB (n, 3) uint8, for sensors that see colour."""
        return None

    def albedo(self, sim: Simulation, poses: np.ndarray) -> Array | None:
        """Per-beam grey level (n,) of the surfaces' own colour (0-255, no lighting), for sensors
        whose returns depend on it; None: not simulated."""
        return None
