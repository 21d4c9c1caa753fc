"""Scene segmentation: support plane (table), objects above it, Euclidean clusters.

The pipeline follows Görner's tabletop segmentation (digest §2) and Kriegel's
pre-segmentation for recognition (thesis §3.4):

1. floor cut: look for the support plane above ``min_plane_height`` (world z; Görner 0.20 m), and
   below it only when there is none above (objects on the floor);
2. RANSAC plane with distance threshold 0.02 m and N = log(1 − p) / log(1 − w³) iterations
   (p = success probability, w = inlier fraction; p = 0.99, w = 1/3 gives 122 ≈ Görner's
   125); planes tilted more than ``max_tilt_deg`` from the up vector are skipped;
3. table = the largest connected inlier cluster (tolerance 0.03 m), least-squares refit,
   its 2-D convex hull in the plane frame;
4. objects = points inside the hull prism between ``min_height`` and ``max_height``
   (0–0.5 m) above the plane; Görner counts points within the 2 cm RANSAC band as table and so
   loses the bottom 2 cm of every object, we keep points above ``min_height`` (1 cm) of the
   refitted plane instead;
5. Euclidean clustering (tolerance, minimum size: 0.05 m / 20 points at room scale, smaller
   tolerance at table scale).

Clusters carry their points, normals (oriented towards the sensor), the views and beams they
came from, an axis-aligned and an upright oriented bounding box. :func:`merge_clusters`
merges clusters of several views.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, open3d_serial
from explore.perception.contracts import Segmenter
from explore.perception.normals import estimate_normals
from explore.sim import Scan

WORLD_UP = np.array([0.0, 0.0, 1.0])


def ransac_iterations(probability: float, inlier_fraction: float, sample_size: int = 3) -> int:
    """Iterations N = log(1 − p) / log(1 − w^s) for success probability p (Görner Ch. 3)."""
    p = min(max(probability, 1e-9), 1.0 - 1e-12)
    w = min(max(inlier_fraction, 1e-6), 1.0)
    miss = 1.0 - w**sample_size
    if miss <= 0.0:
        return 1
    return max(1, math.ceil(math.log(1.0 - p) / math.log(miss)))


def euclidean_clusters(points: Points3, tolerance: float, min_size: int = 1, max_size: int | None = None) -> np.ndarray:
    """Labels (n,) of Euclidean clusters (−1: cluster smaller than ``min_size`` or larger than ``max_size``).

    Points are first binned into voxels of ``tolerance / 2``; voxel means closer than
    ``tolerance`` are connected (a kd-tree radius search + connected components), so two
    points join when their voxels do (an approximation within half a voxel diagonal).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    voxel = tolerance / 2.0
    keys = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    centers = np.zeros((len(counts), 3))
    np.add.at(centers, inverse, points)
    centers /= counts[:, None]
    pairs = cKDTree(centers).query_pairs(tolerance, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(centers),) * 2)
    _, voxel_label = connected_components(graph, directed=False)
    labels = voxel_label[inverse]
    sizes = np.bincount(labels)
    bad = sizes < min_size
    if max_size is not None:
        bad |= sizes > max_size
    # relabel by decreasing size, dropped clusters -> -1
    order = np.argsort(-sizes, kind="stable")
    new = np.full(len(sizes), -1, dtype=np.int64)
    keep = order[~bad[order]]
    new[keep] = np.arange(len(keep))
    return new[labels]


