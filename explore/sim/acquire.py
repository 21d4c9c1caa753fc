"""Turning 'look from here at that' into sensor targets (a pose or a scan path)."""

from __future__ import annotations

import copy

import numpy as np

from explore.core import Array, Pose, look_at
from explore.sim.meshes import TriMesh
from explore.sim.scan import Scan, ScanPath
from explore.sim.sensing import RaySensor
from explore.sim.simulation import RayCaster


def target_for(sensor: RaySensor, eye: Array, target: Array, sweep: float = 0.3) -> Pose | ScanPath:
    """A pose for area sensors; for line sensors a path of length ``sweep`` centred at ``eye``.

    The path runs along the sensor's y axis, across the stripe, at the sensor's speed.
    """
    pose = look_at(eye, target)
    if sensor.geometry != "line":
        return pose
    return centred_path(pose, sweep, getattr(sensor, "speed", 0.05))


def centred_path(pose: Pose, length: float, speed: float) -> ScanPath:
    """A scan path of ``length`` along the pose's y axis, centred on the pose."""
    half = 0.5 * length * pose[:3, 1]
    start, end = pose.copy(), pose.copy()
    start[:3, 3] = pose[:3, 3] - half
    end[:3, 3] = pose[:3, 3] + half
    return ScanPath(start, end, speed)


def path_length(poses: list[Pose] | np.ndarray) -> float:
    """Length of the polyline through the positions of ``poses``."""
    positions = np.asarray([pose[:3, 3] for pose in poses])
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


class MeshWorld:
    """A world of bare meshes for a sensor to look at: what :meth:`RaySensor.acquire` asks of a
    simulation, without pybullet."""

    client = None  # no renderer: nothing that needs the surfaces' colour is simulated

    def __init__(self, meshes: list[TriMesh]) -> None:
        self.raycaster = RayCaster(meshes)
        self.specular = np.zeros(len(meshes))  # bare meshes carry no material: matte

    def acquire(self, sensor: RaySensor, target: Pose | ScanPath, rng: np.random.Generator) -> Scan:
        """What ``sensor`` measures here from ``target``, with every artefact it simulates except
        those that need colour (dark-surface dropouts, RGB): e.g. the training views of a database
        model, which has no colour, as the scene's sensor sees them."""
        alone = copy.copy(sensor)
        alone.dark_level = 0.0
        alone.color = False
        return alone.acquire(self, target, rng)  # type: ignore[arg-type]
