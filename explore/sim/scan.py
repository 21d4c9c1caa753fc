"""Range measurements: one ``Scan`` holds every beam of a view or of a whole scan path."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from explore.core import Array, Points3, Pose


@dataclass(frozen=True)
class ScanPath:
    """A linear Cartesian scan motion at constant speed with fixed orientation.

    ``start`` and ``end`` are world_T_sensor poses (the orientation of ``start`` is kept).
    """

    start: Pose
    end: Pose
    speed: float = 0.05  # m/s

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end[:3, 3] - self.start[:3, 3]))

    def poses(self, rate_hz: float) -> tuple[np.ndarray, Array]:
        """Sensor poses (m, 4, 4) and timestamps (m,) sampled at ``rate_hz`` along the path."""
        duration = self.length / max(self.speed, 1e-9)
        count = max(2, int(np.ceil(duration * rate_hz)) + 1)
        s = np.linspace(0.0, 1.0, count)
        poses = np.repeat(self.start[None], count, axis=0)
        poses[:, :3, 3] = self.start[:3, 3] + s[:, None] * (self.end[:3, 3] - self.start[:3, 3])
        return poses, s * duration

    @property
    def mid(self) -> Pose:
        pose = self.start.copy()
        pose[:3, 3] = 0.5 * (self.start[:3, 3] + self.end[:3, 3])
        return pose


@dataclass(frozen=True)
class Scan:
    """Beams of one acquisition in world coordinates.

    Attributes
    ----------
    origins : (n, 3) float
        Beam origins.
    directions : (n, 3) float
        Unit beam directions.
    ranges : (n,) float
        Measured range along the beam in metres; NaN for a beam without a return.
    sigmas : (n,) float
        Range standard deviation the sensor model gives for the measured range (NaN if none).
    sensor_poses : (m, 4, 4) float
        world_T_sensor of each frame (OpenCV convention).
    timestamps : (m,) float
        Time of each frame in seconds from the start of the acquisition.
    frame_of_beam : (n,) int
        Index into ``sensor_poses`` for every beam.
    min_range, max_range : float
        Working range of the sensor.
    clear_from_origin : bool
        True if a return proves the beam free from its origin; False for triangulation
        sensors, where only the part inside the working range is proven free.
    no_return_clears : bool
        True if a beam without a return proves its working range free.
    colors : (n, 3) uint8 or None
    image_shape : (images, rows, columns) or None
        How the beams form organised depth images (``ranges.reshape(image_shape)``): one image
        per frame of an area sensor, a line sensor's sweep as one image of stripes; None once
        beams are dropped.
    normals : (n, 3) float or None
        Surface normals of the returns (world frame, towards the sensor; NaN where none), when
        depth processing estimated them from the organised image.
    seen_from : (3,) float or None
        A triangulating sensor's second viewpoint (the camera of a laser striper) in the sensor
        frame, when a beam without a return may free the part of its working range that viewpoint
        sees (a surface there would have returned); None: a missing return frees nothing beyond
        ``no_return_clears``.
    """

    origins: Points3
    directions: Points3
    ranges: Array
    sigmas: Array
    sensor_poses: np.ndarray
    timestamps: Array
    frame_of_beam: np.ndarray
    min_range: float
    max_range: float
    clear_from_origin: bool
    no_return_clears: bool
    sensor: str = ""
    colors: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    image_shape: tuple[int, int, int] | None = None
    normals: np.ndarray | None = None
    seen_from: Array | None = None

    def __len__(self) -> int:
        return len(self.ranges)

    @property
    def hits(self) -> np.ndarray:
        """Mask of beams with a return."""
        return np.isfinite(self.ranges)

    def points(self) -> Points3:
        """Measured surface points (only beams with a return)."""
        hit = self.hits
        return self.origins[hit] + self.directions[hit] * self.ranges[hit, None]

    def normals_towards_sensor(self) -> Points3:
        """Unit vectors from each measured point back to its beam origin."""
        return -self.directions[self.hits]

    def to_open3d(self):  # -> open3d.geometry.PointCloud
        """Open3D point cloud of the returns (with colours when the sensor gave them)."""
        import open3d as o3d

        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points()))
        if self.colors is not None:
            cloud.colors = o3d.utility.Vector3dVector(self.colors[self.hits] / 255.0)
        return cloud

    def write_ply(self, path: str | Path) -> None:
        import open3d as o3d

        if not o3d.io.write_point_cloud(str(path), self.to_open3d()):
            raise OSError(f"could not write {path}")

    def subset(self, mask: np.ndarray) -> Scan:
        """The scan restricted to the beams in ``mask``."""
        return Scan(
            self.origins[mask],
            self.directions[mask],
            self.ranges[mask],
            self.sigmas[mask],
            self.sensor_poses,
            self.timestamps,
            self.frame_of_beam[mask],
            self.min_range,
            self.max_range,
            self.clear_from_origin,
            self.no_return_clears,
            self.sensor,
            None if self.colors is None else self.colors[mask],
            dict(self.meta),
            None,
            None if self.normals is None else self.normals[mask],
            self.seen_from,
        )
