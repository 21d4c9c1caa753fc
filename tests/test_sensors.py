"""Simulated sensors: exact depth of a known plane, noise statistics, depth of field."""

from __future__ import annotations

import numpy as np
import pytest

from explore.core import look_at
from explore.sim import RayCaster, ScanPath, WorldSpec, load_world_spec, sigma_kinect, sigma_laser_poly

WALL = """
name: wall
environment:
  - {name: wall, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01]}
objects: []
region: {min: [-1, -1, 0], max: [1, 1, 1]}
sensor: depth_camera
"""


def _world_from(text: str, open_world, folder):  # noqa: ANN001, ANN202
    """A simulation of the world written in ``text`` (YAML)."""
    path = folder / "world.yaml"
    path.write_text(text)
    return open_world(load_world_spec(path))


@pytest.fixture
def wall_sim(open_world, tmp_path):
    with _world_from(WALL, open_world, tmp_path) as sim:
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


def test_a_caster_over_no_mesh_finds_nothing_near_or_in_the_way() -> None:
    """A world without known environment: every point is infinitely far from it and every ray misses
    (Open3D's closest-point query on an empty scene returns uninitialised memory)."""
    caster = RayCaster([], nthreads=1)
    points = np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])
    nearest, normals = caster.closest(points)
    assert np.all(np.isinf(nearest)) and np.all(normals == 0.0)
    hit, index, _ = caster.cast(points, np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert np.all(np.isinf(hit)) and np.all(index == -1)


def test_world_spec_is_a_value(tmp_path) -> None:
    path = tmp_path / "w.yaml"
    path.write_text(WALL)
    spec = load_world_spec(path)
    assert isinstance(spec, WorldSpec) and spec.sensor.plugin == "depth_camera"
    np.testing.assert_allclose(spec.region_size, [2, 2, 1])


STEP = WALL.replace("name: wall\n", "name: step\n").replace(
    "objects: []", "  - {name: box, box: [0.2, 0.2, 0.2], position: [0.0, 0.0, 0.1]}\nobjects: []")


@pytest.fixture
def step_sim(open_world, tmp_path):
    """The wall (floor at z = 0) with a 20 cm box on it, seen from 1.2 m straight above."""
    with _world_from(STEP, open_world, tmp_path) as sim:
        yield sim


def _depth(scan, pose) -> np.ndarray:
    """Depth z along the optical axis of every beam (NaN: no return)."""
    return scan.ranges * (scan.directions @ pose[:3, 2])


@pytest.mark.parametrize("native", [0, 640])
def test_disparity_quantisation_gives_depth_levels_spaced_as_z_squared(wall_sim, registry, rng, native) -> None:
    """Kinect-like 1/8 px disparity steps: every depth is f b / (k / 8), and neighbouring levels are
    z^2 step / (f b) apart (explore.sim.artefacts), f the focal length of the image the disparity is
    matched in (``disparity_width`` 640: twice this 320-px image's, half the spacing)."""
    from explore.sim.artefacts import depth_level_spacing

    camera = _camera(registry, noise="none", max_range=3.0, width=320, height=240, disparity_step=0.125,
                     disparity_width=native)
    f, b = camera.disparity_focal, camera.baseline
    assert f == pytest.approx(float(camera.intrinsics[0, 0]) * (2.0 if native else 1.0))
    pose = look_at([0.0, -1.2, 1.0], [0.0, 0.3, 0.0])  # an oblique view: depth 1.2-2.5 m across the image
    z = _depth(camera.acquire(wall_sim, pose, rng), pose)
    exact = _depth(_camera(registry, noise="none", max_range=3.0, width=320, height=240).acquire(wall_sim, pose, rng),
                   pose)
    z, exact = z[np.isfinite(z)], exact[np.isfinite(z)]
    disparity_steps = f * b / z / 0.125
    np.testing.assert_allclose(disparity_steps, np.round(disparity_steps), atol=1e-6)
    levels = np.unique(np.round(z, 9))
    spacing = np.diff(levels)
    mid = 0.5 * (levels[1:] + levels[:-1])
    np.testing.assert_allclose(spacing, depth_level_spacing(mid, f, b, 0.125), rtol=0.01)
    assert np.all(np.abs(z - exact) <= 0.5 * depth_level_spacing(z, f, b, 0.125) * 1.01 + 1e-9)
    assert len(levels) > 50 and spacing.max() > 2 * spacing.min()  # coarser far away


def test_projector_shadow_behind_a_step_edge_has_the_triangulated_width(step_sim, registry, rng) -> None:
    """The projector sits ``baseline`` along the camera's x axis (world -y here); beside the box, on the
    far side from it, the floor gets no light out to (b - x0) h / (H - h) from the box's edge, of
    which the camera sees the part beyond its own occlusion (x0 h / (H - h))."""
    pose = look_at([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])
    assert np.allclose(pose[:3, 0], [0.0, -1.0, 0.0])
    seen = _camera(registry, noise="none", width=320, height=240).acquire(step_sim, pose, rng)
    shadowed = _camera(registry, noise="none", width=320, height=240, projector_shadow=True).acquire(step_sim, pose,
                                                                                                   rng)
    lost = seen.hits & ~shadowed.hits
    assert not (shadowed.hits & ~seen.hits).any()
    np.testing.assert_array_equal(seen.ranges[shadowed.hits], shadowed.ranges[shadowed.hits])
    points = seen.origins[lost] + seen.directions[lost] * seen.ranges[lost, None]
    b, x0, h, height = 0.075, -0.1, 0.2, 1.2  # camera-x coordinate of the box's far edge is -0.1 (world y = +0.1)
    width = (b - x0) * h / (height - h)
    pixel = 2 * height * np.tan(np.deg2rad(29.0)) / 320
    camera_sees_from = 0.1 * height / (height - h)
    assert len(points) > 100 and np.allclose(points[:, 2], 0.0, atol=1e-6)  # on the floor
    assert camera_sees_from - 1e-6 <= points[:, 1].min() < camera_sees_from + pixel
    assert 0.1 + width - pixel < points[:, 1].max() <= 0.1 + width + 1e-6
    assert np.abs(points[:, 0]).max() < 0.1 * height / (height - h) + pixel  # only beside that edge


def test_flying_pixels_appear_only_on_depth_discontinuities(step_sim, registry, rng) -> None:
    from explore.sim.artefacts import discontinuity_mask

    pose = look_at([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])
    clean = _camera(registry, noise="none", width=160, height=120).acquire(step_sim, pose, rng)
    flying = _camera(registry, noise="none", width=160, height=120, flying_pixels=1.0).acquire(step_sim, pose, rng)
    z0, z1 = _depth(clean, pose).reshape(1, 120, 160), _depth(flying, pose).reshape(1, 120, 160)
    between = (z1 > 1.0 + 1e-6) & (z1 < 1.2 - 1e-6)
    assert not ((z0 > 1.0 + 1e-6) & (z0 < 1.2 - 1e-6)).any()
    edge = discontinuity_mask(z0, 0.03)
    assert between.sum() >= 0.4 * edge.sum() > 0 and not (between & ~edge).any()
    np.testing.assert_array_equal(z1[~edge], z0[~edge])


def test_low_frequency_bias_correlates_neighbouring_pixels(wall_sim, registry) -> None:
    """bias_sigma 1: a smooth per-frame field of the noise's own size on top of the white noise, so
    neighbouring residuals correlate by about 1/2 and the total is about sqrt(2) sigma."""
    pose = look_at([0.0, 0.0, 1.5], [0.0, 0.0, 0.0])

    def residuals(**params) -> np.ndarray:  # noqa: ANN003
        camera = _camera(registry, max_range=3.0, width=80, height=60, **params)
        rng = np.random.default_rng(5)
        out = []
        for _ in range(40):
            scan = camera.acquire(wall_sim, pose, rng)
            true = 1.5 / (scan.directions @ pose[:3, 2])
            out.append(((scan.ranges - true) / sigma_kinect(true)).reshape(60, 80))
        return np.array(out)

    def neighbour_correlation(r: np.ndarray) -> float:
        return float(np.corrcoef(r[:, :, :-1].ravel(), r[:, :, 1:].ravel())[0, 1])

    white, biased = residuals(), residuals(bias_sigma=1.0)
    assert abs(neighbour_correlation(white)) < 0.03 and white.std() == pytest.approx(1.0, abs=0.03)
    assert neighbour_correlation(biased) == pytest.approx(0.5, abs=0.1)
    assert biased.std() == pytest.approx(np.sqrt(2.0), abs=0.15)


def test_flying_pixel_filter_removes_the_flying_pixels_and_keeps_the_silhouettes(step_sim, registry, rng) -> None:
    """explore.perception.filter_depth_scan on the step edge with flying pixels everywhere they can be:
    no point stays that floats farther than 2 % of its depth (the filter's ratio) from both the box
    top and the floor (those that stay hug a surface), at least 95 % of the pixels away from the
    edge stay, and without flying pixels every pixel stays, the box's rim included (the jump-edge
    filter would drop it)."""
    from explore.perception import filter_depth_scan, jump_edges
    from explore.sim import discontinuity_mask

    pose = look_at([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])
    camera = _camera(registry, noise="none", width=160, height=120, flying_pixels=1.0)
    scan = camera.acquire(step_sim, pose, rng)

    def floating(s) -> int:  # noqa: ANN001
        z = _depth(s, pose)
        return int(np.count_nonzero(np.minimum(np.abs(z - 1.0), np.abs(z - 1.2)) > 0.02 * z))

    clean = filter_depth_scan(scan)
    assert floating(scan) > 50 and floating(clean) == 0
    exact = _camera(registry, noise="none", width=160, height=120).acquire(step_sim, pose, rng)
    edge = discontinuity_mask(_depth(exact, pose).reshape(1, 120, 160), 0.03)[0].ravel()
    kept = {tuple(np.round(d, 9)) for d in clean.directions}
    kept_away = sum(tuple(np.round(d, 9)) in kept for d in scan.directions[~edge & scan.hits])
    assert kept_away >= 0.95 * np.count_nonzero(~edge & scan.hits)
    assert clean.hits.all() and len(clean.ranges) < len(scan.ranges)  # dropped, not turned into free space
    assert len(filter_depth_scan(exact).ranges) == len(exact.ranges)
    assert jump_edges(_depth(exact, pose).reshape(1, 120, 160)).sum() == edge.sum() > 100


def test_median_depth_halves_the_noise_on_a_plane(wall_sim, registry, rng) -> None:
    from explore.perception import median_depth

    pose = look_at([0.0, 0.0, 1.5], [0.0, 0.0, 0.0])
    scan = _camera(registry, max_range=3.0, width=160, height=120).acquire(wall_sim, pose, rng)
    z = _depth(scan, pose).reshape(120, 160)
    smooth = median_depth(z, 5)
    inner = (slice(2, -2), slice(2, -2))
    assert np.std(smooth[inner] - 1.5) < 0.5 * np.std(z[inner] - 1.5)
    assert abs(np.mean(smooth[inner]) - 1.5) < 2e-4
    hole = z.copy()
    hole[60, 80] = np.nan
    assert np.isnan(median_depth(hole, 3)[60, 80]) and median_depth(hole, 3)[60, 81] == hole[60, 81]


def test_a_profile_sets_its_artefacts_and_explicit_parameters_win(registry) -> None:
    from explore.core import BadInput

    ideal = _camera(registry)
    kinect = _camera(registry, profile="kinect")
    custom = _camera(registry, profile="kinect", flying_pixels=0.0, disparity_step="0.25 px")
    assert (ideal.disparity_step, ideal.projector_shadow, ideal.patch_sigma) == (0.0, False, 0.0)
    assert (kinect.disparity_step, kinect.projector_shadow, kinect.flying_pixels) == (0.125, True, 0.5)
    assert (custom.flying_pixels, custom.disparity_step, custom.projector_shadow) == (0.0, 0.25, True)
    assert _camera(registry, profile="tof").noise == "tof"
    assert registry.create("sensor", "laser_striper", {"profile": "triangulation"}).camera_shadow
    with pytest.raises(BadInput, match=r"profile: 'kinetic' is not one of \['ideal', 'kinect', 'tof'\]"):
        _camera(registry, profile="kinetic")


def test_returns_thin_out_linearly_in_cos_towards_grazing_incidence(wall_sim, registry) -> None:
    """grazing_from_deg 40, max_incidence_deg 80: the fraction of returns per incidence bin follows
    (cos t - cos 80) / (cos 40 - cos 80) within binomial error."""
    from explore.sim import grazing_return_probability

    pose = look_at([0.0, -1.0, 0.35], [0.0, 0.4, 0.0])  # incidence 50-85 deg across the image
    exact = _camera(registry, noise="none", width=320, height=240, max_incidence_deg=80.0)
    thin = _camera(registry, noise="none", width=320, height=240, max_incidence_deg=80.0, grazing_from_deg=40.0)
    seen = exact.acquire(wall_sim, pose, np.random.default_rng(0)).hits
    kept = thin.acquire(wall_sim, pose, np.random.default_rng(1)).hits
    assert not (kept & ~seen).any()
    cos = np.abs(exact.acquire(wall_sim, pose, np.random.default_rng(0)).directions[:, 2])
    expected = grazing_return_probability(cos, 40.0, 80.0)
    bins = np.digitize(np.rad2deg(np.arccos(cos)), np.arange(40.0, 81.0, 5.0))
    checked = 0
    for b in np.unique(bins[seen]):
        m = seen & (bins == b)
        if m.sum() < 200:
            continue
        p = expected[m].mean()
        assert abs(kept[m].mean() - p) <= 4 * np.sqrt(p * (1 - p) / m.sum()) + 1e-3, b
        checked += 1
    assert checked >= 5 and expected[seen].min() < 0.3


DARK = """
name: dark
environment:
  - {name: floor, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01], color: [0.5, 0.5, 0.5, 1.0]}
  - {name: black, box: [0.3, 0.3, 0.1], position: [-0.2, 0.0, 0.05], color: [0.05, 0.05, 0.05, 1.0]}
  - {name: grey, box: [0.3, 0.3, 0.1], position: [0.2, 0.0, 0.05], color: [0.2, 0.2, 0.2, 1.0]}
objects: []
region: {min: [-1, -1, 0], max: [1, 1, 1]}
sensor: depth_camera
"""


def test_dark_surfaces_return_in_proportion_to_their_grey_level(open_world, registry, tmp_path) -> None:
    """dark_level 60: a surface of grey level g seen at incidence t returns with probability
    min(1, g cos t / 60): the black box (g = 12.75) about 21 %, the dark grey one (g = 51) 85 %, the
    mid-grey floor (g = 127.5) always."""
    pose = look_at([0.0, -0.2, 1.2], [0.0, 0.0, 0.0])
    camera = _camera(registry, noise="none", width=160, height=120, dark_level=60.0)
    with _world_from(DARK, open_world, tmp_path) as sim:
        seen = _camera(registry, noise="none", width=160, height=120).acquire(sim, pose, np.random.default_rng(0))
        kept = camera.acquire(sim, pose, np.random.default_rng(1)).hits
    points = seen.points()
    cos = np.abs(seen.directions[seen.hits, 2])
    top = points[:, 2] > 0.1 - 1e-6
    inner = lambda x0: top & (np.abs(points[:, 0] - x0) < 0.13) & (np.abs(points[:, 1]) < 0.13)  # noqa: E731
    floor = (points[:, 2] < 1e-6) & (np.abs(points[:, 0]) > 0.4)
    kept = kept[seen.hits]
    for mask, grey in ((inner(-0.2), 0.05 * 255), (inner(0.2), 0.2 * 255), (floor, 0.5 * 255)):
        p = np.minimum(1.0, grey * cos[mask] / 60.0)
        n = mask.sum()
        assert n > 300
        assert abs(kept[mask].sum() - p.sum()) <= 4 * np.sqrt((p * (1 - p)).sum()) + 1, grey


GLOSSY = """
name: glossy
environment:
  - {name: floor, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01], color: [0.5, 0.5, 0.5, 1.0], specular: 0.7}
objects: []
region: {min: [-1, -1, 0], max: [1, 1, 1]}
sensor: depth_camera
"""


@pytest.mark.parametrize("projector", [False, True])
def test_a_glossy_highlight_saturates_where_the_mirror_sends_the_light_back(projector, open_world, registry,
                                                                           tmp_path) -> None:
    """A floor of specular 0.7, 1 m below a camera looking down, highlight_deg 10: the mirror reflection of a
    beam at incidence t deviates by 2 t from the way back (coaxial), so the returns within t < 5° (8.7 cm of
    the centre) are lost with probability 0.7 and every other one is kept. With the projector 7.5 cm along x
    the highlight is centred half way, 3.75 cm off, where the mirror sends the projector's light into the
    camera."""
    pose = look_at([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0])
    params = {"noise": "none", "width": 160, "height": 120, "max_range": 3.0, "highlight_deg": 10.0,
              "projector_shadow": projector}
    with _world_from(GLOSSY, open_world, tmp_path) as sim:
        truth = _camera(registry, **{**params, "highlight_deg": 0.0}).acquire(sim, pose, np.random.default_rng(0))
        kept = _camera(registry, **params).acquire(sim, pose, np.random.default_rng(1)).hits
    assert truth.hits.all()
    points = truth.points()
    receiver = pose[:3, 3] + (0.075 * pose[:3, 0] if projector else 0.0)
    to_camera = pose[:3, 3] - points
    to_receiver = receiver - points
    mirrored = to_camera * [-1.0, -1.0, 1.0]  # the beam reflected by the floor, towards where the light goes
    cos = np.einsum("ij,ij->i", mirrored, to_receiver) / np.linalg.norm(mirrored, axis=1) / np.linalg.norm(
        to_receiver, axis=1)
    deviation = np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))
    inside, outside = deviation < 9.5, deviation > 10.5
    assert inside.sum() > 300 and outside.sum() > 5000
    assert kept[outside].all()
    share = kept[inside].mean()
    assert share == pytest.approx(0.3, abs=4 * np.sqrt(0.21 / inside.sum()))
    lost = points[~kept]
    np.testing.assert_allclose(lost[:, :2].mean(axis=0), receiver[:2] / 2.0, atol=0.005)


