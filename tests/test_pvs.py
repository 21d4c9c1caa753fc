"""Probabilistic voxel space: Bayes update, sensor semantics, traversal, queries, OctoMap agreement."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from explore.mapping import FREE, OCCUPIED, PVS, THRESHOLDS, UNKNOWN, entropy_bits, logit, traverse
from explore.sim import Scan

RES = 0.01


def make_scan(
    origins: np.ndarray,
    directions: np.ndarray,
    ranges: np.ndarray,
    sigmas: np.ndarray | None = None,
    min_range: float = 0.0,
    max_range: float = 1.0,
    clear_from_origin: bool = True,
    no_return_clears: bool = True,
) -> Scan:
    origins = np.atleast_2d(np.asarray(origins, dtype=float))
    directions = np.atleast_2d(np.asarray(directions, dtype=float))
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(origins, directions.shape).copy()
    ranges = np.asarray(ranges, dtype=float).reshape(-1)
    n = len(ranges)
    pose = np.eye(4)
    pose[:3, 3] = origins[0]
    return Scan(
        origins=origins,
        directions=directions,
        ranges=ranges,
        sigmas=np.zeros(n) if sigmas is None else np.asarray(sigmas, dtype=float),
        sensor_poses=pose[None],
        timestamps=np.zeros(1),
        frame_of_beam=np.zeros(n, dtype=np.int64),
        min_range=min_range,
        max_range=max_range,
        clear_from_origin=clear_from_origin,
        no_return_clears=no_return_clears,
    )


def bayes(p: float, n: int, clamp: tuple[float, float]) -> float:
    """Closed-form posterior after n identical measurements from p = 0.5, clamped per step."""
    lo = 0.0
    for _ in range(n):
        lo = min(max(lo + logit(p), logit(clamp[0])), logit(clamp[1]))
    return 1.0 / (1.0 + math.exp(-lo))


def beam_pvs(mode: str) -> tuple[PVS, Scan]:
    """A 1 cm grid and one beam along +x from the centre of voxel 0 with a return at 0.1 m.

    The return lies at the centre of voxel 10 (x in [0.10, 0.11]).
    """
    pvs = PVS([0.0, 0.0, 0.0], [0.3, 0.02, 0.02], RES, mode=mode)
    scan = make_scan([0.005, 0.005, 0.005], [1.0, 0.0, 0.0], [0.1])
    return pvs, scan


@pytest.mark.parametrize("n", [1, 2, 3, 5, 12])
def test_single_beam_sensor_model_matches_closed_form_bayes(n: int) -> None:
    pvs, scan = beam_pvs("sensor_model")
    for _ in range(n):
        pvs.integrate(scan)
    p = 1.0 / (1.0 + np.exp(-pvs.log_odds[:, 0, 0].astype(float)))
    clamp = pvs.clamp
    assert pvs.clamp == (0.02, 0.98)
    # before d - k sigma (sigma floored to half a voxel: band = 1 cm): free updates
    np.testing.assert_allclose(p[:9], bayes(0.4, n, clamp), atol=1e-5)
    # the voxel holding the return: full hit weight
    assert p[10] == pytest.approx(bayes(0.7, n, clamp), abs=1e-5)
    # its neighbours lie 5 mm = 1 sigma from d: hit weighted by exp(-1/2)
    weighted = 1.0 / (1.0 + math.exp(-math.exp(-0.5) * logit(0.7)))
    assert p[9] == pytest.approx(bayes(weighted, n, clamp), abs=1e-5)
    assert p[11] == pytest.approx(bayes(weighted, n, clamp), abs=1e-5)
    # behind the band: nothing
    np.testing.assert_array_equal(p[12:], 0.5)
    assert np.all(pvs.log_odds[:, 1, :] == 0.0)


@pytest.mark.parametrize("n", [1, 4, 9])
def test_single_beam_octomap_mode_matches_closed_form_bayes(n: int) -> None:
    pvs, scan = beam_pvs("octomap")
    for _ in range(n):
        pvs.integrate(scan)
    p = 1.0 / (1.0 + np.exp(-pvs.log_odds[:, 0, 0].astype(float)))
    assert pvs.clamp == (0.12, 0.97)
    np.testing.assert_allclose(p[:10], bayes(0.4, n, (0.12, 0.97)), atol=1e-5)
    assert p[10] == pytest.approx(bayes(0.7, n, (0.12, 0.97)), abs=1e-5)
    np.testing.assert_array_equal(p[11:], 0.5)


@pytest.mark.parametrize("hit_wins", [True, False])
def test_hit_wins_within_a_frame(hit_wins: bool) -> None:
    """A voxel in the band of one return is not freed by another beam of the same frame."""
    pvs = PVS([0.0, 0.0, 0.0], [0.3, 0.02, 0.02], RES, hit_wins=hit_wins)
    scan = make_scan([0.005, 0.005, 0.005], [[1.0, 0.0, 0.0]] * 2, [0.1, 0.2])
    pvs.integrate(scan)
    line = pvs.log_odds[:, 0, 0]
    expected = logit(0.7) + (0.0 if hit_wins else logit(0.4))
    assert line[10] == pytest.approx(expected, abs=1e-6)
    assert line[5] == pytest.approx(2 * logit(0.4), abs=1e-6)  # both beams free it
    assert line[20] == pytest.approx(logit(0.7), abs=1e-6)


def fan(eye: np.ndarray, plane_x: float, count: int = 7) -> Scan:
    """Beams from ``eye`` to a grid of points on the plane x = plane_x (returns on the plane)."""
    ys, zs = np.meshgrid(np.linspace(0.06, 0.14, count), np.linspace(0.06, 0.14, count))
    targets = np.column_stack([np.full(ys.size, plane_x), ys.ravel(), zs.ravel()])
    vectors = targets - eye
    ranges = np.linalg.norm(vectors, axis=1)
    return make_scan(eye, vectors, ranges, sigmas=np.full(len(ranges), 1e-3), max_range=2.0)


def test_wall_seen_from_two_sides() -> None:
    pvs = PVS([0.0, 0.0, 0.0], [0.4, 0.2, 0.2], RES)
    wall_x = 0.2047  # inside voxel column ix = 20
    left = fan(np.array([0.02, 0.1, 0.1]), wall_x)
    right = fan(np.array([0.38, 0.1, 0.1]), wall_x)
    for _ in range(8):  # 8 x logit(0.4) < logit(0.05) on voxels only one beam crosses
        pvs.integrate(left)
    line = pvs.log_odds[:, 10, 10]
    prob = 1.0 / (1.0 + np.exp(-line.astype(float)))
    assert prob[20] >= THRESHOLDS["feature"][1]  # the wall: occupied (feature threshold)
    assert np.all(prob[3:19] < THRESHOLDS["planning"][0])  # in front: free for planning
    assert np.all(line[22:] == 0.0)  # behind the band: untouched, unknown
    for _ in range(8):
        pvs.integrate(right)
    line = pvs.log_odds[:, 10, 10]
    prob = 1.0 / (1.0 + np.exp(-line.astype(float)))
    assert prob[20] >= 0.95
    assert np.all(prob[3:19] < 0.05) and np.all(prob[22:37] < 0.05)  # both sides free
    # the occupied layer (p >= 0.75) is the wall voxel plus at most the two band neighbours
    occupied = np.flatnonzero(prob >= 0.75)
    assert 20 in occupied and occupied.min() >= 19 and occupied.max() <= 21
    states = pvs.state(pvs.centers(np.array([[20, 10, 10], [10, 10, 10], [30, 10, 10]])), "validation")
    np.testing.assert_array_equal(states, [OCCUPIED, FREE, FREE])


@pytest.mark.parametrize("kind", ["depth_camera", "laser_striper"])
def test_no_return_semantics_camera_vs_striper(registry, kind: str) -> None:
    sensor = registry.create("sensor", kind)
    pvs = PVS([0.0, 0.0, 0.0], [4.0, 0.02, 0.02], RES)
    origin = [0.005, 0.005, 0.005]
    nothing = make_scan(origin, [1.0, 0.0, 0.0], [np.nan], min_range=sensor.min_range,
                        max_range=sensor.max_range, clear_from_origin=sensor.clear_from_origin,
                        no_return_clears=sensor.no_return_clears)
    pvs.integrate(nothing)
    line = pvs.log_odds[:, 0, 0]
    t_in = np.arange(len(line)) * RES - 0.005  # ray parameter where voxel i starts
    t_out = t_in + RES
    freed = line < 0.0
    inside = (t_out <= sensor.max_range + 1e-9) & ((t_in >= sensor.min_range - 1e-9) | sensor.clear_from_origin)
    np.testing.assert_array_equal(freed, inside)
    np.testing.assert_array_equal(line[~inside], 0.0)
    if kind == "depth_camera":
        assert sensor.clear_from_origin and freed[0]  # freed from the origin
    else:
        assert not sensor.clear_from_origin
        assert not freed[: int(sensor.min_range / RES)].any()  # never below the minimum range
        # a return does not clear below the minimum range either
        pvs2 = PVS([0.0, 0.0, 0.0], [1.0, 0.02, 0.02], RES)
        hit = make_scan(origin, [1.0, 0.0, 0.0], [0.3], min_range=sensor.min_range,
                        max_range=sensor.max_range, clear_from_origin=False)
        pvs2.integrate(hit)
        line2 = pvs2.log_odds[:, 0, 0]
        assert np.all(line2[:15] == 0.0) and np.all(line2[16:28] < 0.0) and line2[30] > 0.0
    # a sensor that does not trust its no-returns changes nothing
    quiet = PVS([0.0, 0.0, 0.0], [4.0, 0.02, 0.02], RES)
    quiet.integrate(make_scan(origin, [1.0, 0.0, 0.0], [np.nan], max_range=sensor.max_range,
                              no_return_clears=False))
    assert not quiet.log_odds.any()


def seen_miss_scan(camera_blocked: bool) -> tuple[PVS, Scan]:
    """A striper beam along +x without a return (working range 0.15-0.5 m), its camera 8 cm along y; with
    ``camera_blocked`` an occupied wall (y = 1-2 cm, x from 0.25 m on) stands between the camera and the beam's
    far part: the camera's sight of the beam meets it from x = 0.25 / 0.875 = 0.286 m on."""
    pvs = PVS([0.0, -0.02, -0.02], [0.6, 0.12, 0.02], RES)
    if camera_blocked:
        lo, hi = pvs.index(np.array([[0.25, 0.015, -0.01], [0.6, 0.015, 0.01]]))[0]
        pvs.log_odds[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1] = logit(0.97)
    scan = make_scan([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [np.nan], min_range=0.15, max_range=0.5,
                     clear_from_origin=False, no_return_clears=False)
    return pvs, dataclasses.replace(scan, seen_from=np.array([0.0, 0.08, 0.0]))


def test_a_missing_return_frees_only_what_the_striper_camera_saw() -> None:
    """A surface on the laser's path where the camera sees it would have returned (PVS._seen_misses)."""
    pvs, scan = seen_miss_scan(camera_blocked=False)
    pvs.integrate(scan)
    line = pvs.log_odds[:, 2, 2]  # y = z = 0: the beam's voxels
    assert np.all(line[:15] == 0.0)  # nothing below the minimum range
    assert np.allclose(line[16:49], logit(0.4))  # one miss each up to the end of the working range
    assert np.all(line[51:] == 0.0)
    # a wall hides the beam beyond x = 0.286 m from the camera: a surface there could have been lost
    pvs, scan = seen_miss_scan(camera_blocked=True)
    pvs.integrate(scan)
    line = pvs.log_odds[:, 2, 2]
    assert np.flatnonzero(line < 0.0).tolist() == list(range(15, 28))
    # without the camera's evidence (or in OctoMap mode) a missing return frees nothing, as before
    quiet = PVS([0.0, -0.02, -0.02], [0.6, 0.12, 0.02], RES)
    quiet.integrate(dataclasses.replace(scan, seen_from=None))
    octomap = PVS([0.0, -0.02, -0.02], [0.6, 0.12, 0.02], RES, mode="octomap")
    octomap.integrate(seen_miss_scan(camera_blocked=False)[1])
    assert not quiet.log_odds.any() and not octomap.log_odds.any()


def brute_force_voxels(pvs: PVS, origin: np.ndarray, direction: np.ndarray, length: float) -> set:
    """Voxels hit by dense samples of the open segment (spacing 1/400 voxel).

    The end points are left out: a ray that only touches the box there has a zero-length
    intersection, which the traversal rightly skips.
    """
    t = np.linspace(0.0, length, int(length / pvs.resolution * 400) + 2)[1:-1]
    ijk, inside = pvs.index(origin + t[:, None] * direction)
    return {tuple(v) for v in ijk[inside]}


@settings(max_examples=150, deadline=None, derandomize=True)
@given(
    origin=st.tuples(*[st.floats(-0.05, 0.15, allow_nan=False)] * 3),
    direction=st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 3),
    length=st.floats(0.001, 0.3),
)
def test_traversal_equals_dense_sampling(origin: tuple, direction: tuple, length: float) -> None:
    d = np.asarray(direction)
    # measure-zero degeneracies: a ray lying in a voxel face with a 1e-79 tilt may be put
    # on either side; exactly axis-parallel rays (components 0.0) stay in the test
    assume(np.linalg.norm(d) > 1e-3 and not np.any((d != 0.0) & (np.abs(d) < 1e-6)))
    o, d, _ = PVS._rays(np.asarray(origin), d, length)  # the normalisation cast() uses
    o, d = o[0], d[0]
    pvs = PVS([0.0, 0.0, 0.0], [0.1, 0.08, 0.06], RES)
    voxels, segments = traverse(o, d, length, pvs.lattice, RES, np.asarray(pvs.shape))
    sampled = brute_force_voxels(pvs, o, d, length)
    found = {tuple(v) for v in voxels}
    assert len(found) == len(voxels)  # no voxel twice
    # consecutive voxels are face neighbours and the segments tile the clipped ray
    if len(voxels) > 1:
        assert np.all(np.abs(np.diff(voxels, axis=0)).sum(axis=1) == 1)
        np.testing.assert_allclose(segments[1:, 0], segments[:-1, 1], atol=1e-12)
    # every densely sampled voxel is traversed; every traversed voxel with a segment longer
    # than the sample spacing is sampled (shorter ones are corner grazes samples can miss)
    assert sampled <= found
    spacing = length / (int(length / RES * 400) + 1)
    long_enough = {tuple(v) for v, s in zip(voxels, segments, strict=True) if s[1] - s[0] > 2.5 * spacing}
    assert long_enough <= sampled
    # the batched query traverses the same voxels in the same order
    result = pvs.cast(o[None], d[None], length, return_voxels=True)
    np.testing.assert_array_equal(result.voxels(0), voxels)


