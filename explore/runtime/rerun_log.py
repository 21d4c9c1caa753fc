"""Optional logging of a run to a Rerun ``.rrd`` file (scans, poses, meshes, PVS, candidates).

``explore run ... --rerun run.rrd`` writes the recording; open it with ``rerun run.rrd``
(the viewer ships with the ``rerun-sdk`` package, installed by ``./run.sh`` as the
``rerun`` extra). Entities (all in metres, world frame, z up):

* ``world/environment/<name>``, ``world/objects/<name>``: the world's meshes (static)
* ``world/scan``: the returns of the latest scan; ``world/sensor/<i>``: its sensor frames
* ``world/model``: the surface mesh after each integration
* ``world/pvs_occupied``: centres of the voxels with occupancy p >= 0.75
* ``world/candidates``: the scored candidates (view direction arrows, score labels)
* ``world/trajectory``, ``world/robot_sensor``: executed sensor path and the final sensor pose

The timeline ``scan`` counts the scans.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from explore.core import BadInput, check_output


def check_rerun(path: str | Path) -> None:
    """BadInput unless the Rerun SDK is installed and ``path`` is a writable ``.rrd`` file path."""
    check_output(path, "--rerun", suffixes=(".rrd",))
    try:
        import rerun  # noqa: F401
    except ImportError:
        raise BadInput("--rerun", None, "needs the rerun-sdk package (pip install rerun-sdk)") from None


class RerunLog:
    """Writes what a run sees and decides to a Rerun recording, one ``scan`` step at a time."""

    def __init__(self, path: str | Path, app_id: str = "explore") -> None:
        check_rerun(path)
        import rerun as rr

        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(app_id)
        self.rec.save(str(self.path))
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._closed = False

    def world(self, sim: Any) -> None:
        """The world's ground-truth meshes (static: for looking, the planner never sees them)."""
        for body in sim.bodies:
            folder = "objects" if body.is_object else "environment"
            colour = [200, 160, 90] if body.is_object else [150, 150, 150]
            self.rec.log(
                f"world/{folder}/{body.name}",
                self.rr.Mesh3D(vertex_positions=body.mesh.vertices, triangle_indices=body.mesh.triangles,
                               albedo_factor=colour),
                static=True,
            )

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
            labels = [f"{s:.3g}" for s in np.asarray(scores, dtype=float)]
            self.rec.log("world/candidates",
                         self.rr.Arrows3D(origins=positions, vectors=directions * 0.05, labels=labels))

    def trajectory(self, positions: np.ndarray) -> None:
        if len(positions) > 1:
            self.rec.log("world/trajectory", self.rr.LineStrips3D([positions], radii=0.002))

    def sensor_pose(self, pose: np.ndarray) -> None:
        self.rec.log("world/robot_sensor", self.rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))

    def close(self) -> None:
        """Flush and finish the file (``disconnect`` writes the footer readers need)."""
        if not self._closed:
            self.rec.flush()
            self.rec.disconnect()
            self._closed = True
