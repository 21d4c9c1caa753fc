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
    """Pinhole depth camera (RGB-D when ``color``), noise none / Kinect sigma(d) ~ d^2 / laser Eq. 4.39;
    optional structured-light artefacts: disparity quantisation, projector shadows, flying pixels and a
    low-frequency bias (explore.sim.structured_light)."""

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
        # structured light (explore.sim.structured_light); all off by default
        Param("baseline", float, 0.075, "m", "projector to camera distance along the camera's x axis", low=1e-4),
        Param("disparity_step", float, 0.0, "px", "disparity quantisation step (Kinect: 0.125; 0: none)", low=0.0),
        Param("projector_shadow", bool, False, "", "no return where the projector does not light the surface"),
        Param("flying_pixels", float, 0.0, "", "probability of a mixed depth on a depth discontinuity",
              low=0.0, high=1.0),
        Param("edge_jump", float, 0.03, "m", "depth step to a neighbour that makes a discontinuity", low=1e-4),
        Param("bias_sigma", float, 0.0, "", "low-frequency per-frame depth bias, in units of sigma(d)", low=0.0),
    )

    def __init__(self, **values: object) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")
        self.clear_from_origin = True

    @property
    def _image_shape(self) -> tuple[int, int]:
        return len(range(0, self.height, self.subsample)), len(range(0, self.width, self.subsample))

    @property
    def casts_shadows(self) -> bool:
        return bool(self.projector_shadow)

    def lit(self, sim: Simulation, poses: np.ndarray, frame: np.ndarray, points: Points3) -> np.ndarray:
        """The projector, ``baseline`` along the camera's x axis, must see the point too (nothing
        closer on the line from the projector to it)."""
        projector = poses[frame, :3, 3] + self.baseline * poses[frame, :3, 0]
        towards = points - projector
        distance = np.linalg.norm(towards, axis=1)
        t_hit, _, _ = sim.raycaster.cast(projector, towards / distance[:, None])
        return t_hit >= distance - max(2e-3, 1e-3 * float(np.max(distance, initial=0.0)))

    def measure(self, ranges: np.ndarray, cos_incidence: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Flying pixels on depth edges, then the range noise, a smooth per-frame bias and the
        quantised disparity, on the organised depth image (each effect only when switched on)."""
        from explore.sim.structured_light import flying_pixels, quantise_disparity, smooth_field

        if not (self.flying_pixels > 0 or self.bias_sigma > 0 or self.disparity_step > 0):
            return super().measure(ranges, cos_incidence, rng)
        along = self.local_directions()[:, 2]  # depth z = range * cos(angle to the optical axis)
        frames = len(ranges) // len(along)
        image = (frames, *self._image_shape)
        if self.flying_pixels > 0:
            z = flying_pixels((ranges.reshape(frames, -1) * along).reshape(image), self.edge_jump,
                              self.flying_pixels, rng)
            ranges = (z.reshape(frames, -1) / along).ravel()
        ranges = super().measure(ranges, cos_incidence, rng)
        if self.bias_sigma > 0:
            bias = self.bias_sigma * smooth_field(*image, rng).ravel()
            ranges = ranges + bias * self.sigma(np.nan_to_num(ranges))
        if self.disparity_step > 0:
            z = ranges.reshape(frames, -1) * along
            z = quantise_disparity(z, float(self.intrinsics[0, 0]), self.baseline, self.disparity_step)
            ranges = (z / along).ravel()
        ranges[(ranges < self.min_range) | (ranges > self.max_range)] = np.nan
        return ranges

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