def test_cast_entropy_counts_and_visited_marking() -> None:
    pvs = PVS([0.0, 0.0, 0.0], [0.2, 0.1, 0.1], RES)
    o, d = np.array([[0.005, 0.055, 0.055]]), np.array([[1.0, 0.0, 0.0]])
    result = pvs.cast(o, d, 0.2)
    assert result.visits[0] == 20 and result.unknown[0] == 20 and result.frontier[0] == 0
    assert result.entropy[0] == pytest.approx(20.0)  # unknown voxels carry 1 bit each
    assert not result.hit[0]
    pvs.log_odds[:5, 5, 5] = logit(0.02)  # free stretch in front
    pvs.log_odds[12, 5, 5] = logit(0.96)  # occluder at voxel 12
    result = pvs.cast(o, d, 0.2)
    assert result.hit_distance[0] == pytest.approx(0.115)
    np.testing.assert_array_equal(result.hit_voxel[0], [12, 5, 5])
    expected = 5 * entropy_bits(0.02) + 7 * 1.0 + entropy_bits(0.96)
    assert result.entropy[0] == pytest.approx(expected, rel=1e-5)
    assert result.unknown[0] == 7 and result.occupied[0] == 1 and result.frontier[0] == 1
    # visited marking: the same beam twice counts once; without it twice (IROS Eq. 2)
    twice_o, twice_d = np.repeat(o, 2, axis=0), np.repeat(d, 2, axis=0)
    assert pvs.entropy_gain(twice_o, twice_d, 0.2) == pytest.approx(expected, rel=1e-5)
    assert pvs.entropy_gain(twice_o, twice_d, 0.2, visited=False) == pytest.approx(2 * expected, rel=1e-5)
    n_v = pvs.log_odds.size - 5
    assert pvs.non_free_count() == n_v
    assert pvs.entropy_gain(o, d, 0.2, normalize=True) == pytest.approx(expected / n_v, rel=1e-5)