def fit_plane_lsq(points: Points3) -> Array:
    """Least-squares plane (a, b, c, d) with unit normal (a, b, c): n·x + d = 0."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[-1]
    return np.append(normal, -normal @ centroid)


@dataclass(frozen=True)
class Table:
    """A support plane with its 2-D convex hull.

    ``plane`` (a, b, c, d) has a unit normal pointing up (n·x + d = 0); ``world_T_table`` has
    z along the normal, origin at the hull centroid, x along the hull's main axis; ``hull``
    (k, 2) holds the hull vertices (counter-clockwise) in the table frame.
    """

    plane: Array
    world_T_table: Pose
    hull: Array
    inliers: int

    @property
    def normal(self) -> Array:
        return self.plane[:3]

    @property
    def height(self) -> float:
        """Height of the plane above the world origin along its normal (−d)."""
        return float(-self.plane[3])

    def heights(self, points: Points3) -> Array:
        """Signed height of points above the plane."""
        return points @ self.plane[:3] + self.plane[3]

    def to_table(self, points: Points3) -> Points3:
        """Points in the table frame."""
        pose = self.world_T_table
        return (points - pose[:3, 3]) @ pose[:3, :3]

    def inside(self, points: Points3, margin: float = 0.0) -> np.ndarray:
        """Mask of points whose projection lies inside the hull (grown by ``margin``)."""
        local = self.to_table(points)[:, :2]
        edges = np.roll(self.hull, -1, axis=0) - self.hull
        normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward for a CCW polygon
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        offset = np.einsum("ij,ij->i", normals, self.hull)
        return np.all(local @ normals.T - offset <= margin, axis=1)


def same_plane(a: Table, b: Table, distance: float, max_angle_deg: float = 5.0) -> bool:
    """True if two tables lie in one plane: normals within ``max_angle_deg``, heights within ``distance``."""
    angle = math.degrees(math.acos(min(1.0, abs(float(a.normal @ b.normal)))))
    return angle <= max_angle_deg and abs(float(b.heights(a.world_T_table[:3, 3][None])[0])) <= distance


def merge_tables(a: Table, b: Table | None) -> Table:
    """``a`` with its hull grown by ``b``'s (both hulls projected into ``a``'s table frame)."""
    if b is None:
        return a
    return grown_to(a, b.hull @ b.world_T_table[:3, :2].T + b.world_T_table[:3, 3], b.inliers)


def grown_to(table: Table, points: Points3, inliers: int = 0) -> Table:
    """``table`` with its hull grown to cover ``points`` (world, projected onto its plane); ``table``
    itself if the hull cannot be built."""
    from scipy.spatial import ConvexHull, QhullError

    local = np.vstack([table.hull, table.to_table(points)[:, :2]])
    try:
        hull = ConvexHull(local)
    except QhullError:
        return table
    return Table(table.plane, table.world_T_table, local[hull.vertices], table.inliers + inliers)


@dataclass
class Cluster:
    """One object candidate: points with normals and where they came from.

    ``views`` (n,) and ``beams`` (n,) give, for every point, the id of the view (scan) and
    the index of its beam in that scan.
    """

    id: int
    points: Points3
    normals: Points3
    views: np.ndarray
    beams: np.ndarray
    up: Array = field(default_factory=lambda: WORLD_UP.copy())

    @property
    def view_ids(self) -> tuple[int, ...]:
        return tuple(int(v) for v in np.unique(self.views))

    @property
    def centroid(self) -> Array:
        return self.points.mean(axis=0)

    @property
    def aabb(self) -> tuple[Array, Array]:
        """Axis-aligned box (lo, hi)."""
        return self.points.min(axis=0), self.points.max(axis=0)

    @property
    def obb(self) -> tuple[Pose, Array]:
        """Upright oriented box: (world_T_box with z = up and x along the 2-D main axis, extents)."""
        up = self.up / np.linalg.norm(self.up)
        helper = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(up, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(up, e1)
        centered = self.points - self.centroid
        uv = np.column_stack([centered @ e1, centered @ e2])
        if len(uv) >= 2:
            _, vecs = np.linalg.eigh(np.cov(uv.T) + 1e-12 * np.eye(2))
            major = vecs[:, -1]
        else:
            major = np.array([1.0, 0.0])
        x = major[0] * e1 + major[1] * e2
        y = np.cross(up, x)
        rotation = np.column_stack([x, y, up])
        local = centered @ rotation
        lo, hi = local.min(axis=0), local.max(axis=0)
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = self.centroid + rotation @ (0.5 * (lo + hi))
        return pose, hi - lo

    def in_view(self, view: int) -> np.ndarray:
        """Mask of the points seen in ``view``."""
        return self.views == view

    def subset(self, mask: np.ndarray) -> Cluster:
        """The cluster restricted to the points in ``mask`` (same id)."""
        return Cluster(self.id, self.points[mask], self.normals[mask], self.views[mask], self.beams[mask],
                       self.up.copy())

    def only_view(self, view: int) -> Cluster:
        """The points of one view (per-view recognition for multi-view fusion)."""
        return self.subset(self.in_view(view))

    def main_view(self) -> int:
        """The view that contributed most points."""
        ids, counts = np.unique(self.views, return_counts=True)
        return int(ids[np.argmax(counts)])

    def describe(self) -> dict[str, Any]:
        lo, hi = self.aabb
        return {"id": self.id, "points": len(self.points), "views": list(self.view_ids),
                "centroid": self.centroid.round(4).tolist(), "aabb": [lo.round(4).tolist(), hi.round(4).tolist()]}


@dataclass
class Segmentation:
    """The result of a segmenter: the support plane (or None) and the clusters above it."""

    table: Table | None
    clusters: list[Cluster]
    diagnostics: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Cloud:
    """Points from one or more scans with, per point, the sensor origin, view id and beam index, and
    the normal the scan's depth processing gave it (NaN where none)."""

    points: Points3
    origins: Points3
    views: np.ndarray
    beams: np.ndarray
    normals: Points3 | None = None

    @classmethod
    def from_scans(cls, scans: Scan | Sequence[Scan], view_ids: Sequence[int] | None = None) -> Cloud:
        scans = [scans] if isinstance(scans, Scan) else list(scans)
        ids = list(view_ids) if view_ids is not None else list(range(len(scans)))
        if len(ids) != len(scans):
            raise ValueError("one view id per scan")
        parts = []
        for view, scan in zip(ids, scans, strict=True):
            hit = np.flatnonzero(scan.hits)
            pts = scan.origins[hit] + scan.directions[hit] * scan.ranges[hit, None]
            normals = scan.normals[hit] if scan.normals is not None else np.full((len(hit), 3), np.nan)
            parts.append((pts, scan.origins[hit], np.full(len(hit), view, dtype=np.int64), hit.astype(np.int64),
                          normals))
        if not parts:
            return cls(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
        return cls(*(np.concatenate([p[i] for p in parts]) for i in range(5)))

    def subset(self, mask: np.ndarray) -> Cloud:
        return Cloud(self.points[mask], self.origins[mask], self.views[mask], self.beams[mask],
                     None if self.normals is None else self.normals[mask])


class PlaneClusterSegmenter(Segmenter):
    """Support plane by RANSAC, table hull prism, Euclidean clusters (Görner Ch. 3)."""

    name = "plane_clusters"

    def __init__(
        self,
        distance_threshold: float = 0.02,
        success_probability: float = 0.99,
        inlier_fraction: float = 1.0 / 3.0,
        min_plane_height: float = 0.2,
        max_tilt_deg: float = 20.0,
        max_planes: int = 3,
        table_tolerance: float = 0.03,
        min_table_points: int = 200,
        min_height: float = 0.01,
        max_height: float = 0.5,
        cluster_tolerance: float = 0.05,
        min_cluster_size: int = 20,
        normal_radius: float = 0.01,
        seed: int = 0,
    ) -> None:
        self.distance_threshold = distance_threshold
        self.success_probability = success_probability
        self.inlier_fraction = inlier_fraction
        self.min_plane_height = min_plane_height
        self.max_tilt_deg = max_tilt_deg
        self.max_planes = max_planes
        self.table_tolerance = table_tolerance
        self.min_table_points = min_table_points
        self.min_height = min_height
        self.max_height = max_height
        self.cluster_tolerance = cluster_tolerance
        self.min_cluster_size = min_cluster_size
        self.normal_radius = normal_radius
        self.seed = seed

    @property
    def iterations(self) -> int:
        return ransac_iterations(self.success_probability, self.inlier_fraction)

    def segment(self, scans: Scan | Sequence[Scan] | Cloud, view_ids: Sequence[int] | None = None,
                table: Table | None = None) -> Segmentation:
        """Segment one or several scans (their points are fused) into a table and clusters.

        With ``table`` (e.g. the support plane found in earlier views) the plane of this view
        is still searched, and merged into it (Görner's table tracking: the hull grows) when it
        is the same plane; a view that sees too little of the table uses ``table`` as it is.
        """
        cloud = scans if isinstance(scans, Cloud) else Cloud.from_scans(scans, view_ids)
        diag: dict[str, Any] = {"points": len(cloud.points), "ransac_iterations": self.iterations}
        above_floor = cloud.points[:, 2] >= self.min_plane_height
        found = self.find_table(cloud.points[above_floor], diag)
        on_floor = table is not None and table.height < self.min_plane_height
        if found is not None and on_floor:
            table, diag["table"] = None, "replaces the floor"  # the floor was the support for want of a table
        elif found is None and (table is None or on_floor) and not above_floor.all():
            found = self.find_table(cloud.points, diag)  # no table: the objects stand on the floor
            diag["support"] = "floor"
        if table is not None:
            same = found is not None and same_plane(found, table, 2.0 * self.distance_threshold)
            diag["table"] = "merged" if same else "kept"
            table = merge_tables(table, found) if same else table
        else:
            table = found
        if table is None:
            return Segmentation(None, [], diag)
        h = table.heights(cloud.points)
        above = (h > self.min_height) & (h <= self.max_height)
        above[above] = table.inside(cloud.points[above])
        objects = cloud.subset(above)
        diag["object_points"] = len(objects.points)
        clusters = self.cluster(objects, up=table.normal)
        diag["clusters"] = len(clusters)
        return Segmentation(table, clusters, diag)

    __call__ = segment

    def find_table(self, points: Points3, diag: dict[str, Any] | None = None) -> Table | None:
        """The support plane: RANSAC, connectivity, refit, hull; None if there is none."""
        import open3d as o3d

        diag = {} if diag is None else diag
        remaining = np.arange(len(points))
        for attempt in range(self.max_planes):
            if len(remaining) < max(3, self.min_table_points):
                break
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[remaining]))
            with open3d_serial():  # RANSAC with per-thread generators
                o3d.utility.random.seed(self.seed + attempt)
                plane, inliers = cloud.segment_plane(
                    self.distance_threshold, 3, self.iterations, probability=self.success_probability
                )
            plane = np.asarray(plane, dtype=float)
            plane /= np.linalg.norm(plane[:3])
            inliers = remaining[np.asarray(inliers, dtype=np.int64)]
            if plane[:3] @ WORLD_UP < 0:
                plane = -plane
            tilt = math.degrees(math.acos(min(1.0, abs(float(plane[:3] @ WORLD_UP)))))
            if tilt <= self.max_tilt_deg and len(inliers) >= self.min_table_points:
                table = self._table_from_inliers(points[inliers], diag)
                if table is not None:
                    diag["plane_attempts"] = attempt + 1
                    return table
            remaining = np.setdiff1d(remaining, inliers, assume_unique=True)
        diag["plane_attempts"] = self.max_planes
        return None

    def _table_from_inliers(self, inlier_points: Points3, diag: dict[str, Any]) -> Table | None:
        from scipy.spatial import ConvexHull, QhullError

        labels = euclidean_clusters(inlier_points, self.table_tolerance, self.min_table_points)
        if not np.any(labels == 0):
            return None
        top = inlier_points[labels == 0]
        plane = fit_plane_lsq(top)
        for _ in range(3):  # refit on the points close to the plane (robust to object bottoms)
            residual = np.abs(top @ plane[:3] + plane[3])
            band = max(3.0 * float(np.median(residual)) * 1.4826, 0.002)
            close = top[residual <= band]
            if len(close) < 3:
                break
            plane = fit_plane_lsq(close)
        if plane[:3] @ WORLD_UP < 0:
            plane = -plane
        normal = plane[:3]
        # table frame: z = normal, x = main axis of the inliers in the plane
        center = top.mean(axis=0)
        center = center - (center @ normal + plane[3]) * normal
        helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(normal, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)
        uv = np.column_stack([(top - center) @ e1, (top - center) @ e2])
        _, vecs = np.linalg.eigh(np.cov(uv.T))
        x = vecs[0, 1] * e1 + vecs[1, 1] * e2
        rotation = np.column_stack([x, np.cross(normal, x), normal])
        world_T_table = np.eye(4)
        world_T_table[:3, :3] = rotation
        world_T_table[:3, 3] = center
        local = (top - center) @ rotation[:, :2]
        try:
            hull = ConvexHull(local)
        except QhullError:
            return None
        diag["table_inliers"] = len(top)
        return Table(plane, world_T_table, local[hull.vertices], len(top))

    def cluster(self, objects: Cloud, up: Array = WORLD_UP, first_id: int = 0) -> list[Cluster]:
        """Euclidean clusters of the object points, with oriented normals."""
        labels = euclidean_clusters(objects.points, self.cluster_tolerance, self.min_cluster_size)
        normals = estimate_normals(objects.points, max(self.normal_radius, 1e-4), objects.origins)
        if objects.normals is not None:  # the organised image's normals where the depth processing gave them
            given = np.isfinite(objects.normals[:, 0])
            normals[given] = objects.normals[given]
        clusters = []
        for label in range(labels.max(initial=-1) + 1):
            mask = labels == label
            clusters.append(Cluster(first_id + label, objects.points[mask], normals[mask], objects.views[mask],
                                    objects.beams[mask], np.asarray(up, dtype=float).copy()))
        return clusters


