"""What a scene exploration knows about the scene: its views (where each scan was taken: believed, corrected
and true poses) and its objects (a cluster with its status, hypotheses, pose and model), their statuses, and the
helpers that need nothing else (the mesh of a modelled object, the upright surfaces a base localises on, plugin
lookup)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose
from explore.mapping import boundary_loops, sample_surface
from explore.perception import (
    Cluster,
    FusedPose,
    Hypothesis,
)
from explore.sim import Scan, TriMesh

UNEXPLAINED, RECOGNISED, AMBIGUOUS, UNKNOWN, MODELLING, MODELLED = (
    "unexplained", "recognised", "ambiguous", "unknown", "modelling", "modelled")


EXPLAINED = (RECOGNISED, MODELLED)

# why an object's modelling stopped: the termination rule's target, its per-object scan budget (Kriegel's
# n_abort), the rule saw no progress left, no reachable view was left, the scene's view budget ran out, or
# a modelling scan showed a known object after all
TARGET, SCAN_BUDGET, NO_PROGRESS, NO_VIEW, VIEW_BUDGET, RECOGNISED_INSTEAD = (
    "target", "scan_budget", "no_progress", "no_view", "view_budget", "recognised")


FLOOR = (0.0, 0.0, 1.0, 0.0)  # the plane robot bases drive on (world z = 0)
UPRIGHT_NORMAL_Z = math.cos(math.radians(45.0))  # a face whose normal has |n_z| below this is upright
ENVIRONMENT_MARGIN = 0.005  # m: points this near the known environment (or outside the region) are not an object's
WALL_MARGIN = 0.02  # m: nor points this near its upright faces (the segmenter's plane distance threshold)


@dataclass
class View:
    """One acquisition: the scan at the believed pose, and why it was taken.

    ``true_pose`` is where the sensor really was (metrics only); ``believed`` the pose the
    scan is recorded at (odometry), ``corrected`` the pose graph's estimate (if run).
    """

    index: int
    scan: Scan
    believed: Pose
    true_pose: Pose
    purpose: str
    object_id: int | None = None
    corrected: Pose | None = None

    @property
    def recorded(self) -> Pose:
        """The pose the scan is recorded at now: the pose graph's estimate, else odometry."""
        return self.corrected if self.corrected is not None else self.believed


@dataclass
class SceneObject:
    """A cluster of the scene and how it is explained."""

    id: int
    cluster: Cluster
    status: str = UNEXPLAINED
    model: str | None = None
    pose: Pose | None = None
    q_h: float = math.nan
    v_h: float = math.nan
    hypotheses: list[Hypothesis] = field(default_factory=list)
    rivals: list[Hypothesis] = field(default_factory=list)
    rejected: list[dict[str, Any]] = field(default_factory=list)
    view_hypotheses: list[tuple[int, Hypothesis]] = field(default_factory=list)
    checked_views: set[tuple[int, str]] = field(default_factory=set)
    # view -> why that view alone did or did not confirm a pose (q_h, N_m/N_r, PVS votes): the margins
    view_checks: dict[int, str] = field(default_factory=dict)
    fused: FusedPose | None = None
    multi_views: int = 0
    modelling_scans: int = 0
    modelling_end: str = ""  # why its modelling stopped (TARGET, SCAN_BUDGET, ...; "" before)
    closer_looks: int = 0
    closer_look_unreached: bool = False  # a closer look was wanted and no view of it could be reached
    closer_look_offered: bool = False  # a closer-look step has seen it too small (and aimed its views at it)
    coverage_estimate: float = math.nan
    surface_points: Points3 | None = None
    recognised_after_views: int | None = None
    events: list[str] = field(default_factory=list)
    apart: set[int] = field(default_factory=set)  # objects a model told apart from it: never merged back
    _sample: Points3 | None = field(default=None, repr=False)

    @property
    def only_its_pose_in_doubt(self) -> bool:
        """No other model rivals its model: rivals, if any, are the same model at other turns (a shape
        sorter turned by 90°, a mug with its handle hidden)."""
        return all(r.model == self.model for r in self.rivals)

    @property
    def explained(self) -> bool:
        return self.status in EXPLAINED

    def box(self, margin: float = 0.0, top: float = 0.0) -> tuple[Array, Array]:
        """Axis-aligned box of the points, grown by ``margin`` (and by ``top`` upwards)."""
        lo, hi = self.cluster.aabb
        return lo - [margin, margin, 0.0], hi + [margin, margin, margin + top]

    def sample(self, voxel: float = 0.005) -> Points3:
        """The points thinned to one per ``voxel`` (for association tests)."""
        if self._sample is None:
            keys = np.floor(self.cluster.points / voxel).astype(np.int64)
            _, first = np.unique(keys, axis=0, return_index=True)
            self._sample = self.cluster.points[np.sort(first)]
        return self._sample

    def touches(self, points: Points3, tolerance: float) -> bool:
        """Whether any of ``points`` lies within ``tolerance`` of this object's (thinned) points."""
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(self.sample()).query(points, distance_upper_bound=tolerance)
        return bool(np.isfinite(dist).any())

    def extend(self, part: Cluster) -> None:
        c = self.cluster
        self.cluster = Cluster(c.id, np.vstack([c.points, part.points]), np.vstack([c.normals, part.normals]),
                               np.concatenate([c.views, part.views]), np.concatenate([c.beams, part.beams]), c.up)
        self._sample = None

    def note(self, text: str) -> None:
        self.events.append(text)


