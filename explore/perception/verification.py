"""Kriegel's render-and-compare verification of a pose hypothesis: render the model from the views the
cluster was seen from, compare with the measured depths, q_h = (N_m/N_r)(N_m/N_c)^2 (thesis Eq. 3.10), and ICP
refinement of a hypothesis' pose."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Array, Points3, Pose, invert, look_at
from explore.perception.hypotheses import ScanSource, raycasting_scene
from explore.perception.normals import estimate_normals
from explore.perception.segmentation import Cluster
from explore.sim import MeshWorld, RaySensor, Scan, TriMesh, box_mesh, target_for

if TYPE_CHECKING:
    from explore.perception.depth_filters import DepthProcessing
    from explore.perception.model_data import ModelCloud


def _cast(scene: Any, origins: Points3, directions: Points3) -> tuple[Array, Points3]:
    import open3d as o3d

    rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
    result = scene.cast_rays(rays)
    return result["t_hit"].numpy().astype(np.float64), result["primitive_normals"].numpy().astype(np.float64)


def pinhole_directions(width: int, height: int, fov_deg: float) -> Points3:
    """Unit beam directions (OpenCV camera frame) of a pinhole camera, row-major."""
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    v, u = np.mgrid[0:height, 0:width]
    rays = np.column_stack([(u.ravel() + 0.5 - width / 2.0) / f, (v.ravel() + 0.5 - height / 2.0) / f,
                            np.ones(width * height)])
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


@dataclass(frozen=True)
class RenderedView:
    """A synthetic view of a model: points (model frame) with normals, and model_T_camera."""

    points: Points3
    normals: Points3
    model_T_camera: Pose


def view_directions(count: int, min_elevation_deg: float = 10.0, max_elevation_deg: float = 70.0) -> Points3:
    """``count`` unit vectors on the upper part of the view sphere (rings of elevation)."""
    rings = max(1, int(round(math.sqrt(count / 4.0))))
    elevations = np.linspace(math.radians(min_elevation_deg), math.radians(max_elevation_deg), rings)
    weights = np.cos(elevations)
    per_ring = np.maximum(1, np.round(count * weights / weights.sum()).astype(int))
    out = []
    for k, (elev, n) in enumerate(zip(elevations, per_ring, strict=True)):
        az = (np.arange(n) + 0.5 * (k % 2)) * 2.0 * math.pi / n
        out.append(np.column_stack([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.full(n, math.sin(elev))]))
    return np.vstack(out)


def render_views(
    mesh: TriMesh,
    directions: Points3,
    distance: float = 1.0,
    resolution: int = 128,
    normal_radius: float = 0.01,
    min_height: float = 0.0,
    pixel_angle_deg: float | None = None,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> list[RenderedView]:
    """Ray-cast the model from ``distance`` along each direction (camera looks at the origin).

    The field of view just covers the model, with ``resolution`` pixels across or, when
    ``pixel_angle_deg`` is given, the angular pixel pitch of the real sensor (same point
    density). ``noise`` adds a range error of that standard deviation (m). Points lower than
    ``min_height`` above the model's lowest vertex are dropped (the segmentation cuts object
    bottoms the same way).
    """
    scene = raycasting_scene(mesh)
    lo, hi = mesh.bounds
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    fov = 2.0 * math.degrees(math.atan(1.15 * radius / distance))
    if pixel_angle_deg:
        resolution = max(8, int(math.ceil(fov / pixel_angle_deg)))
    local = pinhole_directions(resolution, resolution, fov)
    rng = rng or np.random.default_rng(0)
    views = []
    for direction in directions:
        eye = direction * distance
        pose = look_at(eye, np.zeros(3))
        dirs = local @ pose[:3, :3].T
        origins = np.broadcast_to(eye, dirs.shape)
        t_hit, _ = _cast(scene, origins, dirs)
        hit = np.isfinite(t_hit)
        ranges = t_hit[hit] + (rng.normal(0.0, noise, int(hit.sum())) if noise > 0 else 0.0)
        points = eye + dirs[hit] * ranges[:, None]
        normals = estimate_normals(points, normal_radius, eye)
        keep = points[:, 2] >= lo[2] + min_height
        views.append(RenderedView(points[keep], normals[keep], pose))
    return views


def sensed_views(
    mesh: TriMesh,
    directions: Points3,
    distance: float,
    sensor: RaySensor,
    processing: DepthProcessing,
    normal_radius: float = 0.01,
    min_height: float = 0.0,
    rng: np.random.Generator | None = None,
) -> list[RenderedView]:
    """The model standing on a floor, seen by ``sensor`` from ``distance`` along each direction
    (looking at the origin) with the sensor's artefacts and ``processing``, cut as the segmenter
    cuts a cluster: the returns within 1 cm of the model's box and ``min_height`` above its lowest
    vertex, with the depth image's normals where it gave them, else a neighbour search's. Training
    views that look like the scene's clusters (:func:`render_views` gives the bare surface)."""
    lo, hi = mesh.bounds
    floor = box_mesh(np.array([4.0 * distance, 4.0 * distance, 0.01]))
    world = MeshWorld([mesh, TriMesh(floor.vertices + [0.0, 0.0, lo[2] - 0.005], floor.triangles)])
    rng = rng or np.random.default_rng(0)
    views = []
    for direction in directions:
        eye = direction * distance
        scan = processing.apply(world.acquire(sensor, target_for(sensor, eye, np.zeros(3)), rng))
        points, origins = scan.points(), scan.origins[scan.hits]
        keep = np.all((points >= lo - 0.01) & (points <= hi + 0.01), axis=1) & (points[:, 2] >= lo[2] + min_height)
        points, origins = points[keep], origins[keep]
        normals = estimate_normals(points, normal_radius, origins) if len(points) else np.zeros((0, 3))
        if scan.normals is not None:
            given = scan.normals[scan.hits][keep]
            finite = np.isfinite(given[:, 0])
            normals[finite] = given[finite]
        views.append(RenderedView(points, normals, look_at(eye, np.zeros(3))))
    return views