def test_highlights_leave_a_matte_world_as_it_was(wall_sim, registry) -> None:
    """No body is glossy: the Kinect profile's highlights draw no random numbers, so the scan is the one
    without them, range for range."""
    pose = look_at([0.1, -0.2, 1.25], [0.1, -0.2, 0.0])
    with_highlights = _camera(registry, profile="kinect", max_range=3.0)
    without = _camera(registry, profile="kinect", max_range=3.0, highlight_deg=0.0)
    assert with_highlights.highlight_deg == 10.0
    a = with_highlights.acquire(wall_sim, pose, np.random.default_rng(5))
    b = without.acquire(wall_sim, pose, np.random.default_rng(5))
    np.testing.assert_array_equal(a.ranges, b.ranges)


def test_a_glossy_surface_sends_back_only_its_diffuse_share(open_world, registry, tmp_path) -> None:
    """dark_level 60 on the floor of grey level 127.5 and specular 0.7: outside the highlight a beam at
    incidence t returns with probability min(1, 127.5 x 0.3 x cos t / 60), about 64 % (a matte floor of
    the same grey always returns)."""
    pose = look_at([0.0, -0.2, 1.2], [0.0, 0.0, 0.0])
    params = {"noise": "none", "width": 160, "height": 120, "max_range": 3.0, "dark_level": 60.0}
    with _world_from(GLOSSY, open_world, tmp_path) as sim:
        truth = _camera(registry, noise="none", width=160, height=120, max_range=3.0).acquire(
            sim, pose, np.random.default_rng(0))
        kept = _camera(registry, **params).acquire(sim, pose, np.random.default_rng(1)).hits
    assert truth.hits.all()
    p = np.minimum(1.0, 127.5 * 0.3 * np.abs(truth.directions[:, 2]) / 60.0)
    assert abs(kept.sum() - p.sum()) <= 4 * np.sqrt((p * (1 - p)).sum()) + 1
    assert 0.55 < kept.mean() < 0.7


