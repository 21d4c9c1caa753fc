"""Simulated range sensors: a pinhole depth camera and a laser stripe profiler."""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from explore.core import Param, Points3
from explore.sim import (
    NOISE_MODELS,
    RaySensor,
    correlated_field,
    depth_level_spacing,
    flying_pixels,
    noise_sigma,
    p,
    quantise_disparity,
    smooth_field,
)

if TYPE_CHECKING:
    from explore.sim import Simulation


# A real device's missing return (a shadow, a dark or grazing surface) cannot be told from a beam
# that met nothing, so the realistic profiles do not let it clear the working range.
_DEPTH_PROFILES = {
    "ideal": {},
    # Kinect v1-like structured light (Khoshelham & Elberink 2012; Nguyen et al. 2012)
    "kinect": {"noise": "kinect", "disparity_step": 0.125, "disparity_width": 640, "projector_shadow": True,
               "flying_pixels": 0.5, "edge_jump": 0.02, "bias_sigma": 0.5, "patch_sigma": 0.7, "patch_px": 2.0,
               "grazing_from_deg": 60.0, "dark_level": 30.0, "highlight_deg": 10.0, "no_return_clears": False},
    # Kinect v2-like time of flight: every edge pixel mixes, flat noise, no projector baseline
    "tof": {"noise": "tof", "flying_pixels": 1.0, "edge_jump": 0.02, "bias_sigma": 0.5, "grazing_from_deg": 70.0,
            "dark_level": 50.0, "highlight_deg": 10.0, "no_return_clears": False},
}

# glossy surfaces (a world body's ``specular``): both sensors lose the returns in the highlight
_HIGHLIGHT = Param("highlight_deg", float, 0.0, "deg", "a glossy surface's highlight (the mirror reflection of the "
                   "emitter's light within this angle of the receiver) saturates the sensor: no return, with the "
                   "probability of the surface's `specular` share (0: off)", low=0.0, high=90.0)