def without_vertices(mesh: TriMesh, drop: np.ndarray) -> TriMesh:
    """The mesh without the triangles that touch a dropped vertex (``drop``: (n,) bool), compacted."""
    triangles = mesh.triangles[~drop[mesh.triangles].any(axis=1)]
    used, inverse = np.unique(triangles, return_inverse=True)
    return TriMesh(mesh.vertices[used], inverse.reshape(-1, 3).astype(np.int32))


def close_holes(mesh: TriMesh) -> TriMesh:
    """Fill every boundary loop with a fan from its centroid (the open bottom becomes a cap).

    Each fan triangle runs against the direction of its border half-edge, so the filled mesh
    keeps the orientation of the surface it closes.
    """
    loops = boundary_loops(mesh.triangles, closed_only=True)
    if not loops:
        return mesh
    vertices = [mesh.vertices]
    triangles = [mesh.triangles]
    next_index = len(mesh.vertices)
    for loop in loops:
        centre = mesh.vertices[loop].mean(axis=0)
        a, b = loop, np.roll(loop, -1)
        triangles.append(np.column_stack([b, a, np.full(len(loop), next_index)]))
        vertices.append(centre[None])
        next_index += 1
    return TriMesh(np.vstack(vertices), np.vstack(triangles).astype(np.int32))


def environment_reference(sim: Any, spacing: float = 0.02, min_height: float = 0.05) -> Points3:
    """Points on the upright surfaces of the known environment (walls, table edges and legs):
    the map a mobile base localises in (a planner may know the environment; objects are left out)."""
    return environment_surface(sim, spacing, min_height)[0]


def environment_surface(sim: Any, spacing: float = 0.02, min_height: float = 0.05) -> tuple[Points3, Points3]:
    """:func:`environment_reference`'s points and their outward normals, one sample per ``spacing`` cell."""
    points, normals = [], []
    for body in sim.bodies:
        if body.is_object:
            continue
        p, n = sample_surface(body.mesh, spacing * spacing, seed=0)
        upright = (np.abs(n[:, 2]) < UPRIGHT_NORMAL_Z) & (p[:, 2] > min_height)
        points.append(p[upright])
        normals.append(n[upright])
    if not points:
        return np.zeros((0, 3)), np.zeros((0, 3))
    out, out_normals = np.vstack(points), np.vstack(normals)
    keys = np.floor(out / spacing).astype(np.int64)
    first = np.sort(np.unique(keys, axis=0, return_index=True)[1])
    return out[first], out_normals[first]


def _plugin(registry: Any, kind: str, spec: Any, role: str = "") -> Any:
    """A plugin from a name, (name, params), an object, or None (the registry's default for ``role``)."""
    if spec is None:
        spec = registry.default(kind, role)
    if isinstance(spec, str):
        return registry.create(kind, spec, {}, "<scene>", kind)
    if isinstance(spec, tuple):
        return registry.create(kind, spec[0], spec[1], "<scene>", kind)
    return spec
