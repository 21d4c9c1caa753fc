"""The sparse PVS: the dense PVS's numbers in hashed blocks, memory that follows the observed space, .bt files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_pvs import bayes, make_scan

from explore.core import BadInput
from explore.mapping import PVS, SparsePVS, make_pvs
from explore.mapping.octomap_bt import CENTER, read_bt
from explore.runtime.video import pvs_layer
from explore.sim import target_for

CENTRE = np.array([0.0, 0.0, 0.58])


@pytest.fixture(scope="module")
def bunny_scans(open_world):  # noqa: ANN001, ANN201
    """Three striper scans of the bunny and the box they cover (sensor origins included)."""
    with open_world("bunny_pedestal") as sim:
        rng = np.random.default_rng(3)
        scans = [sim.sensor.acquire(sim, target_for(sim.sensor, CENTRE + offset, CENTRE, 0.12), rng)
                 for offset in ([0.3, -0.1, 0.1], [-0.2, 0.22, 0.15], [0.05, -0.3, 0.2])]
    origins = np.vstack([s.origins for s in scans])
    return scans, np.minimum(origins.min(axis=0), CENTRE - 0.15) - 0.02, np.maximum(origins.max(axis=0), CENTRE + 0.15)


def test_the_striper_camera_frees_the_same_voxels_in_both_layouts(open_world) -> None:  # noqa: ANN001
    """Triangulation scans: a missing return frees what the camera saw (PVS._seen_misses), the same in both."""
    with open_world("bunny_pedestal", profile="triangulation") as sim:
        rng = np.random.default_rng(3)
        scans = [sim.sensor.acquire(sim, target_for(sim.sensor, CENTRE + offset, CENTRE, 0.12), rng)
                 for offset in ([0.3, -0.1, 0.1], [-0.2, 0.22, 0.15])]
    assert all(scan.seen_from is not None and not scan.no_return_clears for scan in scans)
    lo, hi = CENTRE - 0.15, CENTRE + 0.15
    dense, sparse, blind = PVS(lo, hi, 0.005), SparsePVS(lo, hi, 0.005), PVS(lo, hi, 0.005)
    for scan in scans:
        assert dense.integrate(scan) == sparse.integrate(scan)
        blind.integrate(dataclasses.replace(scan, seen_from=None))
    assert np.array_equal(sparse.window(lo, hi).log_odds, dense.log_odds)
    free, blind_free = dense.counts()["free"], blind.counts()["free"]
    assert free > 2 * blind_free  # the air beside the bunny, which no return crosses, is no longer unknown
    occupied, blind_occupied = dense.counts()["occupied"], blind.counts()["occupied"]
    assert blind_occupied > 1500 and 0.995 * blind_occupied <= occupied <= blind_occupied  # the surface kept


@pytest.mark.parametrize("mode", ["sensor_model", "octomap"])
def test_sparse_gives_the_dense_numbers(bunny_scans, mode: str, tmp_path) -> None:  # noqa: ANN001
    """Same scans, same voxels, same log-odds, queries, rays, entropy and .bt bytes (both update rules)."""
    scans, lo, hi = bunny_scans
    dense, sparse = PVS(lo, hi, 0.005, mode=mode), SparsePVS(lo, hi, 0.005, mode=mode)
    rng = np.random.default_rng(0)
    probe = rng.uniform(lo - 0.05, hi + 0.05, (20_000, 3))
    for scan in scans:
        assert dense.integrate(scan) == sparse.integrate(scan)
        # the planners' free-space test, its block bitmap rebuilt after every scan
        for p in (0.4, 0.6, 0.75, 0.97):
            assert np.array_equal(sparse.probability_below(probe, p), dense.probability(probe) < p)
    assert 0 < np.count_nonzero(~sparse.probability_below(probe, 0.75)) < len(probe)
    assert np.array_equal(sparse.window(lo, hi).log_odds, dense.log_odds)
    assert np.count_nonzero(dense.log_odds) > 50_000
    for thresholds in ("validation", "planning", "octomap"):
        assert sparse.counts(thresholds) == dense.counts(thresholds)
    assert sparse.non_free_count() == dense.non_free_count()
    assert np.array_equal(sparse.probability(probe), dense.probability(probe))
    assert np.array_equal(sparse.state(probe, "vasquez"), dense.state(probe, "vasquez"))
    eyes = CENTRE + rng.normal(0.0, 0.3, (200, 3))
    rays = CENTRE - eyes + rng.normal(0.0, 0.03, (200, 3))
    for parallel in (False, True):
        a = dense.cast(eyes, rays, 0.8, parallel=parallel, return_voxels=True)
        b = sparse.cast(eyes, rays, 0.8, parallel=parallel, return_voxels=True)
        assert a.hit.sum() > 50
        for field in ("hit_distance", "hit_voxel", "entropy", "unknown", "occupied", "frontier", "visits",
                      "voxel_ids"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), field
    for visited in (True, False):
        assert sparse.entropy_gain(eyes, rays, 0.8, visited=visited, return_stats=True) == \
            dense.entropy_gain(eyes, rays, 0.8, visited=visited, return_stats=True)
    points = CENTRE + rng.normal(0.0, 0.08, (2000, 3))
    assert np.array_equal(sparse.is_free(points, 0.01), dense.is_free(points, 0.01))
    assert np.array_equal(np.sort(sparse.occupied_points(), axis=0), np.sort(dense.occupied_points(), axis=0))
    assert len(sparse.voxel_mesh().triangles) == len(dense.voxel_mesh().triangles) > 0
    layer = pvs_layer(dense)  # the run video's PVS panel
    assert np.array_equal(pvs_layer(sparse), layer) and np.count_nonzero(layer > 0) > 50
    assert sparse.save_octomap(tmp_path / "s.bt") == dense.save_octomap(tmp_path / "d.bt")
    assert (tmp_path / "s.bt").read_bytes() == (tmp_path / "d.bt").read_bytes()


def test_sparse_bayes_update_of_one_beam_matches_closed_form() -> None:
    """A beam along +x through a 2 km box: free voxels before the return, the hit voxel at Eq. 3.4's posterior."""
    pvs = SparsePVS([-1000.0, -1000.0, -10.0], [1000.0, 1000.0, 10.0], 0.01)
    scan = make_scan([0.005, 0.005, 0.005], [1.0, 0.0, 0.0], [0.1])
    for _ in range(3):
        pvs.integrate(scan)
    p = pvs.probability(np.column_stack([np.arange(12) * 0.01 + 0.005, np.full(12, 0.005), np.full(12, 0.005)]))
    np.testing.assert_allclose(p[:9], bayes(0.4, 3, pvs.clamp), atol=1e-5)
    assert p[10] == pytest.approx(bayes(0.7, 3, pvs.clamp), abs=1e-5)
    assert pvs.blocks == 2 and pvs.nbytes < 2**20  # 2 km box: two 8^3 blocks in use, a small pool


