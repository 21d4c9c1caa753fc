"""Ground-truth metrics: observable surface, c_a, RMS error, Chamfer, AUC, path length."""

from __future__ import annotations

import time

import numpy as np
import pytest

from explore.core import look_at
from explore.mapping import (
    GroundTruthMetrics,
    SelectionTimer,
    chamfer,
    coverage,
    coverage_auc,
    observable_surface,
    path_length,
    rms_error,
    sample_surface,
)
from explore.sim import ScanPath, TriMesh, sphere_mesh


@pytest.fixture(scope="module")
def bunny(open_world):

    with open_world("bunny_pedestal") as sim:
        yield sim, GroundTruthMetrics(sim)


def test_sample_surface_is_uniform_and_deterministic() -> None:
    mesh = sphere_mesh(0.05, 30)
    a, na = sample_surface(mesh, 2e-6, seed=3)
    b, _ = sample_surface(mesh, 2e-6, seed=3)
    np.testing.assert_array_equal(a, b)
    assert len(a) == pytest.approx(mesh.area() / 2e-6, rel=1e-3)
    # upper and lower halves get equal shares; normals point outwards
    assert np.mean(a[:, 2] > 0) == pytest.approx(0.5, abs=0.02)
    assert np.all(np.einsum("ij,ij->i", na, a) > 0)


def test_coverage_rms_chamfer_on_simple_sets() -> None:
    mesh = sphere_mesh(0.05, 40)
    gt, normals = sample_surface(mesh, 2e-6, seed=0)
    other, _ = sample_surface(mesh, 1e-6, seed=1)
    assert coverage(other, gt) == 1.0
    assert coverage(np.zeros((0, 3)), gt) == 0.0
    half = other[other[:, 0] > 0]
    assert coverage(half, gt, tau=0.003) == pytest.approx(0.5 + 0.003 / 0.1, abs=0.02)
    assert rms_error(other, mesh) < 1e-4  # polygon vs samples of the same polygon
    assert rms_error(gt + 0.001 * normals, mesh) == pytest.approx(0.001, rel=0.02)
    assert chamfer(gt, gt) == 0.0
    grid = np.stack(np.meshgrid(*[np.arange(5) * 0.01] * 3), -1).reshape(-1, 3)
    assert chamfer(grid, grid + [0.002, 0.0, 0.0]) == pytest.approx(0.002)
    assert chamfer(grid, grid[:1]) == pytest.approx(0.5 * np.linalg.norm(grid, axis=1).mean())


def test_coverage_auc_and_path_length() -> None:
    assert coverage_auc([0.5, 1.0], 4) == pytest.approx((0.5 + 1.0 + 1.0 + 1.0) / 4)
    assert coverage_auc([0.2, 0.4, 0.6, 0.8], 2) == pytest.approx(0.3)
    assert coverage_auc([], 5) == 0.0
    with pytest.raises(ValueError):
        coverage_auc([1.0], 0)
    a = look_at([1, 0, 0], [0, 0, 0])
    b = look_at([1, 1, 0], [0, 0, 0])
    assert path_length([a, b]) == pytest.approx(1.0)
    assert path_length([a]) == 0.0
    start, end = a.copy(), a.copy()
    end[:3, 3] += [0, 0, 0.3]
    assert path_length([b, ScanPath(start, end)]) == pytest.approx(1.0 + 0.3)
    timer = SelectionTimer()
    with timer.measure():
        time.sleep(0.01)
    assert timer.seconds and timer.mean >= 0.009 and timer.total == pytest.approx(timer.mean)


def test_observable_surface_of_a_mesh_without_simulation() -> None:
    mesh = TriMesh(sphere_mesh(0.05, 30).vertices + [0, 0, 0.5], sphere_mesh(0.05, 30).triangles)
    points = observable_surface(gt_mesh=mesh, min_range=0.15, max_range=0.5, view_distance=0.3,
                                max_incidence_deg=80.0, n_views=128)
    all_points, normals = sample_surface(mesh)
    # views above the lowest point see all but a cap around the bottom pole (incidence > 80°)
    share = len(points) / len(all_points)
    assert 0.95 < share < 0.995
    bottom = all_points[normals[:, 2] < -0.995]
    assert len(bottom) > 10 and coverage(points, bottom, tau=1e-6) == 0.0
    # a sensor that cannot get within range sees nothing
    assert len(observable_surface(gt_mesh=mesh, min_range=0.4, max_range=0.5, view_distance=0.3)) == 0


def test_observable_bunny_surface(bunny) -> None:
    sim, metrics = bunny
    observable = metrics.observable
    assert 0.85 < metrics.observable_share < 0.99
    assert metrics.precompute_seconds < 5.0
    # the bottom resting on the pedestal is not observable
    samples, normals = sample_surface(sim.object_mesh())
    lo = sim.object_mesh().bounds[0]
    bottom = (samples[:, 2] < lo[2] + 1e-3) & (normals[:, 2] < -0.9)
    assert bottom.sum() > 50
    assert coverage(observable, samples[bottom], tau=1e-6) == 0.0
    # deterministic
    again = GroundTruthMetrics(sim)
    np.testing.assert_array_equal(again.observable, observable)


def test_ground_truth_itself_and_half_of_it(bunny) -> None:
    sim, metrics = bunny
    gt = sim.object_mesh()
    dense, _ = sample_surface(gt, 1e-6, seed=7)
    assert metrics.coverage(dense) == 1.0
    split = np.median(metrics.observable[:, 1])
    half = dense[dense[:, 1] > split]
    assert metrics.coverage(half) == pytest.approx(0.5, abs=0.03)
    result = metrics.evaluate(dense)
    assert result["coverage"] == 1.0 and result["rms_error"] < 1e-5 and result["chamfer"] < 1e-3
    empty = metrics.evaluate(np.zeros((0, 3)))
    assert empty["coverage"] == 0.0 and np.isnan(empty["rms_error"])


def test_noise_free_scans_are_accurate_and_coverage_rises(bunny) -> None:
    from explore.mapping import SurfaceModel
    from explore.sim import target_for

    sim, metrics = bunny
    sensor = sim.sensor
    saved = sensor.noise
    sensor.noise = "none"
    try:
        lo, hi = sim.object_mesh().bounds
        centre = 0.5 * (lo + hi)
        model = SurfaceModel(sim.spec.region_min, sim.spec.region_max)
        rng = np.random.default_rng(0)
        ca, raw = [], []
        for direction in [(1, 0, 0.3), (-1, 0, 0.3), (0, 1, 0.3), (0, -1, 0.3)]:
            d = np.asarray(direction, float) / np.linalg.norm(direction)
            scan = sensor.acquire(sim, target_for(sensor, centre + sensor.optimal_distance * d, centre, 0.3), rng)
            raw.append(scan.points())
            model.integrate(scan)
            ca.append(metrics.coverage(model.mesh.vertices))
        assert np.all(np.diff(ca) > 0), ca
        assert ca[-1] > 0.9
        assert metrics.rms_error(model.mesh.vertices) < 0.001  # mesh ē < 1 mm
        inside = np.vstack(raw)
        inside = inside[model.inside_region(inside)]
        assert metrics.rms_error(inside) < 1e-4  # the raw returns lie on the surface
        assert metrics.rms_error(model.points) < 5e-4
    finally:
        sensor.noise = saved