def test_a_one_pixel_kinect_camera_measures_with_its_bias(wall_sim, registry) -> None:
    """A 1 x 1 image has no spread to normalise the bias field by: its bias is one unit-normal
    draw per frame, so the residuals over many frames keep a total of about sqrt(2) sigma."""
    camera = registry.create("sensor", "depth_camera", {"profile": "kinect", "width": 1, "height": 1,
                                                        "max_range": 3.0, "disparity_step": 0.0})
    pose = look_at([0.0, 0.0, 1.5], [0.0, 0.0, 0.0])
    rng = np.random.default_rng(3)
    scans = [camera.acquire(wall_sim, pose, rng) for _ in range(400)]
    assert all(scan.hits.all() for scan in scans)
    residual = np.array([scan.ranges[0] - 1.5 for scan in scans]) / sigma_kinect(np.array(1.5))
    assert residual.std() == pytest.approx(np.sqrt(1.0 + camera.bias_sigma**2 + camera.patch_sigma**2), rel=0.15)


def test_correlated_patches_follow_the_gaussian_correlation(wall_sim, registry) -> None:
    """patch_sigma 1, patch_px 3 on top of the white noise: residuals of pixels L apart correlate
    by exp(-L^2 / 36) / 2, their standard deviation is sqrt(2) sigma(d), and the sensor reports
    that total sigma to the PVS."""
    pose = look_at([0.0, 0.0, 1.5], [0.0, 0.0, 0.0])
    camera = _camera(registry, max_range=3.0, width=80, height=60, patch_sigma=1.0, patch_px=3.0)
    rng = np.random.default_rng(3)
    out = []
    for _ in range(30):
        scan = camera.acquire(wall_sim, pose, rng)
        true = 1.5 / (scan.directions @ pose[:3, 2])
        out.append(((scan.ranges - true) / sigma_kinect(true)).reshape(scan.image_shape))
    r = np.concatenate(out)
    for lag in (1, 3, 6):
        rho = np.corrcoef(r[:, :, :-lag].ravel(), r[:, :, lag:].ravel())[0, 1]
        assert rho == pytest.approx(0.5 * np.exp(-lag**2 / 36.0), abs=0.05), lag
    assert r.std() == pytest.approx(np.sqrt(2.0), abs=0.1)
    np.testing.assert_allclose(camera.sigma(np.array([1.5])), np.sqrt(2.0) * sigma_kinect(1.5))