def test_memory_follows_the_observed_space_not_the_region(bunny_scans) -> None:  # noqa: ANN001
    """A 2 km region at 5 mm: the dense grid is refused before allocation; the sparse one holds the bunny
    scans in blocks around the rays, a few MB, and grows its box without moving data."""
    scans, lo, hi = bunny_scans
    with pytest.raises(BadInput, match="would need"):
        PVS([-1000.0] * 3, [1000.0] * 3, 0.005)
    big = SparsePVS([-1000.0] * 3, [1000.0] * 3, 0.005)
    small = SparsePVS(lo, hi, 0.005)
    for scan in scans:
        big.integrate(scan)
        small.integrate(scan)
    assert big.blocks == small.blocks  # every ray ends in the small box already
    observed = big.counts("octomap")
    assert observed["free"] + observed["occupied"] > 50_000
    assert big.stored_blocks * 512 < 4 * (observed["free"] + observed["occupied"])
    assert big.stored_blocks < big.blocks  # uniform blocks keep one value, as OctoMap prunes equal children
    assert big.nbytes < 32 * 2**20
    probe = np.random.default_rng(1).uniform(lo, hi, (5000, 3))
    before = small.probability(probe)
    small.grow(lo - 1.0, hi + 1.0)
    assert np.array_equal(small.probability(probe), before)
    with pytest.raises(BadInput, match="reaches only"):
        SparsePVS([0.0] * 3, [6000.0, 1.0, 1.0], 0.005)


