"""Optional logging of a run to a Rerun ``.rrd`` file (scans, poses, meshes, PVS, candidates)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .errors import BadInput


class RerunLog:
    """Writes what a run sees and decides to a Rerun recording, one ``scan`` step at a time."""

    def __init__(self, path: str | Path, app_id: str = "explore") -> None:
        try:
            import rerun as rr
        except ImportError:
            raise BadInput("--rerun", None, "needs the rerun-sdk package (pip install rerun-sdk)") from None
        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(app_id)
        self.rec.save(str(self.path))
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def step(self, index: int) -> None:
        self.rec.set_time("scan", sequence=int(index))

    def scan(self, scan: Any) -> None:
        points = scan.points()
        if len(points):
            self.rec.log("world/scan", self.rr.Points3D(points, radii=0.0008))
        for i, pose in enumerate(scan.sensor_poses[:: max(1, len(scan.sensor_poses) // 8)]):
            self.rec.log(f"world/sensor/{i}", self.rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))

    def mesh(self, vertices: np.ndarray, triangles: np.ndarray, name: str = "model") -> None:
        if len(triangles):
            self.rec.log(f"world/{name}", self.rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles))

    def voxels(self, centres: np.ndarray, size: float, name: str = "pvs_occupied") -> None:
        if len(centres):
            self.rec.log(f"world/{name}", self.rr.Points3D(centres, radii=size / 2))

    def candidates(self, positions: np.ndarray, directions: np.ndarray, scores: np.ndarray) -> None:
        if len(positions):
            self.rec.log(
                "world/candidates",
                self.rr.Arrows3D(origins=positions, vectors=directions * 0.05, labels=[f"{s:.3g}" for s in scores]),
            )

    def close(self) -> None:
        self.rec.flush()
