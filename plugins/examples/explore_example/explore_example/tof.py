"""A time-of-flight camera: a pinhole range camera whose noise grows with range and incidence."""

from __future__ import annotations

import numpy as np

from explore.api import Array, Param, Points3, Sensor


class TofCamera(Sensor):
    """Time-of-flight camera: sigma = a + b d^2 (phase noise over the returned light), worse at grazing angles.

    The returned light falls with d^2 and with the cosine of the incidence angle, so the phase
    noise grows as ``(a + b d^2) / sqrt(cos incidence)``; pixels that get too little light
    (incidence beyond ``max_incidence_deg``) return nothing.
    """

    name = "tof_camera"
    geometry = "area"
    params = (
        Param("width", int, 160, "px", "image width", low=2, high=4096),
        Param("height", int, 120, "px", "image height", low=2, high=4096),
        Param("fov_deg", float, 62.0, "deg", "horizontal field of view", low=1.0, high=170.0),
        Param("min_range", float, 0.1, "m", "closest measurable range", low=0.0),
        Param("max_range", float, 1.5, "m", "farthest measurable range (the modulation's unambiguous range)",
              low=0.01),
        Param("sigma_a", float, 0.001, "m", "range-independent noise", low=0.0),
        Param("sigma_b", float, 0.003, "1/m", "noise growth with the square of the range", low=0.0),
        Param("max_incidence_deg", float, 75.0, "deg", "no return beyond this incidence", low=0.0, high=90.0),
        Param("rate_hz", float, 30.0, "Hz", "frame rate", low=0.01),
    )

    def __init__(self, **values: object) -> None:
        super().__init__(**values)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")

    def local_directions(self) -> Points3:
        """(width x height, 3) unit rays of the pixel centres (OpenCV: x right, y down, z forward)."""
        f = (self.width / 2.0) / np.tan(np.deg2rad(self.fov_deg) / 2.0)
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        rays = np.column_stack([(u.ravel() + 0.5 - self.width / 2.0) / f, (v.ravel() + 0.5 - self.height / 2.0) / f,
                                np.ones(u.size)])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def sigma(self, d: Array) -> Array:
        """The range sigma the PVS assumes (head-on incidence)."""
        return self.sigma_a + self.sigma_b * np.square(np.asarray(d, dtype=float))

    def measure(self, ranges: Array, cos_incidence: Array, rng: np.random.Generator) -> Array:
        """True ranges + Gaussian phase noise of sigma(d) / sqrt(cos incidence)."""
        cos = np.clip(np.asarray(cos_incidence, dtype=float), 1e-3, 1.0)
        noisy = ranges + rng.normal(0.0, 1.0, size=ranges.shape) * self.sigma(np.nan_to_num(ranges)) / np.sqrt(cos)
        noisy[(noisy < self.min_range) | (noisy > self.max_range)] = np.nan
        return noisy
