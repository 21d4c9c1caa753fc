"""Simulated sensors: exact depth of a known plane, noise statistics, depth of field."""

from __future__ import annotations

import numpy as np
import pytest

from explore.core import look_at
from explore.sim import ScanPath, WorldSpec, load_world_spec, sigma_kinect, sigma_laser_poly

WALL = """
name: wall
environment:
  - {name: wall, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01]}
objects: []
region: {min: [-1, -1, 0], max: [1, 1, 1]}
sensor: depth_camera
"""


@pytest.fixture
def wall_sim(open_world, tmp_path):
    path = tmp_path / "wall.yaml"
    path.write_text(WALL)
    with open_world(load_world_spec(path)) as sim:
        yield sim


def _camera(registry, **params):
    return registry.create("sensor", "depth_camera", {"width": 64, "height": 48, **params})


def test_depth_camera_measures_a_plane_exactly_without_noise(wall_sim, registry, rng) -> None:
    camera = _camera(registry, noise="none", max_range=3.0)
    pose = look_at([0.1, -0.2, 1.25], [0.1, -0.2, 0.0])
    scan = camera.acquire(wall_sim, pose, rng)
    assert scan.hits.all()
    points = scan.points()
    np.testing.assert_allclose(points[:, 2], 0.0, atol=1e-6)
    depth = (points - pose[:3, 3]) @ pose[:3, 2]
    np.testing.assert_allclose(depth, 1.25, atol=1e-6)


def test_depth_camera_noise_has_the_model_standard_deviation(wall_sim, registry, rng) -> None:
    camera = registry.create(
        "sensor", "depth_camera", {"width": 160, "height": 120, "noise": "kinect", "max_range": 3.0}
    )
    pose = look_at([0.0, 0.0, 2.0], [0.0, 0.0, 0.0])
    exact = camera.acquire(wall_sim, pose, rng)
    true_range = 2.0 / (exact.directions @ pose[:3, 2])
    residual = (exact.ranges - true_range) / sigma_kinect(true_range)
    assert abs(residual.mean()) < 0.03
    assert residual.std() == pytest.approx(1.0, abs=0.02)
    assert sigma_kinect(np.array(2.0)) == pytest.approx(1.425e-3 * 4)
    np.testing.assert_allclose(exact.sigmas, sigma_kinect(exact.ranges))


def test_laser_polynomial_matches_thesis_eq_4_39() -> None:
    # sigma(250 mm) = 0.005 + 0.125 + 0.64125 + 0.0312 + 0.00494 mm
    assert sigma_laser_poly(np.array(0.25)) * 1000 == pytest.approx(0.80739, rel=1e-4)


def test_no_return_is_reported_as_such(wall_sim, registry, rng) -> None:
    camera = _camera(registry, noise="none", max_range=1.0)
    scan = camera.acquire(wall_sim, look_at([0.0, 0.0, 1.5], [0.0, 0.0, 0.0]), rng)
    assert not scan.hits.any() and np.isnan(scan.ranges).all()
    assert len(scan.points()) == 0


def test_striper_respects_its_depth_of_field(wall_sim, registry, rng) -> None:
    striper = registry.create("sensor", "laser_striper", {"noise": "none"})
    assert striper.stripe_width == pytest.approx(2 * 0.325 * np.tan(np.deg2rad(12)), rel=1e-6)
    for height, expect_hits in [(0.10, False), (0.30, True), (0.45, True), (0.55, False)]:
        pose = look_at([0.0, 0.0, height], [0.0, 0.0, 0.0])
        scan = striper.acquire(wall_sim, pose, rng)
        hits = scan.hits
        if expect_hits:
            assert hits.sum() >= 0.9 * len(scan), height
            assert np.nanmin(scan.ranges) >= striper.min_range and np.nanmax(scan.ranges) <= striper.max_range
        else:
            assert not hits.any(), height
    assert not scan.clear_from_origin  # triangulation: never proves space below min range free


def test_striper_sweeps_one_stripe_per_frame(wall_sim, registry, rng) -> None:
    striper = registry.create("sensor", "laser_striper", {"noise": "none", "speed": 0.1})
    start = look_at([-0.1, 0.0, 0.3], [-0.1, 0.0, 0.0])
    end = start.copy()
    end[:3, 3] = [0.1, 0.0, 0.3]
    scan = striper.acquire(wall_sim, ScanPath(start, end, 0.1), rng)
    frames = len(scan.sensor_poses)
    assert frames == int(np.ceil(0.2 / 0.1 * 25)) + 1
    assert len(scan) == frames * 224
    assert scan.timestamps[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(scan.points()[:, 2], 0.0, atol=1e-6)


def test_colour_comes_from_the_renderer(open_world, registry, rng) -> None:
    with open_world("tabletop") as sim:
        camera = _camera(registry, color=True, noise="none")
        scan = camera.acquire(sim, look_at([0.0, -0.9, 1.35], [0.0, 0.0, 0.65]), rng)
        assert scan.colors is not None and scan.colors.shape == (len(scan), 3)
        assert scan.colors[scan.hits].std() > 5  # not a flat image
        assert len(scan.to_open3d().colors) == scan.hits.sum()


def test_world_spec_is_a_value(tmp_path) -> None:
    path = tmp_path / "w.yaml"
    path.write_text(WALL)
    spec = load_world_spec(path)
    assert isinstance(spec, WorldSpec) and spec.sensor.plugin == "depth_camera"
    np.testing.assert_allclose(spec.region_size, [2, 2, 1])