def as_scan_map(scans: ScanSource | None, cluster: Cluster) -> dict[int, Scan]:
    """Normalise the scans argument to {view id: Scan}."""
    if scans is None:
        return {}
    if isinstance(scans, Scan):
        return {v: scans for v in cluster.view_ids}
    if isinstance(scans, Mapping):
        return dict(scans)
    return dict(enumerate(scans))


@dataclass(frozen=True)
class Verification:
    """Render-and-compare counts and q_h = (N_m/N_r)(N_m/N_c)^2 (Kriegel Eq. 3.10)."""

    quality: float
    matched: int
    rendered: int
    cluster: int
    occluded: int

    def as_dict(self) -> dict[str, float]:
        return {"q_h": self.quality, "N_m": self.matched, "N_r": self.rendered, "N_c": self.cluster,
                "occluded": self.occluded}


def render_and_compare(
    mesh: TriMesh,
    world_T_model: Pose,
    cluster: Cluster,
    scans: Mapping[int, Scan],
    threshold: float = 0.005,
    sigma_factor: float = 3.0,
    occlusion_aware: bool = True,
) -> Verification:
    """Render the model at the pose into each scan's beams and compare depths (Eq. 3.10).

    A rendered beam matches when it is one of the cluster's beams and the rendered range is
    within max(``threshold``, ``sigma_factor`` x the beam's sigma) of the measured range. With
    ``occlusion_aware`` a rendered beam whose measurement lies in front of the model and does
    not belong to the cluster is counted as occluded (removed from N_r) instead of as a miss.
    A rendered beam without a return is removed from N_r too when the scan's sensor does not let
    a missing return clear space (``no_return_clears`` false: a real camera's zero pixel, which a
    projector shadow, a dark or a grazing surface gives as well as empty space).
    """
    lo, hi = mesh.bounds
    center = world_T_model[:3, :3] @ (0.5 * (lo + hi)) + world_T_model[:3, 3]
    radius = 0.5 * float(np.linalg.norm(hi - lo)) * 1.05
    scene = raycasting_scene(mesh, world_T_model)
    matched = rendered = occluded = n_cluster = 0
    for view, scan in scans.items():
        in_cluster = cluster.beams[cluster.views == view]
        n_cluster += len(in_cluster)
        rel = center - scan.origins
        along = np.einsum("ij,ij->i", rel, scan.directions)
        perp = np.linalg.norm(rel - along[:, None] * scan.directions, axis=1)
        near = np.flatnonzero((perp <= radius) & (along > 0))
        if len(near) == 0:
            continue
        t_hit, _ = _cast(scene, scan.origins[near], scan.directions[near])
        hit = np.isfinite(t_hit)
        beams, t_hit = near[hit], t_hit[hit]
        measured = scan.ranges[beams]
        sigma = np.nan_to_num(scan.sigmas[beams], nan=0.0)
        tol = np.maximum(threshold, sigma_factor * sigma)
        member = np.isin(beams, in_cluster)
        ok = member & (np.abs(measured - t_hit) <= tol)
        hidden = np.zeros(len(beams), dtype=bool)
        if occlusion_aware:
            hidden = ~member & np.isfinite(measured) & (measured < t_hit - tol)
        if not scan.no_return_clears:  # a missing return says nothing (a shadow, a dark or grazing surface)
            hidden |= ~np.isfinite(measured)
        matched += int(ok.sum())
        occluded += int(hidden.sum())
        rendered += int(len(beams) - hidden.sum())
    q = 0.0
    if rendered > 0 and n_cluster > 0:
        q = (matched / rendered) * (matched / n_cluster) ** 2
    return Verification(float(q), matched, rendered, n_cluster, occluded)