def test_time_of_flight_noise_is_nearly_flat_with_range(wall_sim, registry, rng) -> None:
    from explore.sim import sigma_tof

    assert sigma_tof(np.array([0.5, 1.0, 3.0])) * 1e3 == pytest.approx([1.325, 1.3, 2.7])
    camera = _camera(registry, noise="tof", max_range=3.5, width=160, height=120)
    pose = look_at([0.0, 0.0, 2.5], [0.0, 0.0, 0.0])
    scan = camera.acquire(wall_sim, pose, rng)
    true = 2.5 / (scan.directions @ pose[:3, 2])
    assert scan.hits.all() and ((scan.ranges - true) / sigma_tof(true)).std() == pytest.approx(1.0, abs=0.03)


def _striper_world(box_side: np.ndarray, open_world, folder):  # noqa: ANN001, ANN202
    """The wall with a 5 cm high slab on the half-plane towards ``box_side`` (a horizontal unit
    vector) from the origin."""
    centre = 0.5 * box_side
    size = np.abs(box_side) + np.abs(box_side[::-1])  # 1 m along box_side, 1 m across
    box = f"  - {{name: slab, box: [{size[0]}, {size[1]}, 0.05], position: [{centre[0]}, {centre[1]}, 0.025]}}\n"
    return _world_from(WALL.replace("objects: []", box + "objects: []"), open_world, folder)