def test_save_load_and_bt_round_trip(bunny_scans, tmp_path) -> None:  # noqa: ANN001
    """pvs.npz keeps every block; pvs.bt read back (by our reader and by OctoMap) gives every observed voxel
    in its maximum-likelihood state."""
    scans, lo, hi = bunny_scans
    pvs = SparsePVS(lo, hi, 0.005)
    for scan in scans:
        pvs.integrate(scan)
    pvs.save(tmp_path / "pvs.npz")
    loaded = SparsePVS.load(tmp_path / "pvs.npz")
    probe = np.random.default_rng(2).uniform(lo, hi, (20_000, 3))
    assert np.array_equal(loaded.probability(probe), pvs.probability(probe))
    assert loaded.blocks == pvs.blocks and loaded.counts() == pvs.counts()
    nodes = pvs.save_octomap(tmp_path / "pvs.bt")
    keys, occupied, res = read_bt(tmp_path / "pvs.bt")
    ours, values = pvs._stored()
    assert res == pytest.approx(0.005) and len(keys) == len(ours) > 50_000
    order_a, order_b = np.lexsort((keys - CENTER).T), np.lexsort(ours.T)
    assert np.array_equal((keys - CENTER)[order_a], ours[order_b])
    assert np.array_equal(occupied[order_a], values[order_b] > 0.0)
    pyoctomap = pytest.importorskip("pyoctomap")
    tree = pyoctomap.OcTree(0.1)
    assert tree.readBinary(str(tmp_path / "pvs.bt")) and tree.size() == nodes


def test_make_pvs_chooses_the_layout_by_size() -> None:
    assert type(make_pvs([0, 0, 0], [0.3, 0.3, 0.3], 0.005)) is PVS
    assert type(make_pvs([-2.5, -2.5, 0], [2.5, 2.5, 2.0], 0.005)) is SparsePVS
    assert type(make_pvs([0, 0, 0], [0.3, 0.3, 0.3], 0.005, layout="sparse")) is SparsePVS
    with pytest.raises(ValueError, match="layout"):
        make_pvs([0, 0, 0], [1, 1, 1], 0.01, layout="octree")


@pytest.mark.slow
def test_a_scene_run_on_the_sparse_pvs_is_the_dense_run(tmp_path) -> None:  # noqa: ANN001
    """scene_exploration on scene_small with the scene PVS in hashed blocks: the same metrics.json and trace as
    with the dense grid (apart from the setting itself, wall times, ticks and paths)."""
    import subprocess
    import sys
    from pathlib import Path

    from explore.runtime import run_differences

    explore = Path(sys.executable).parent / "explore"
    runs = {}
    for layout in ("dense", "sparse"):
        out = tmp_path / layout
        args = [str(explore), "run", "scene_exploration", "--world", "scene_small", "--seed", "3", "-q", "--out",
                str(out), "--set", f"start_scene.db={tmp_path / ('db_' + layout) / 'objects.db'}",
                "--set", f"start_scene.pvs_layout={layout}"]
        runs[layout] = (out, subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
    for out, process in runs.values():
        text, _ = process.communicate(timeout=600)
        assert (out / "metrics.json").exists(), text[-2000:]
    differences = [line for line in run_differences(runs["dense"][0], runs["sparse"][0]) if "pvs_layout" not in line]
    assert not differences, "\n".join(differences[:20])


def test_a_scene_tree_at_object_resolution_in_a_room_is_accepted_where_its_pvs_may_be_sparse(registry) -> None:  # noqa: ANN001
    """Before a run: 2 mm over two_tables' room would be a 37 GiB dense grid; the scene PVS's layout is
    auto (sparse at that size), so the run is accepted, and refused only with the dense layout."""
    from explore.runtime import RunConfig, check_inputs

    check_inputs(RunConfig("table_patrol", "two_tables", settings={"resolution": 0.002}), registry)
    with pytest.raises(BadInput, match="would need"):
        check_inputs(RunConfig("table_patrol", "two_tables", settings={"resolution": 0.002,
                                                                          "start_scene.pvs_layout": "dense"}), registry)