class DepthCamera(RaySensor):
    """Pinhole depth camera (RGB-D when ``color``), noise none / Kinect sigma(d) ~ d^2 / time of flight /
    laser Eq. 4.39; the artefacts of real devices (explore.sim.artefacts), switched on together by a
    ``profile``: ``kinect`` (structured light: disparity quantisation, projector shadows, flying pixels,
    grazing, dark-surface and glossy-highlight dropouts, a per-frame bias and correlated patches) or ``tof``."""

    name = "depth_camera"
    geometry = "area"
    params = (
        Param("profile", str, "ideal", "", "a device's artefacts at once (parameters given beside it win)",
              choices=tuple(_DEPTH_PROFILES), presets=_DEPTH_PROFILES),
        Param("width", int, 320, "px", "image width", low=1, high=8192),
        Param("height", int, 240, "px", "image height", low=1, high=8192),
        Param("fov_deg", float, 58.0, "deg", "horizontal field of view", low=1.0, high=170.0),
        Param("min_range", float, 0.3, "m", "closest measurable range", low=0.0),
        Param("max_range", float, 3.5, "m", "farthest measurable range", low=0.01),
        Param("subsample", int, 1, "px", "keep every n-th pixel row and column", low=1, high=1024),
        Param("noise", str, "kinect", "", "range noise model", choices=NOISE_MODELS),
        Param("noise_scale", float, 1.0, "", "multiplier on the noise sigma", low=0.0, high=100.0),
        Param("max_incidence_deg", float, 85.0, "deg", "no return beyond this incidence angle", low=0.0, high=90.0),
        Param("grazing_from_deg", float, 90.0, "deg", "returns thin out (linearly in cos) from this incidence "
              "angle to max_incidence_deg", low=0.0, high=90.0),
        Param("rate_hz", float, 30.0, "Hz", "frame rate", low=0.01),
        Param("no_return_clears", bool, True, "", "a beam without return frees the working range"),
        Param("color", bool, False, "", "add colour from pybullet's renderer"),
        Param("dark_level", float, 0.0, "", "surface grey level (0-255) x cos(incidence) below which returns "
              "thin out in proportion (0: off)", low=0.0, high=255.0),
        _HIGHLIGHT,
        Param("baseline", float, 0.075, "m", "projector to camera distance along the camera's x axis", low=1e-4),
        Param("disparity_step", float, 0.0, "px", "disparity quantisation step (Kinect: 0.125; 0: none)", low=0.0),
        Param("disparity_width", int, 0, "px", "width of the image the device matches disparities in (Kinect: 640; "
              "0: this image's), which sets the focal length of the quantisation", low=0, high=8192),
        Param("projector_shadow", bool, False, "", "no return where the projector does not light the surface"),
        Param("flying_pixels", float, 0.0, "", "probability of a mixed depth on a depth discontinuity",
              low=0.0, high=1.0),
        Param("edge_jump", float, 0.03, "m", "depth step to a neighbour that makes a discontinuity", low=1e-4),
        Param("bias_sigma", float, 0.0, "", "low-frequency per-frame depth bias, in units of sigma(d)", low=0.0),
        Param("patch_sigma", float, 0.0, "", "correlated depth noise in patches, in units of sigma(d)", low=0.0),
        Param("patch_px", float, 2.0, "px", "correlation length of the patches (Gaussian sigma, full-resolution "
              "pixels)", low=0.1, high=1000.0),
    )

    def __init__(self, **values: object) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")
        if self.grazing_from_deg > self.max_incidence_deg:
            self.grazing_from_deg = 90.0  # no ramp: the hard cut at max_incidence_deg only
        self.clear_from_origin = True

    @property
    def _image_shape(self) -> tuple[int, int]:
        return len(range(0, self.height, self.subsample)), len(range(0, self.width, self.subsample))

    def organised_shape(self, frames: int) -> tuple[int, int, int]:
        return (frames, *self._image_shape)

    @property
    def shadow_offset(self) -> np.ndarray | None:
        """The projector, ``baseline`` along the camera's x axis."""
        return np.array([self.baseline, 0.0, 0.0]) if self.projector_shadow else None

    def sigma(self, d: np.ndarray) -> np.ndarray:
        """The total range standard deviation: white noise, bias, patches and the rounding to the
        quantised depth levels (uniform over a level spacing: variance spacing^2 / 12)."""
        white = super().sigma(d) * np.sqrt(1.0 + self.bias_sigma**2 + self.patch_sigma**2)
        if self.disparity_step <= 0:
            return white
        spacing = depth_level_spacing(np.asarray(d, dtype=float), self.disparity_focal, self.baseline,
                                      self.disparity_step)
        return np.sqrt(np.square(white) + np.square(spacing) / 12.0)

    def measure(self, ranges: np.ndarray, cos_incidence: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Flying pixels on depth edges, then the white range noise, a smooth per-frame bias,
        correlated patches and the quantised disparity, on the organised depth image (each effect
        only when switched on)."""
        if not (self.flying_pixels > 0 or self.bias_sigma > 0 or self.patch_sigma > 0 or self.disparity_step > 0):
            return super().measure(ranges, cos_incidence, rng)
        along = self.local_directions()[:, 2]  # depth z = range * cos(angle to the optical axis)
        frames = len(ranges) // len(along)
        image = (frames, *self._image_shape)
        if self.flying_pixels > 0:
            z = flying_pixels((ranges.reshape(frames, -1) * along).reshape(image), self.edge_jump,
                              self.flying_pixels, rng)
            ranges = (z.reshape(frames, -1) / along).ravel()
        ranges = super().measure(ranges, cos_incidence, rng)
        white = noise_sigma(self.noise, np.nan_to_num(ranges), self.noise_scale)
        if self.bias_sigma > 0:
            ranges = ranges + self.bias_sigma * smooth_field(*image, rng).ravel() * white
        if self.patch_sigma > 0:
            length = self.patch_px / self.subsample
            ranges = ranges + self.patch_sigma * correlated_field(image, (length, length), rng).ravel() * white
        if self.disparity_step > 0:
            z = ranges.reshape(frames, -1) * along
            z = quantise_disparity(z, self.disparity_focal, self.baseline, self.disparity_step)
            ranges = (z / along).ravel()
        ranges[(ranges < self.min_range) | (ranges > self.max_range)] = np.nan
        return ranges

    @property
    def disparity_focal(self) -> float:
        """Focal length (px) of the image the disparity is matched in: a 320-px image of a Kinect
        is its 640-px depth image downsampled, with the 640-px image's depth levels."""
        return float(self.intrinsics[0, 0]) * (self.disparity_width or self.width) / self.width

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
        return self._render(sim, poses, {})

    def albedo(self, sim: Simulation, poses: np.ndarray) -> np.ndarray:
        """Per-beam grey level of the surfaces' own colour: the render lit by ambient light only."""
        flat = {"shadow": 0, "lightAmbientCoeff": 1.0, "lightDiffuseCoeff": 0.0, "lightSpecularCoeff": 0.0}
        return self._render(sim, poses, flat).astype(float) @ np.array([0.299, 0.587, 0.114])

    def _render(self, sim: Simulation, poses: np.ndarray, lighting: dict) -> np.ndarray:
        out = []
        fov_v = 2.0 * np.rad2deg(np.arctan((self.height / 2.0) / self.intrinsics[1, 1]))
        u, v = self._pixels
        for pose in poses:
            eye, z, y = pose[:3, 3], pose[:3, 2], pose[:3, 1]
            view = p.computeViewMatrix(eye.tolist(), (eye + z).tolist(), (-y).tolist())
            proj = p.computeProjectionMatrixFOV(fov_v, self.width / self.height, 0.01, self.max_range * 2)
            _, _, rgb, _, _ = p.getCameraImage(
                self.width, self.height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=sim.client,
                **lighting,
            )
            rgb = np.reshape(rgb, (self.height, self.width, 4))[:, :, :3]
            out.append(rgb[v, u])
        return np.vstack(out).astype(np.uint8)


#: closest spacing of a striper's stripes along its path (m); closer adds no surface, only beams
MIN_STRIPE_SPACING = 1e-5

_STRIPER_PROFILES = {
    "ideal": {},
    # a real triangulating striper: its camera beside the laser, speckle along the stripe
    "triangulation": {"camera_shadow": True, "speckle_sigma": 1.0, "speckle_beams": 2.0, "grazing_from_deg": 60.0,
                      "highlight_deg": 10.0, "no_return_clears": False},
}


class LaserStriper(RaySensor):
    """Line sensor (laser stripe profiler) swept along linear scan paths; triangulation semantics.
    The ``triangulation`` profile adds what its camera, ``baseline`` along the sweep, makes of the
    stripe: shadows where the camera does not see the laser, speckle along the stripe, thinning
    returns at grazing incidence and none in a glossy surface's highlight (explore.sim.artefacts)."""

    name = "laser_striper"
    geometry = "line"
    params = (
        Param("profile", str, "ideal", "", "a device's artefacts at once (parameters given beside it win)",
              choices=tuple(_STRIPER_PROFILES), presets=_STRIPER_PROFILES),
        Param("beams_per_stripe", int, 224, "", "beams per stripe", low=2, high=65536),
        Param("fan_deg", float, 24.0, "deg", "fan angle of the stripe (~14 cm wide at 325 mm)", low=0.1, high=170.0),
        Param("min_range", float, 0.15, "m", "near end of the depth of field", low=0.0),
        Param("max_range", float, 0.5, "m", "far end of the depth of field", low=0.01),
        Param("rate_hz", float, 25.0, "Hz", "stripes per second", low=0.01),
        Param("speed", float, 0.05, "m/s", "default scan speed along a path", low=1e-4),
        Param("noise", str, "laser_poly", "", "range noise model", choices=NOISE_MODELS),
        Param("noise_scale", float, 1.0, "", "multiplier on the noise sigma", low=0.0, high=100.0),
        Param("max_incidence_deg", float, 80.0, "deg", "no return beyond this incidence angle", low=0.0, high=90.0),
        Param("grazing_from_deg", float, 90.0, "deg", "returns thin out (linearly in cos) from this incidence "
              "angle to max_incidence_deg", low=0.0, high=90.0),
        Param("no_return_clears", bool, True, "", "a beam without return frees the depth of field"),
        _HIGHLIGHT,
        Param("baseline", float, 0.08, "m", "laser to camera distance along the sweep (the sensor's y axis)",
              low=1e-4),
        Param("camera_shadow", bool, False, "", "no return where the camera does not see the laser line"),
        Param("clear_where_seen", bool, True, "",
              "with camera_shadow: a beam without a return frees the part of its depth of field the camera sees "
              "(a surface there would have returned)"),
        Param("speckle_sigma", float, 0.0, "", "speckle noise along the stripe, in units of sigma(d)", low=0.0),
        Param("speckle_beams", float, 2.0, "", "correlation length of the speckle along the stripe (beams)",
              low=0.1, high=10000.0),
    )

    def __init__(self, **values: object) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        if self.max_range <= self.min_range:
            raise ValueError("max_range must exceed min_range")
        if self.speed / self.rate_hz < MIN_STRIPE_SPACING:  # a 20 cm path would take millions of stripes
            raise ValueError(f"stripes {self.speed / self.rate_hz:.2g} m apart (speed / rate_hz): "
                             f"at least {MIN_STRIPE_SPACING:g} m")
        if self.grazing_from_deg > self.max_incidence_deg:
            self.grazing_from_deg = 90.0
        # a triangulation sensor never proves anything below its minimum range free
        self.clear_from_origin = False

    @property
    def shadow_offset(self) -> np.ndarray | None:
        """The camera, ``baseline`` along the sweep."""
        return np.array([0.0, self.baseline, 0.0]) if self.camera_shadow else None

    @property
    def seen_from(self) -> np.ndarray | None:
        """The camera, when ``clear_where_seen``: a surface it sees on the laser's path would have returned."""
        return self.shadow_offset if self.clear_where_seen else None

    def sigma(self, d: np.ndarray) -> np.ndarray:
        """The total range standard deviation: white noise and speckle (independent)."""
        return super().sigma(d) * np.sqrt(1.0 + self.speckle_sigma**2)

    def measure(self, ranges: np.ndarray, cos_incidence: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The white range noise, then speckle correlated along each stripe."""
        measured = super().measure(ranges, cos_incidence, rng)
        if self.speckle_sigma <= 0:
            return measured
        white = noise_sigma(self.noise, np.nan_to_num(measured), self.noise_scale)
        stripes = (len(measured) // self.beams_per_stripe, self.beams_per_stripe)
        speckle = correlated_field(stripes, (0.0, self.speckle_beams), rng).ravel()
        measured = measured + self.speckle_sigma * speckle * white
        measured[(measured < self.min_range) | (measured > self.max_range)] = np.nan
        return measured

    @property
    def stripe_width(self) -> float:
        """Width of the stripe at the optimal distance (m)."""
        return 2.0 * self.optimal_distance * np.tan(np.deg2rad(self.fan_deg) / 2.0)

    def local_directions(self) -> Points3:
        """The fan lies in the sensor's x-z plane; a scan path moves along the sensor's y."""
        angles = np.deg2rad(np.linspace(-self.fan_deg / 2.0, self.fan_deg / 2.0, self.beams_per_stripe))
        return np.column_stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)])
PLUGINS = [DepthCamera, LaserStriper]