def test_striper_camera_shadow_behind_a_step_has_the_triangulated_width(open_world, registry, tmp_path) -> None:
    """The striper's camera sits ``baseline`` b along the sweep. A stripe that reaches the floor a
    distance s before a step of height h (seen from height H) is hidden from the camera by the step
    while s < b h / H: the shadow band on the floor is that wide and lies right before the step."""
    pose = look_at([0.0, 0.0, 0.35], [0.0, 0.0, 0.0])
    sweep = pose[:3, 1]
    start, end = pose.copy(), pose.copy()
    start[:3, 3] -= 0.04 * sweep
    end[:3, 3] += 0.01 * sweep
    path = ScanPath(start, end, 0.01)
    params = {"noise": "none", "speed": 0.01}
    with _striper_world(sweep[:2], open_world, tmp_path) as sim:
        seen = registry.create("sensor", "laser_striper", params).acquire(sim, path, np.random.default_rng(0))
        shadowed = registry.create("sensor", "laser_striper", {**params, "camera_shadow": True}).acquire(
            sim, path, np.random.default_rng(0))
    lost = seen.hits & ~shadowed.hits
    assert not (shadowed.hits & ~seen.hits).any()
    points = seen.origins[lost] + seen.directions[lost] * seen.ranges[lost, None]
    along = points[:, :2] @ sweep[:2]
    width = 0.08 * 0.05 / 0.35
    spacing = 0.01 / 25.0
    assert len(points) > 500 and np.allclose(points[:, 2], 0.0, atol=1e-6)
    assert -width - 1e-6 <= along.min() < -width + 2 * spacing and along.max() <= 1e-6
    seen_floor = seen.hits & (seen.origins[:, :2] @ sweep[:2] < -width - 2 * spacing)
    assert shadowed.hits[seen_floor].all()