# -- ICP and pose helpers -------------------------------------------------------------------
def o3d_cloud(points: Points3, normals: Points3 | None = None):  # -> o3d.geometry.PointCloud
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=float)))
    if normals is not None:
        cloud.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=float))
    return cloud


def _rotation_from_vector(w: Array) -> np.ndarray:
    """Rodrigues: rotation matrix of the rotation vector ``w``."""
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3)
    k = w / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * (kx @ kx)


def icp_refine(
    cluster_points: Points3,
    model: ModelCloud,
    world_T_model: Pose,
    distances: Sequence[float] = (0.01, 0.005, 0.003),
    iterations: int = 15,
) -> tuple[Pose, float, float]:
    """Point-to-plane ICP of the cluster (source) onto the model surface (target, model frame).

    Every visible cluster point has a true partner on the full model, which is why the
    cluster is the source. The model's kd-tree is built once and cached. Each stage gates
    correspondences at its distance; a Gauss-Newton step solves the 6x6 normal equations.
    Returns (world_T_model, fitness, inlier rmse) of the last stage.
    """
    tree = model.tree()
    T = invert(world_T_model)  # model_T_world
    src = np.asarray(cluster_points, dtype=float)
    fitness = rmse = 0.0
    for distance in distances:
        for _ in range(iterations):
            p = src @ T[:3, :3].T + T[:3, 3]
            d, idx = tree.query(p, k=1, distance_upper_bound=distance)
            ok = np.isfinite(d)
            if ok.sum() < 6:
                break
            q, n, pk = model.dense_points[idx[ok]], model.dense_normals[idx[ok]], p[ok]
            r = np.einsum("ij,ij->i", n, pk - q)
            a = np.hstack([np.cross(pk, n), n])
            x = np.linalg.lstsq(a.T @ a + 1e-9 * np.eye(6), -a.T @ r, rcond=None)[0]
            step = np.eye(4)
            step[:3, :3] = _rotation_from_vector(x[:3])
            step[:3, 3] = x[3:]
            T = step @ T
            if np.linalg.norm(x[:3]) < 1e-6 and np.linalg.norm(x[3:]) < 1e-7:
                break
        p = src @ T[:3, :3].T + T[:3, 3]
        d, _ = tree.query(p, k=1, distance_upper_bound=distance)
        ok = np.isfinite(d)
        fitness = float(ok.mean())
        rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else 0.0
    return invert(T), fitness, rmse


def inlier_fraction(cluster_points: Points3, model: ModelCloud, world_T_model: Pose, distance: float) -> float:
    """Fraction of cluster points within ``distance`` of the model surface at the pose."""
    T = invert(world_T_model)
    d, _ = model.tree().query(cluster_points @ T[:3, :3].T + T[:3, 3], k=1, distance_upper_bound=distance)
    return float(np.isfinite(d).mean()) if len(d) else 0.0