def test_parallel_and_serial_casts_agree() -> None:
    rng = np.random.default_rng(0)
    pvs = PVS([0.0, 0.0, 0.0], [0.2, 0.2, 0.2], RES)
    pvs.log_odds[:] = rng.normal(0.0, 2.0, pvs.shape).astype(np.float32)
    origins = rng.uniform(-0.1, 0.3, (300, 3))
    directions = rng.normal(size=(300, 3))
    a = pvs.cast(origins, directions, 0.4, parallel=True, return_voxels=True)
    b = pvs.cast(origins, directions, 0.4, parallel=False, return_voxels=True)
    for field in ("hit_distance", "hit_voxel", "entropy", "unknown", "occupied", "frontier", "voxel_ids"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert a.hit.sum() > 50 and a.frontier.sum() > 0


def test_named_thresholds_and_states() -> None:
    assert THRESHOLDS["planning"] == (0.05, 0.05)
    assert THRESHOLDS["feature"][1] == 0.95
    assert THRESHOLDS["validation"] == (0.25, 0.75)
    assert THRESHOLDS["vasquez"] == (0.45, 0.55)
    probs = np.array([0.04, 0.06, 0.24, 0.44, 0.5, 0.56, 0.75, 0.94, 0.95])
    pvs = PVS([0.0, 0.0, 0.0], [len(probs) * RES, RES, RES], RES)
    pvs.log_odds[:, 0, 0] = logit(probs)
    points = pvs.centers(np.column_stack([np.arange(len(probs)), np.zeros((len(probs), 2), int)]))
    np.testing.assert_allclose(pvs.probability(points), probs, atol=1e-6)
    F, U, X = FREE, UNKNOWN, OCCUPIED  # noqa: N806
    np.testing.assert_array_equal(pvs.state(points, "planning"), [F, X, X, X, X, X, X, X, X])
    np.testing.assert_array_equal(pvs.state(points, "feature"), [F, U, U, U, U, U, U, U, X])
    np.testing.assert_array_equal(pvs.state(points, "validation"), [F, F, F, U, U, U, X, X, X])
    np.testing.assert_array_equal(pvs.state(points, "vasquez"), [F, F, F, F, U, X, X, X, X])
    assert pvs.probability(np.array([[5.0, 5.0, 5.0]]))[0] == 0.5  # outside: unknown
    assert pvs.counts("validation") == {"unknown": 3, "free": 3, "occupied": 3}
    assert pvs.count(OCCUPIED, "vasquez") == 4


def test_grow_distance_field_mesh_and_export(tmp_path) -> None:
    pvs = PVS([0.0, 0.0, 0.0], [0.1, 0.1, 0.1], RES)
    pvs.log_odds[:] = logit(0.02)
    pvs.log_odds[5, 5, 5] = logit(0.9)
    pvs.grow([-0.05, 0.0, 0.0], [0.1, 0.12, 0.1])
    assert pvs.shape == (15, 12, 10) and np.allclose(pvs.origin, [-0.05, 0.0, 0.0])
    centre = np.array([[0.055, 0.055, 0.055]])
    assert pvs.probability(centre)[0] == pytest.approx(0.9, abs=1e-6)
    assert pvs.obstacle_grid().sum() == 1 + 5 * 10 * 10 + 15 * 2 * 10  # voxel + new unknown
    field = pvs.distance_field()
    assert field[10, 5, 5] == 0.0 and field[13, 5, 5] == pytest.approx(0.03)
    probe = np.array([[0.085, 0.055, 0.055], [0.065, 0.055, 0.055], [0.055, 0.055, 0.055]])
    np.testing.assert_array_equal(pvs.is_free(probe), [True, True, False])
    np.testing.assert_array_equal(pvs.is_free(probe, clearance=0.02), [True, False, False])
    np.testing.assert_allclose(pvs.occupied_points(), centre)
    mesh = pvs.voxel_mesh()
    assert mesh.vertices.shape == (8, 3) and mesh.triangles.shape == (12, 3)
    assert mesh.area() == pytest.approx(6 * RES**2)
    np.testing.assert_allclose(mesh.vertices.min(axis=0), [0.05, 0.05, 0.05])
    pvs.save_png(tmp_path / "pvs.png")
    assert (tmp_path / "pvs.png").stat().st_size > 1000


def test_save_load_round_trip_and_features(tmp_path) -> None:
    pvs = PVS.for_region([0.0, 0.0, 0.0], [0.2, 0.2, 0.2], RES, independence_filter=True)
    scan = fan(np.array([0.02, 0.1, 0.1]), 0.15)
    first = pvs.integrate(scan)
    assert first["rejected"] == 0 and first["used"] == 49
    assert pvs.integrate(scan)["rejected"] == 49  # the same beams again: not independent
    points = np.array([[0.155, 0.1, 0.1], [0.156, 0.101, 0.1], [0.155, 0.125, 0.1]])
    written = pvs.set_features(points, density=[0.2, 0.4, 0.9], normals=[[-1, 0, 0]] * 3, border=[0, 1, 0])
    assert written == 2
    np.testing.assert_allclose(pvs.feature("density", points), [0.3, 0.3, 0.9], atol=1e-6)
    np.testing.assert_allclose(pvs.feature("border", points[:1]), [0.5])
    path = tmp_path / "pvs.npz"
    pvs.save(path)
    loaded = PVS.load(path)
    np.testing.assert_array_equal(loaded.log_odds, pvs.log_odds)
    np.testing.assert_array_equal(loaded.lattice, pvs.lattice)
    assert loaded.shape == pvs.shape and loaded.resolution == pvs.resolution
    assert loaded._params() == pvs._params()
    for name in ("density", "normal", "border"):
        np.testing.assert_array_equal(loaded.features[name], pvs.features[name])
    assert loaded.integrate(scan)["rejected"] == 49  # the filter state survives
    probe = np.random.default_rng(0).uniform(-0.05, 0.25, (500, 3))
    np.testing.assert_array_equal(loaded.probability(probe), pvs.probability(probe))


def octomap_states(tree, pvs: PVS) -> np.ndarray:  # noqa: ANN001
    """OctoMap leaves inside the PVS box as a grid of -1 unknown / 0 free / 1 occupied."""
    states = np.full(pvs.shape, -1, dtype=np.int8)
    shape = np.asarray(pvs.shape)
    eps = 0.25 * pvs.resolution
    for leaf in tree.begin_leafs_bbx(pvs.min_corner + eps, pvs.max_corner - eps):
        coord, size = np.asarray(leaf.getCoordinate()), leaf.getSize()
        node = tree.search(coord)
        first = np.floor((coord - 0.5 * size) / pvs.resolution + 0.5).astype(np.int64) - pvs.lattice
        a = np.clip(first, 0, shape)
        b = np.clip(first + max(1, round(size / pvs.resolution)), 0, shape)
        states[a[0] : b[0], a[1] : b[1], a[2] : b[2]] = 1 if node.getLogOdds() > 0.0 else 0
    return states


def test_agreement_with_octomap_on_a_small_scene(bunny_sim) -> None:
    pyoctomap = pytest.importorskip("pyoctomap")
    from explore.sim import target_for

    rng = np.random.default_rng(0)
    centre = np.array([0.0, 0.0, 0.58])
    scans = [
        bunny_sim.sensor.acquire(bunny_sim, target_for(bunny_sim.sensor, centre + offset, centre, 0.12), rng)
        for offset in ([0.3, -0.1, 0.1], [-0.2, 0.22, 0.15])
    ]
    res = 0.01
    origins = np.vstack([s.origins for s in scans])
    pvs = PVS(np.minimum(origins.min(axis=0), [-0.13, -0.13, 0.5]), np.maximum(origins.max(axis=0), 0.72), res,
              mode="octomap")
    tree = pyoctomap.OcTree(res)
    tree.setProbHit(0.7)
    tree.setProbMiss(0.4)
    tree.setClampingThresMin(0.12)
    tree.setClampingThresMax(0.97)
    for scan in scans:
        pvs.integrate(scan)
        ends = scan.origins + scan.directions * np.where(scan.hits, scan.ranges, 2 * scan.max_range)[:, None]
        for frame in np.unique(scan.frame_of_beam):
            mask = scan.frame_of_beam == frame
            tree.insertPointCloud(np.ascontiguousarray(ends[mask]), scan.sensor_poses[frame, :3, 3].copy(),
                                  max_range=float(scan.max_range), lazy_eval=True)
        tree.updateInnerOccupancy()
    theirs = octomap_states(tree, pvs)
    codes = pvs.states("octomap")
    ours = np.where(codes == UNKNOWN, -1, np.where(codes == OCCUPIED, 1, 0))
    observed = (theirs >= 0) | (ours >= 0)
    agreement = np.count_nonzero((theirs == ours) & observed) / np.count_nonzero(observed)
    assert np.count_nonzero(observed) > 8000 and np.count_nonzero(ours == 1) > 250
    assert agreement >= 0.999


def test_octomap_binary_export_is_read_back_by_octomap_cell_for_cell(bunny_sim, tmp_path) -> None:
    """pvs.bt: OctoMap reads every observed voxel back in its maximum-likelihood state, the unobserved
    ones stay unknown, and uniform blocks are pruned as OctoMap prunes them."""
    pyoctomap = pytest.importorskip("pyoctomap")
    from explore.sim import target_for

    rng = np.random.default_rng(1)
    centre = np.array([0.0, 0.0, 0.58])
    pvs = PVS.for_region([-0.15, -0.15, 0.45], [0.15, 0.15, 0.75], 0.005)
    for offset in ([0.3, -0.1, 0.1], [-0.2, 0.22, 0.15]):
        pvs.integrate(bunny_sim.sensor.acquire(bunny_sim, target_for(bunny_sim.sensor, centre + offset, centre, 0.12),
                                               rng))
    nodes = pvs.save_octomap(tmp_path / "pvs.bt")
    tree = pyoctomap.OcTree(0.1)
    assert tree.readBinary(str(tmp_path / "pvs.bt"))
    assert tree.getResolution() == pytest.approx(0.005) and tree.size() == nodes
    ours = np.where(pvs.log_odds == 0.0, -1, (pvs.log_odds > 0.0).astype(int))
    assert np.array_equal(octomap_states(tree, pvs), ours)
    observed = np.count_nonzero(ours >= 0)
    assert np.count_nonzero(ours == 1) > 300 and observed > 50_000 and nodes < observed  # pruned