def test_striper_speckle_correlates_along_the_stripe_only(wall_sim, registry) -> None:
    """speckle_sigma 1, speckle_beams 2: residuals of beams L apart on a stripe correlate by
    exp(-L^2 / 16) / 2, neighbouring stripes not at all; the scan's organised image is the sweep."""
    striper = registry.create("sensor", "laser_striper", {"speckle_sigma": 1.0, "speckle_beams": 2.0,
                                                          "speed": 0.1})
    start = look_at([-0.1, 0.0, 0.3], [-0.1, 0.0, 0.0])
    end = start.copy()
    end[:3, 3] = [0.1, 0.0, 0.3]
    scan = striper.acquire(wall_sim, ScanPath(start, end, 0.1), np.random.default_rng(4))
    assert scan.image_shape == (1, len(scan.sensor_poses), 224)
    true = 0.3 / (scan.directions @ start[:3, 2])
    r = ((scan.ranges - true) / sigma_laser_poly(true)).reshape(scan.image_shape)[0]
    for lag in (1, 2, 4):
        rho = np.corrcoef(r[:, :-lag].ravel(), r[:, lag:].ravel())[0, 1]
        assert rho == pytest.approx(0.5 * np.exp(-lag**2 / 16.0), abs=0.05), lag
    assert abs(np.corrcoef(r[:-1].ravel(), r[1:].ravel())[0, 1]) < 0.05
    assert r.std() == pytest.approx(np.sqrt(2.0), abs=0.1)