def merge_clusters(clusters: Sequence[Cluster], tolerance: float) -> list[Cluster]:
    """Merge clusters (e.g. from several views) whose points come closer than ``tolerance``.

    Görner associates object views by overlapping 2-D hulls; merging by point proximity
    is the 3-D equivalent for registered views. Ids are reassigned in input order.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(clusters)
    if n == 0:
        return []
    trees = [cKDTree(c.points) for c in clusters]
    rows, cols = [], []
    for i in range(n):
        lo_i, hi_i = clusters[i].aabb
        for j in range(i + 1, n):
            lo_j, hi_j = clusters[j].aabb
            if np.any(lo_i - tolerance > hi_j) or np.any(lo_j - tolerance > hi_i):
                continue
            d, _ = trees[j].query(clusters[i].points, k=1, distance_upper_bound=tolerance)
            if np.any(np.isfinite(d)):
                rows.append(i)
                cols.append(j)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    out = []
    for new_id, label in enumerate(dict.fromkeys(labels.tolist())):
        members = [c for c, lab in zip(clusters, labels, strict=True) if lab == label]
        out.append(Cluster(
            new_id,
            np.vstack([c.points for c in members]),
            np.vstack([c.normals for c in members]),
            np.concatenate([c.views for c in members]),
            np.concatenate([c.beams for c in members]),
            members[0].up.copy(),
        ))
    return out
