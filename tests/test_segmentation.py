"""Segmentation: support plane, clusters vs ground truth, views, bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from explore.core import look_at
from explore.perception import Cloud, Cluster, euclidean_clusters, merge_clusters, ransac_iterations

TABLE_TOP = 0.625  # m, pybullet_data table.urdf at z = 0.3125 (see worlds/tabletop.yaml)
MIN_HEIGHT = 0.01


@pytest.fixture(scope="module")
def overview(tabletop):
    ov = tabletop.spec.overview
    return tabletop.sensor.acquire(tabletop, look_at(ov[:3], ov[3:]), np.random.default_rng(0))


@pytest.fixture(scope="module")
def segmenter(registry):
    return registry.create("segmenter", "plane_clusters", {"scale": "table"})


@pytest.fixture(scope="module")
def segmentation(segmenter, overview):
    return segmenter.segment(overview)


def visible_objects(sim, scan, min_points: int) -> dict[str, np.ndarray]:
    """Ground-truth visible surface points (above the object cut) of each object in ``scan``."""
    t_hit, index, _ = sim.raycaster.cast(scan.origins, scan.directions)
    hit = scan.hits & (index >= 0)
    points = scan.origins + scan.directions * t_hit[:, None]
    out = {}
    for i, body in enumerate(sim.bodies):
        if not body.is_object:
            continue
        mask = hit & (index == i) & (points[:, 2] > TABLE_TOP + MIN_HEIGHT)
        if mask.sum() >= min_points:
            out[body.name] = points[mask]
    return out


def test_ransac_iterations_formula():
    # Görner: p = 0.99, w = 1/3 gives about 122 (he used 125)
    assert ransac_iterations(0.99, 1.0 / 3.0) == math.ceil(math.log(0.01) / math.log(1 - 1 / 27))
    assert 120 <= ransac_iterations(0.99, 1.0 / 3.0) <= 125
    assert ransac_iterations(0.99, 1.0) == 1


def test_table_plane_normal_and_height(segmentation):
    table = segmentation.table
    assert table is not None
    tilt = math.degrees(math.acos(float(table.normal @ np.array([0.0, 0.0, 1.0]))))
    assert tilt < 2.0
    assert abs(table.height - TABLE_TOP) < 0.005
    # the hull covers the visible table top (1.5 m x 1.0 m) at least in part, and its centre is inside
    assert table.inside(table.world_T_table[:3, 3][None]).all()
    assert len(table.hull) >= 4


def test_clusters_match_visible_objects(tabletop, overview, segmenter, segmentation):
    visible = visible_objects(tabletop, overview, segmenter.min_cluster_size)
    assert len(visible) == 6
    assert len(segmentation.clusters) == len(visible)
    matched = set()
    for cluster in segmentation.clusters:
        distances = {name: np.linalg.norm(cluster.centroid - pts.mean(axis=0)) for name, pts in visible.items()}
        name = min(distances, key=distances.get)
        assert distances[name] < 0.03, (name, distances[name])
        matched.add(name)
        lo, hi = cluster.aabb
        assert np.all(lo <= cluster.centroid) and np.all(cluster.centroid <= hi)
        pose, extent = cluster.obb
        assert abs(pose[2, 2] - 1.0) < 1e-2 and np.all(extent > 0)
        assert cluster.view_ids == (0,)
        # normals point towards the sensor
        assert np.mean(np.einsum("ij,ij->i", cluster.normals, overview.origins[0] - cluster.points) > 0) > 0.99
    assert matched == set(visible)


def test_two_views_fused_and_merged(tabletop, overview, segmenter):
    other = tabletop.sensor.acquire(tabletop, look_at([0.0, 0.9, 1.35], [0.0, 0.0, 0.65]), np.random.default_rng(1))
    fused = segmenter.segment([overview, other])
    assert len(fused.clusters) == 6
    assert all(c.view_ids == (0, 1) for c in fused.clusters)
    per_view = segmenter.segment([other], view_ids=[1]).clusters + segmenter.segment(overview).clusters
    merged = merge_clusters(per_view, segmenter.cluster_tolerance)
    assert len(per_view) == 12 and len(merged) == 6
    assert sorted(c.view_ids for c in merged) == [(0, 1)] * 6


def test_empty_scene(tabletop, segmenter):
    scan = tabletop.sensor.acquire(tabletop, look_at([0.0, 0.0, 2.0], [0.0, 0.0, 3.0]), np.random.default_rng(0))
    assert not scan.hits.any()
    result = segmenter.segment(scan)
    assert result.table is None and result.clusters == []
    assert segmenter.segment([]).clusters == []


def test_table_without_objects(segmenter):
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.5, 0.5, size=(5000, 2))
    points = np.column_stack([xy, np.full(5000, 0.7) + rng.normal(0, 0.001, 5000)])
    cloud = Cloud(points, np.tile([0.0, -1.0, 1.5], (5000, 1)), np.zeros(5000, np.int64), np.arange(5000))
    result = segmenter.segment(cloud)
    assert result.table is not None and abs(result.table.height - 0.7) < 0.002
    assert result.clusters == []


def _cloud(*parts: np.ndarray) -> Cloud:
    points = np.vstack(parts)
    n = len(points)
    return Cloud(points, np.tile([0.0, -1.0, 1.5], (n, 1)), np.zeros(n, np.int64), np.arange(n))


def _slab(rng, lo, hi, n: int) -> np.ndarray:
    return rng.uniform(lo, hi, size=(n, 3))


def test_objects_on_the_floor_stand_on_it_only_when_no_table_does(segmenter):
    """The floor cut keeps the floor from being taken for the table; with no plane above it, the
    floor is the support and a box standing on it is the one cluster."""
    rng = np.random.default_rng(0)
    floor = _slab(rng, [-0.5, -0.5, -0.001], [0.5, 0.5, 0.001], 6000)
    box = _slab(rng, [0.1, 0.1, 0.015], [0.16, 0.16, 0.06], 600)  # 6 cm box on the floor
    result = segmenter.segment(_cloud(floor, box))
    assert result.table is not None and abs(result.table.height) < 0.002
    assert result.diagnostics["support"] == "floor"
    assert len(result.clusters) == 1 and len(result.clusters[0].points) == 600
    table = _slab(rng, [-0.4, -0.4, 0.699], [0.0, 0.0, 0.701], 4000)
    mug = _slab(rng, [-0.2, -0.2, 0.72], [-0.15, -0.15, 0.8], 300)
    result = segmenter.segment(_cloud(floor, box, table, mug))
    assert abs(result.table.height - 0.7) < 0.002 and "support" not in result.diagnostics
    assert len(result.clusters) == 1 and len(result.clusters[0].points) == 300
    # a later view that shows only the floor keeps the tracked table and finds nothing on the floor
    result = segmenter.segment(_cloud(floor, box), table=result.table)
    assert abs(result.table.height - 0.7) < 0.002 and result.clusters == []
    # a table seen after the floor was taken for the support (a first view that missed it) replaces it
    on_floor = segmenter.segment(_cloud(floor, box)).table
    result = segmenter.segment(_cloud(floor, table, mug), table=on_floor)
    assert abs(result.table.height - 0.7) < 0.002 and len(result.clusters) == 1


def test_euclidean_clusters_separate_and_drop_small():
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0, 0], 0.005, (200, 3))
    b = rng.normal([0.2, 0, 0], 0.005, (100, 3))
    c = rng.normal([0.5, 0, 0], 0.005, (5, 3))
    labels = euclidean_clusters(np.vstack([a, b, c]), 0.02, min_size=20)
    assert set(labels[:200]) == {0} and set(labels[200:300]) == {1} and set(labels[300:]) == {-1}


def test_touching_objects_form_one_cluster(touching_world):
    sim, scan, segmentation = touching_world
    assert len(segmentation.clusters) == 1
    cluster: Cluster = segmentation.clusters[0]
    lo, hi = cluster.aabb
    for body in sim.objects():
        center = 0.5 * sum(body.mesh.bounds)
        assert np.all(center[:2] >= lo[:2] - 0.01) and np.all(center[:2] <= hi[:2] + 0.01)


TOUCHING_WORLD = Path(__file__).parent / "worlds" / "touching.yaml"


@pytest.fixture(scope="module")
def touching_world(open_world, registry):
    """A duck with a block pressed against its side; overview scan and segmentation."""
    sim = open_world(str(TOUCHING_WORLD))
    scan = sim.sensor.acquire(sim, look_at([0.05, -0.9, 1.3], [0.05, -0.18, 0.65]), np.random.default_rng(0))
    segmenter = registry.create("segmenter", "plane_clusters", {"scale": "table"})
    yield sim, scan, segmenter.segment(scan)
    sim.close()