def test_normals_from_the_organised_image_are_exact_on_planes_and_stop_at_jumps(step_sim, registry, rng) -> None:
    """explore.perception.organised_normals on the box on the floor seen from above: every normal
    of the box top and of the floor is (0, 0, 1) (without noise, to 1e-5; with Kinect noise within
    3 deg at the median), and none is given where the 5 x 5 window meets the box's edge."""
    from explore.perception import organised_normals

    pose = look_at([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])
    exact = _camera(registry, noise="none", width=160, height=120).acquire(step_sim, pose, rng)
    normals = organised_normals(exact)
    given = np.isfinite(normals[:, 0])
    assert given.mean() > 0.8
    np.testing.assert_allclose(normals[given], np.tile([0.0, 0.0, 1.0], (given.sum(), 1)), atol=1e-5)
    points = exact.points()
    near_edge = np.abs(np.max(np.abs(points[:, :2]), axis=1) - 0.1) < 0.01  # within 1 cm of the box's rim
    assert not given[near_edge & (np.max(np.abs(points[:, :2]), axis=1) > 0.1 + 0.005)].any()
    noisy = _camera(registry, width=160, height=120).acquire(step_sim, pose, rng)
    n = organised_normals(noisy)
    angle = np.degrees(np.arccos(np.clip(n[np.isfinite(n[:, 0]), 2], -1.0, 1.0)))
    assert np.median(angle) < 3.0


