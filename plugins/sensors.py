"""Simulated range sensors: a pinhole depth camera and a laser stripe profiler."""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from explore.core import Param, Points3
from explore.sim import NOISE_MODELS, RaySensor

if TYPE_CHECKING:
    from explore.sim import Simulation


class DepthCamera(RaySensor):
    """Pinhole depth camera (RGB-D when ``color``), noise none / Kinect sigma(d) ~ d^2 / laser Eq. 4.39."""

    name = "depth_camera"
    geometry = "area"
    params = (
        Param("width", int, 320, "px", "image width", low=1, high=8192),
        Param("height", int, 240, "px", "image height", low=1, high=8192),
        Param("fov_deg", float, 58.0, "deg", "horizontal field of view", low=1.0, high=170.0),
        Param("min_range", float, 0.3, "m", "closest measurable range", low=0.0),
        Param("max_range", float, 3.5, "m", "farthest measurable range", low=0.01),
        Param("subsample", int, 1, "px", "keep every n-th pixel row and column", low=1),
        Param("noise", str, "kinect", "", "range noise model", choices=NOISE_MODELS),
        Param("noise_scale", float, 1.0, "", "multiplier on the noise sigma", low=0.0),
        Param("max_incidence_deg", float, 85.0, "deg", "no return beyond this incidence angle", low=0.0, high=90.0),
        Param("rate_hz", float, 30.0, "Hz", "frame rate", low=0.01),
        Param("no_return_clears", bool, True, "", "a beam without return frees the working range"),
        Param("color", bool, False, "", "add colour from pybullet's renderer"),
    )

    def __init__(self, **values: object) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")
        self.clear_from_origin = True

    @property
    def intrinsics(self) -> np.ndarray:
        """3x3 camera matrix (OpenCV) of the full-resolution image."""
        fx = (self.width / 2.0) / np.tan(np.deg2rad(self.fov_deg) / 2.0)
        return np.array([[fx, 0.0, self.width / 2.0], [0.0, fx, self.height / 2.0], [0.0, 0.0, 1.0]])

    @cached_property
    def _pixels(self) -> tuple[np.ndarray, np.ndarray]:
        v, u = np.mgrid[0 : self.height : self.subsample, 0 : self.width : self.subsample]
        return u.ravel(), v.ravel()

    def local_directions(self) -> Points3:
        k = self.intrinsics
        u, v = self._pixels
        rays = np.column_stack([(u + 0.5 - k[0, 2]) / k[0, 0], (v + 0.5 - k[1, 2]) / k[1, 1], np.ones(len(u))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def colors(self, sim: Simulation, poses: np.ndarray) -> np.ndarray:
        """Per-beam RGB from pybullet's TinyRenderer at the same intrinsics."""
        from explore.sim import p

        out = []
        fov_v = 2.0 * np.rad2deg(np.arctan((self.height / 2.0) / self.intrinsics[1, 1]))
        u, v = self._pixels
        for pose in poses:
            eye, z, y = pose[:3, 3], pose[:3, 2], pose[:3, 1]
            view = p.computeViewMatrix(eye.tolist(), (eye + z).tolist(), (-y).tolist())
            proj = p.computeProjectionMatrixFOV(fov_v, self.width / self.height, 0.01, self.max_range * 2)
            _, _, rgb, _, _ = p.getCameraImage(
                self.width, self.height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=sim.client
            )
            rgb = np.reshape(rgb, (self.height, self.width, 4))[:, :, :3]
            out.append(rgb[v, u])
        return np.vstack(out).astype(np.uint8)


class LaserStriper(RaySensor):
    """Line sensor (laser stripe profiler) swept along linear scan paths; triangulation semantics."""

    name = "laser_striper"
    geometry = "line"
    params = (
        Param("beams_per_stripe", int, 224, "", "beams per stripe", low=2),
        Param("fan_deg", float, 24.0, "deg", "fan angle of the stripe (~14 cm wide at 325 mm)", low=0.1, high=170.0),
        Param("min_range", float, 0.15, "m", "near end of the depth of field", low=0.0),
        Param("max_range", float, 0.5, "m", "far end of the depth of field", low=0.01),
        Param("rate_hz", float, 25.0, "Hz", "stripes per second", low=0.01),
        Param("speed", float, 0.05, "m/s", "default scan speed along a path", low=1e-4),
        Param("noise", str, "laser_poly", "", "range noise model", choices=NOISE_MODELS),
        Param("noise_scale", float, 1.0, "", "multiplier on the noise sigma", low=0.0),
        Param("max_incidence_deg", float, 80.0, "deg", "no return beyond this incidence angle", low=0.0, high=90.0),
        Param("no_return_clears", bool, True, "", "a beam without return frees the depth of field"),
    )

    def __init__(self, **values: object) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")
        # a triangulation sensor never proves anything below its minimum range free
        self.clear_from_origin = False

    @property
    def stripe_width(self) -> float:
        """Width of the stripe at the optimal distance (m)."""
        return 2.0 * self.optimal_distance * np.tan(np.deg2rad(self.fan_deg) / 2.0)

    def local_directions(self) -> Points3:
        """The fan lies in the sensor's x-z plane; a scan path moves along the sensor's y."""
        angles = np.deg2rad(np.linspace(-self.fan_deg / 2.0, self.fan_deg / 2.0, self.beams_per_stripe))
        return np.column_stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)])
PLUGINS = [DepthCamera, LaserStriper]
