"""Ground-truth metrics of a reconstruction (for evaluation only, never for planners).

* c_a: share of the *observable* ground-truth surface with a reconstructed point within τ
  (thesis §4.7 uses a 3 mm ball test). Observable = surface samples that a sensor in its
  working range sees from at least one pose of a dense omniscient view sphere (occlusion by
  every ground-truth body, incidence below the sensor's limit), so bottoms resting on a
  support do not count.
* ē: RMS point-to-surface distance of the reconstruction to the ground-truth object.
* Chamfer distance, coverage AUC over a scan budget, sensor path length, selection timing.

Everything is deterministic (fixed sampling seed, fixed view lattice).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from explore.core import Array, Points3, fibonacci_sphere
from explore.mapping.surface import border_edges
from explore.sim import RayCaster, TriMesh

if TYPE_CHECKING:
    from explore.sim import RayCaster, Simulation

__all__ = [
    "GroundTruthMetrics",
    "SelectionTimer",
    "chamfer",
    "coverage",
    "coverage_auc",
    "observable_surface",
    "path_length",
    "rms_error",
    "sample_surface",
    "seen_from",
    "view_sphere",
]


def sample_surface(mesh: TriMesh, area_per_point: float = 2e-6, seed: int = 0) -> tuple[Points3, Points3]:
    """Uniform area sampling of a mesh: about one point per ``area_per_point`` m².

    Returns points (n, 3) and the unit normals (n, 3) of the triangles they lie on.
    """
    tris = mesh.vertices[mesh.triangles]
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    total = 0.5 * float(double_area.sum())
    if total <= 0.0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    count = max(1, int(round(total / area_per_point)))
    rng = np.random.default_rng(seed)
    face = rng.choice(len(tris), size=count, p=double_area / double_area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    a, b, c = tris[face, 0], tris[face, 1], tris[face, 2]
    points = (1.0 - s)[:, None] * a + (s * (1.0 - r2))[:, None] * b + (s * r2)[:, None] * c
    normals = cross[face] / np.maximum(double_area[face], 1e-30)[:, None]
    return points, normals


def view_sphere(
    centre: Array,
    distance: float,
    n_views: int = 256,
    min_height: float | None = None,
    obstacles: Sequence[TriMesh] = (),
) -> Points3:
    """Sensor positions of the omniscient view sphere (Fibonacci lattice).

    Positions below ``min_height`` (the upper hemisphere above the support) and inside the
    bounding box of an obstacle mesh are dropped.
    """
    positions = np.asarray(centre, dtype=float) + distance * fibonacci_sphere(n_views)
    keep = np.ones(len(positions), dtype=bool)
    if min_height is not None:
        keep &= positions[:, 2] >= min_height
    for mesh in obstacles:
        lo, hi = mesh.bounds
        keep &= ~np.all((positions >= lo) & (positions <= hi), axis=1)
    return positions[keep]


def _orientation(mesh: TriMesh) -> int:
    """+1 if the mesh is closed with outward triangles, -1 if closed and inward, 0 if open."""
    if len(mesh.triangles) == 0 or len(border_edges(mesh.triangles)):
        return 0
    tris = mesh.vertices[mesh.triangles]
    volume = np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6.0
    return 1 if volume > 0 else -1


def observable_surface(
    sim: Simulation | None = None,
    *,
    gt_mesh: TriMesh | None = None,
    raycaster: RayCaster | None = None,
    min_range: float | None = None,
    max_range: float | None = None,
    max_incidence_deg: float | None = None,
    n_views: int = 256,
    view_distance: float | None = None,
    min_view_height: float | None = None,
    obstacles: Sequence[TriMesh] | None = None,
    area_per_point: float = 2e-6,
    seed: int = 0,
    tolerance: float = 5e-4,
    return_normals: bool = False,
) -> Points3 | tuple[Points3, Points3]:
    """Samples of the ground-truth object surface that some pose of a dense view sphere sees.

    With ``sim`` the object mesh, the ray caster (all ground-truth bodies occlude), the
    sensor's working range, incidence limit and optimal distance, and the environment bodies
    (poses inside them are dropped) come from the simulation; keyword arguments override.
    Without ``sim`` pass ``gt_mesh`` (and optionally a ``raycaster``; default: the mesh alone).

    Views sit at ``view_distance`` (default: the sensor's optimal distance) around the centre
    of the object's bounding box, above ``min_view_height`` (default: the object's lowest
    point, i.e. the support plane). A sample is visible from a view if its distance lies in
    [min_range, max_range], it faces the view (closed meshes; either side for open ones), the
    incidence angle is below ``max_incidence_deg`` and the first hit along the line of sight
    is the sample itself (within ``tolerance``).
    """
    sensor = getattr(sim, "sensor", None) if sim is not None else None
    if gt_mesh is None:
        if sim is None:
            raise ValueError("observable_surface needs a simulation or a ground-truth mesh")
        gt_mesh = sim.object_mesh()
    if raycaster is None:
        if sim is not None:
            raycaster = sim.raycaster
        else:
            raycaster = RayCaster([gt_mesh])
    if min_range is None:
        min_range = float(getattr(sensor, "min_range", 0.0))
    if max_range is None:
        max_range = float(getattr(sensor, "max_range", np.inf))
    if max_incidence_deg is None:
        max_incidence_deg = float(getattr(sensor, "max_incidence_deg", 90.0))
    if view_distance is None:
        view_distance = float(sensor.optimal_distance) if sensor is not None else 0.5 * (min_range + max_range)
    if not np.isfinite(view_distance):
        raise ValueError("observable_surface: give view_distance (no finite sensor range)")
    if obstacles is None:
        obstacles = [b.mesh for b in sim.ground_truth if not b.is_object] if sim is not None else []
    lo, hi = gt_mesh.bounds
    if min_view_height is None:
        min_view_height = float(lo[2])
    positions = view_sphere(0.5 * (lo + hi), view_distance, n_views, min_view_height, obstacles)

    points, normals = sample_surface(gt_mesh, area_per_point, seed)
    one_sided = _orientation(gt_mesh)
    if one_sided < 0:
        normals = -normals
    visible = np.zeros(len(points), dtype=bool)
    cos_limit = np.cos(np.deg2rad(min(max_incidence_deg, 90.0)))
    for eye in positions:
        todo = np.flatnonzero(~visible)
        if len(todo) == 0:
            break
        visible[todo[seen_from(eye, points[todo], normals[todo], raycaster, min_range, max_range, cos_limit,
                               both_sides=one_sided == 0, tolerance=tolerance)]] = True
    if return_normals:
        return points[visible], normals[visible]
    return points[visible]


def seen_from(eye: Array, points: Points3, normals: Points3, raycaster: RayCaster, min_range: float,
              max_range: float, cos_limit: float, both_sides: bool = False, tolerance: float = 5e-4,
              cone: tuple[Array, float] | None = None) -> Array:
    """(n,) True where a surface sample is seen from ``eye``: its distance in [min_range, max_range], its
    normal facing the eye within the incidence limit (cos >= ``cos_limit``; either side with
    ``both_sides``), inside ``cone`` = (unit axis, cos of the half angle) if given, and the first hit along
    the line of sight is the sample itself (within ``tolerance``)."""
    ray = points - eye
    dist = np.linalg.norm(ray, axis=1)
    direction = ray / np.maximum(dist, 1e-12)[:, None]
    cos = -np.einsum("ij,ij->i", direction, normals)
    if both_sides:  # orientation unknown: both sides of a triangle may be seen
        cos = np.abs(cos)
    ok = (dist >= min_range) & (dist <= max_range) & (cos >= cos_limit)
    if cone is not None:
        ok &= direction @ np.asarray(cone[0]) >= cone[1]
    seen = np.zeros(len(points), dtype=bool)
    todo = np.flatnonzero(ok)
    if len(todo):
        t_hit, _, _ = raycaster.cast(np.broadcast_to(eye, (len(todo), 3)), direction[todo])
        seen[todo[np.asarray(t_hit) >= dist[todo] - tolerance]] = True
    return seen


def covered(reconstructed: Points3, observable: Points3, tau: float = 0.003) -> Array:
    """(n,) True where an ``observable`` point has a reconstructed point within ``tau`` (m)."""
    observable = np.asarray(observable, dtype=float).reshape(-1, 3)
    reconstructed = np.asarray(reconstructed, dtype=float).reshape(-1, 3)
    if len(observable) == 0 or len(reconstructed) == 0:
        return np.zeros(len(observable), dtype=bool)
    dist, _ = cKDTree(reconstructed).query(observable, k=1, distance_upper_bound=tau)
    return np.isfinite(dist)


def coverage(reconstructed: Points3, observable: Points3, tau: float = 0.003) -> float:
    """c_a: share of ``observable`` points with a reconstructed point within ``tau`` (m)."""
    mask = covered(reconstructed, observable, tau)
    return float(mask.mean()) if len(mask) else 0.0


def _distance_scene(meshes: Sequence[TriMesh]):  # -> open3d.t.geometry.RaycastingScene
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes:
        tmesh = o3d.t.geometry.TriangleMesh()
        tmesh.vertex.positions = o3d.core.Tensor(mesh.vertices.astype(np.float32))
        tmesh.triangle.indices = o3d.core.Tensor(mesh.triangles.astype(np.int32))
        scene.add_triangles(tmesh)
    return scene


def _surface_distance(scene: Any, points: Points3) -> Array:
    import open3d as o3d

    query = o3d.core.Tensor(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    return scene.compute_distance(query).numpy().astype(np.float64)


def rms_error(reconstructed: Points3, gt_mesh: TriMesh) -> float:
    """ē: RMS distance of reconstructed points to the ground-truth surface (m); NaN if empty."""
    points = np.asarray(reconstructed, dtype=float).reshape(-1, 3)
    if len(points) == 0:
        return float("nan")
    dist = _surface_distance(_distance_scene([gt_mesh]), points)
    return float(np.sqrt(np.mean(dist**2)))


def chamfer(a: Points3, b: Points3) -> float:
    """Symmetric Chamfer distance: mean NN distance a→b plus mean b→a, halved (m)."""
    a = np.asarray(a, dtype=float).reshape(-1, 3)
    b = np.asarray(b, dtype=float).reshape(-1, 3)
    if len(a) == 0 or len(b) == 0:
        return float("inf")
    ab, _ = cKDTree(b).query(a, k=1)
    ba, _ = cKDTree(a).query(b, k=1)
    return float(0.5 * (ab.mean() + ba.mean()))


def coverage_auc(coverage_per_scan: Sequence[float], budget: int) -> float:
    """Normalised area under the coverage curve over scans 1..``budget`` (0..1).

    A run that stopped early keeps its last coverage for the remaining scans; values beyond
    the budget are ignored. AUC = (1/budget) Σ_{i=1..budget} c_i.
    """
    if budget <= 0:
        raise ValueError("budget must be positive")
    values = np.asarray(list(coverage_per_scan), dtype=float)[:budget]
    if len(values) == 0:
        return 0.0
    padded = np.concatenate([values, np.full(budget - len(values), values[-1])])
    return float(padded.mean())


def path_length(poses: Iterable[Any]) -> float:
    """Total sensor path length (m) through a sequence of 4x4 poses or scan paths.

    A :class:`~explore.sim.scan.ScanPath` contributes its start and end (so its own length and
    the transfer to and from it count).
    """
    positions = []
    for item in poses:
        if hasattr(item, "start") and hasattr(item, "end"):
            positions.extend([np.asarray(item.start)[:3, 3], np.asarray(item.end)[:3, 3]])
        else:
            positions.append(np.asarray(item, dtype=float).reshape(4, 4)[:3, 3])
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(np.asarray(positions), axis=0), axis=1).sum())


class SelectionTimer:
    """Wall-clock time per view selection: ``with timer.measure(): select()``."""

    def __init__(self) -> None:
        self.seconds: list[float] = []

    @contextmanager
    def measure(self) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds.append(time.perf_counter() - start)

    @property
    def mean(self) -> float:
        return float(np.mean(self.seconds)) if self.seconds else 0.0

    @property
    def total(self) -> float:
        return float(np.sum(self.seconds))


class GroundTruthMetrics:
    """Precomputes the observable surface of a simulation once, then evaluates quickly.

    ``GroundTruthMetrics(sim)`` or ``GroundTruthMetrics(gt_mesh=mesh, ...)``; remaining
    keyword arguments go to :func:`observable_surface`.
    """

    def __init__(
        self,
        sim: Simulation | None = None,
        *,
        gt_mesh: TriMesh | None = None,
        tau: float = 0.003,
        **observable_kwargs: Any,
    ) -> None:
        if gt_mesh is None:
            if sim is None:
                raise ValueError("GroundTruthMetrics needs a simulation or a ground-truth mesh")
            gt_mesh = sim.object_mesh()
        self.gt_mesh = gt_mesh
        self.tau = float(tau)
        start = time.perf_counter()
        self.observable, self.observable_normals = observable_surface(
            sim, gt_mesh=gt_mesh, return_normals=True, **observable_kwargs
        )
        self.all_samples, _ = sample_surface(
            gt_mesh, observable_kwargs.get("area_per_point", 2e-6), observable_kwargs.get("seed", 0)
        )
        self.precompute_seconds = time.perf_counter() - start
        self._scene = _distance_scene([gt_mesh])
        self._observable_tree = cKDTree(self.observable if len(self.observable) else np.zeros((1, 3)))

    @property
    def observable_share(self) -> float:
        """Share of the object surface that is observable at all."""
        return len(self.observable) / max(len(self.all_samples), 1)

    def coverage(self, points: Points3, tau: float | None = None) -> float:
        """c_a of ``points`` against the observable surface."""
        return coverage(points, self.observable, self.tau if tau is None else tau)

    def rms_error(self, points: Points3) -> float:
        """ē of ``points`` to the ground-truth object surface (m); NaN if empty."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) == 0:
            return float("nan")
        return float(np.sqrt(np.mean(_surface_distance(self._scene, points) ** 2)))

    def chamfer(self, points: Points3) -> float:
        """Chamfer distance between ``points`` and the observable surface samples (m)."""
        return chamfer(points, self.observable)

    def evaluate(self, points: Points3) -> dict[str, float]:
        """c_a, ē and Chamfer distance of a reconstruction (its points or mesh vertices)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) == 0 or len(self.observable) == 0:
            return {"coverage": 0.0, "rms_error": float("nan"), "chamfer": float("inf"), "points": 0.0}
        to_model, _ = cKDTree(points).query(self.observable, k=1)
        to_observable, _ = self._observable_tree.query(points, k=1)
        return {
            "coverage": float(np.count_nonzero(to_model <= self.tau) / len(self.observable)),
            "rms_error": self.rms_error(points),
            "chamfer": float(0.5 * (to_model.mean() + to_observable.mean())),
            "points": float(len(points)),
        }