def test_organised_normals_travel_with_the_scan_into_the_clusters(step_sim, registry, rng) -> None:
    """filter_depth_scan(normals=True) keeps each kept beam's organised normal; rebase_scan turns
    the normals with the beams; the segmenter's clusters take them over the neighbour search's."""
    from explore.perception import Cloud, filter_depth_scan, rebase_scan

    pose = look_at([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])
    scan = filter_depth_scan(_camera(registry, noise="none", width=160, height=120).acquire(step_sim, pose, rng),
                             normals=True)
    given = np.isfinite(scan.normals[:, 0])
    assert scan.normals.shape == (len(scan), 3) and given.mean() > 0.8
    np.testing.assert_allclose(scan.normals[given], np.tile([0.0, 0.0, 1.0], (given.sum(), 1)), atol=1e-5)
    turned = pose.copy()
    turned[:3, :3] = look_at([0.0, 0.2, 1.2], [0.0, 0.0, 0.0])[:3, :3]
    moved = rebase_scan(scan, turned)
    delta = turned[:3, :3] @ pose[:3, :3].T
    np.testing.assert_allclose(moved.normals[given], scan.normals[given] @ delta.T, atol=1e-9)
    cloud = Cloud.from_scans(moved)
    np.testing.assert_array_equal(cloud.normals, moved.normals[moved.hits])
    clusters = registry.create("segmenter", "plane_clusters", {"scale": "table"}).cluster(
        cloud.subset(cloud.points[:, 2] > 0.05))
    box = max(clusters, key=lambda c: len(c.points))
    organised = moved.normals[box.beams]
    mine = np.isfinite(organised[:, 0])
    assert len(box.points) > 500 and mine.mean() > 0.5
    np.testing.assert_array_equal(box.normals[mine], organised[mine])


def test_a_world_of_bare_meshes_is_seen_as_the_simulation_sees_it(wall_sim, registry, rng) -> None:
    """MeshWorld: the same camera on the same wall, without pybullet, gives the same exact depths;
    a Kinect-profiled camera with dark-surface dropouts gets every frontal return there (the
    meshes have no colour) and its depths stay on the disparity levels."""
    from explore.sim import MeshWorld, TriMesh, box_mesh
    from explore.sim.artefacts import depth_level_spacing

    pose = look_at([0.1, -0.2, 1.25], [0.1, -0.2, 0.0])
    exact = _camera(registry, noise="none", max_range=3.0)
    wall = box_mesh(np.array([4.0, 4.0, 0.02]))
    bare = MeshWorld([TriMesh(wall.vertices - [0.0, 0.0, 0.01], wall.triangles)])  # the wall of WALL
    np.testing.assert_allclose(bare.acquire(exact, pose, rng).ranges, exact.acquire(wall_sim, pose, rng).ranges,
                               atol=1e-6)
    kinect = _camera(registry, profile="kinect", dark_level=200.0, max_range=3.0)
    scan = bare.acquire(kinect, pose, rng)
    assert kinect.dark_level == 200.0  # the plugin itself is left as it was
    assert scan.hits.mean() > 0.99
    z = _depth(scan, pose)
    steps = kinect.disparity_focal * kinect.baseline / z / kinect.disparity_step
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    assert np.abs(z - 1.25).max() < 4 * float(kinect.sigma(np.array(1.25))) + depth_level_spacing(
        1.25, kinect.disparity_focal, kinect.baseline, kinect.disparity_step)
