"""Utilities on hand-made PVS states, with the numbers worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from explore.mapping import (
    ENTROPY,
    HITS,
    OCC_FIRST,
    QUAL_LIT,
    QUAL_NEED,
    REAR_VOXEL,
    UNK_FIRST,
    UNKNOWN_VOXELS,
    TraceSettings,
    VoxelGrid,
    first_blocked,
    trace,
)
from explore.nbv import Candidate, CandidateStack, PlanningContext, frame_from
from explore.sim import RaySensor

RES = 0.01


def h(p: float) -> float:
    return float(-(p * np.log2(p) + (1 - p) * np.log2(1 - p)))


def row_grid(values: list[float]) -> VoxelGrid:
    """A 1-voxel-thick row along x: voxel i has occupancy values[i]."""
    prob = np.asarray(values, dtype=np.float32).reshape(-1, 1, 1)
    grid = VoxelGrid(prob, np.zeros(3), RES)
    grid.ensure_features()
    return grid


def ray_x(n: int = 1) -> tuple[np.ndarray, np.ndarray]:
    return np.tile([[-0.05, 0.005, 0.005]], (n, 1)), np.tile([[1.0, 0.0, 0.0]], (n, 1))


def test_entropy_until_occupied_and_counts() -> None:
    grid = row_grid([0.5] * 5 + [0.99] + [0.5] * 4)
    o, d = ray_x()
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0)[0]
    assert acc[ENTROPY] == pytest.approx(5 + h(0.99), rel=1e-6)  # IROS Eq. 1-2, stop at p >= 0.95
    assert acc[UNKNOWN_VOXELS] == 5
    assert acc[OCC_FIRST] == 0 and acc[UNK_FIRST] == 1  # the first non-free voxel is unknown
    assert acc[HITS] == 1 and acc[REAR_VOXEL] == 1  # voxel 6, behind the surface, is unknown


def test_visited_marking_counts_each_voxel_once() -> None:
    grid = row_grid([0.2, 0.5, 0.5, 0.97, 0.5])
    o, d = ray_x(2)
    once = trace(grid, o, d, np.zeros(2, np.int64), 1, 0.0, 1.0, TraceSettings(visited=True))[0]
    twice = trace(grid, o, d, np.zeros(2, np.int64), 1, 0.0, 1.0, TraceSettings(visited=False))[0]
    single = h(0.2) + 2 * h(0.5) + h(0.97)
    assert once[ENTROPY] == pytest.approx(single, rel=1e-6)
    assert twice[ENTROPY] == pytest.approx(2 * single, rel=1e-6)
    assert once[OCC_FIRST] == 0 and once[UNK_FIRST] == 1  # first non-free: voxel 1 (0.5), counted once
    # two candidates: each gets its own visited marks
    two = trace(grid, o, d, np.array([0, 1]), 2, 0.0, 1.0)
    assert two[:, ENTROPY] == pytest.approx([single, single], rel=1e-6)


def test_min_range_skips_near_voxels() -> None:
    grid = row_grid([0.5] * 10)
    o, d = ray_x()
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.05 + 0.03, 1.0)[0]  # first 3 voxels before min range
    assert acc[ENTROPY] == pytest.approx(7.0)


def test_a_box_of_the_known_environment_ends_the_beams() -> None:
    grid = row_grid([0.5] * 10)  # x from 0 to 0.1 m, all unknown
    o, d = ray_x()
    table = (np.array([0.043, -1.0, -1.0]), np.array([0.2, 1.0, 1.0]))  # enters voxel 4 at x = 0.043
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0, TraceSettings(visited=True), occluders=[table])[0]
    assert acc[UNKNOWN_VOXELS] == 5  # voxels 0-4: the one holding the box's face counts, none behind it
    assert acc[UNK_FIRST] == 1
    flush = (np.array([0.04, -1.0, -1.0]), np.array([0.2, 1.0, 1.0]))  # the face on a voxel border
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0, occluders=[flush])[0]
    assert acc[UNKNOWN_VOXELS] == 4  # voxel 4 lies wholly inside the box
    behind = (np.array([-0.2, -1.0, -1.0]), np.array([-0.06, 1.0, 1.0]))  # behind the sensor: no effect
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0, occluders=[behind])[0]
    assert acc[UNKNOWN_VOXELS] == 10
    inside = (np.array([-0.1, -1.0, -1.0]), np.array([0.01, 1.0, 1.0]))  # the sensor inside a box sees nothing
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0, occluders=[inside])[0]
    assert acc[UNKNOWN_VOXELS] == 0 and acc[UNK_FIRST] == 0


def test_quality_terms_and_incidence_cutoff() -> None:
    grid = row_grid([0.1, 0.1, 0.98, 0.5])
    grid.has_feature[2, 0, 0] = True
    grid.border[2, 0, 0] = 0.4
    grid.density[2, 0, 0] = 0.25
    grid.normal[2, 0, 0] = [-1.0, 0.0, 0.0]  # facing the ray
    o, d = ray_x()
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0)[0]
    assert acc[QUAL_LIT] == pytest.approx(0.7 * 0.4 + 0.3 * 0.25)  # Eq. 4.33 literal
    assert acc[QUAL_NEED] == pytest.approx(0.7 * 0.4 + 0.3 * 0.75)  # the need variant
    tilt = np.deg2rad(75.0)  # incidence beyond 70 deg: no quality
    grid.normal[2, 0, 0] = [-np.cos(tilt), np.sin(tilt), 0.0]
    acc = trace(grid, o, d, np.zeros(1, np.int64), 1, 0.0, 1.0)[0]
    assert acc[QUAL_LIT] == 0.0 and acc[QUAL_NEED] == 0.0


def test_hierarchical_tracing_skips_only_free_bundles() -> None:
    prob = np.full((16, 16, 16), 0.02, dtype=np.float32)
    prob[8:, :, :] = 0.5
    grid = VoxelGrid(prob, np.zeros(3), RES)
    origins = np.column_stack(
        [np.full(64, -0.05), np.repeat(np.linspace(0.005, 0.155, 8), 8), np.tile(np.linspace(0.005, 0.155, 8), 8)]
    )
    dirs = np.tile([1.0, 0.0, 0.0], (64, 1))
    fine = trace(grid, origins, dirs, np.zeros(64, np.int64), 1, 0.0, 1.0)[0]
    coarse = trace(grid, origins, dirs, np.zeros(64, np.int64), 1, 0.0, 1.0, TraceSettings(hierarchy=1),
                   beams_per_frame=8)[0]
    assert coarse[UNKNOWN_VOXELS] == pytest.approx(fine[UNKNOWN_VOXELS])
    free = VoxelGrid(np.full((16, 16, 16), 0.02, dtype=np.float32), np.zeros(3), RES)
    skipped = trace(free, origins, dirs, np.zeros(64, np.int64), 1, 0.0, 1.0, TraceSettings(hierarchy=1))[0]
    assert skipped[ENTROPY] == 0.0  # every bundle is free: nothing traced


def test_first_blocked_distance() -> None:
    grid = row_grid([0.1, 0.1, 0.96, 0.1])
    o, d = ray_x()
    assert first_blocked(grid, o, d, 1.0)[0] == pytest.approx(0.07, abs=0.003)
    assert np.isinf(first_blocked(grid, o, d, 0.06)[0])


# -- the utility plugins on a one-beam sensor -------------------------------------------
class OneBeam(RaySensor):
    geometry = "area"
    min_range = 0.0
    max_range = 1.0

    def local_directions(self) -> np.ndarray:
        return np.array([[0.0, 0.0, 1.0]])


class Counted:
    def __init__(self, n: int) -> None:
        self.n = n

    def non_free_count(self) -> int:
        return self.n


def utility_ctx(grid: VoxelGrid, iteration: int = 0, n_v: int = 100) -> PlanningContext:
    ctx = PlanningContext(
        pvs=Counted(n_v),
        surface=None,
        grid=grid,
        sensor=OneBeam(),
        robot=None,
        region_min=np.zeros(3),
        region_max=np.ones(3),
        stack=CandidateStack(),
    )
    ctx.iteration = iteration
    ctx.sensor_pose = np.eye(4)
    return ctx


def beam_candidate(y: float) -> Candidate:
    pose = frame_from(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([-0.05, y, 0.005]))
    return Candidate(pose, "test")


def two_rows() -> VoxelGrid:
    """Row y=0: 3 unknown voxels then a surface with features; row y=1: free then unknown."""
    prob = np.full((6, 2, 1), 0.5, dtype=np.float32)
    prob[3, 0, 0] = 0.99
    prob[:3, 1, 0] = 0.05
    grid = VoxelGrid(prob, np.zeros(3), RES)
    grid.ensure_features()
    grid.has_feature[3, 0, 0] = True
    grid.border[3, 0, 0] = 1.0
    grid.density[3, 0, 0] = 0.0
    grid.normal[3, 0, 0] = [-1.0, 0.0, 0.0]
    return grid


def test_information_gain_and_unknown_count(registry) -> None:  # noqa: ANN001
    ctx = utility_ctx(two_rows())
    cands = [beam_candidate(0.005), beam_candidate(0.015)]
    ig = registry.create("utility", "information_gain").score(cands, ctx)
    assert ig == pytest.approx([3 + h(0.99), 3 * h(0.05) + 3], rel=1e-5)
    unknown = registry.create("utility", "unknown_count").score(cands, ctx)
    assert list(unknown) == [3, 3]


def test_ig_quality_weights_and_variants(registry) -> None:  # noqa: ANN001
    grid = two_rows()
    cands = [beam_candidate(0.005), beam_candidate(0.015)]
    e = np.array([3 + h(0.99), 3 * h(0.05) + 3]) / 100.0
    ctx = utility_ctx(grid, iteration=5, n_v=100)  # omega = 5 / (5 + 5) = 0.5, thesis normalisation by N_v
    need = registry.create("utility", "ig_quality", {"normalise": "n_v"}).score(cands, ctx)
    assert need == pytest.approx(0.5 * e + 0.5 * np.array([0.7 * 1 + 0.3 * 1, 0.0]) / 100.0, rel=1e-5)
    literal = registry.create("utility", "ig_quality", {"variant": "kriegel_literal", "normalise": "n_v"}).score(
        cands, ctx
    )
    assert literal == pytest.approx(0.5 * e + 0.5 * (1 - np.array([0.7, 0.0]) / 100.0), rel=1e-5)
    # the literal sign penalises the candidate that sees the border voxel; "need" rewards it
    ig_only = registry.create("utility", "ig_quality", {"omega": 0.0, "normalise": "n_v"}).score(cands, ctx)
    assert ig_only == pytest.approx(e, rel=1e-5)
    quality_only = registry.create("utility", "ig_quality", {"omega": 1.0}).score(cands, ctx)
    assert np.argmax(quality_only) == 0
    # normalise = max: each term divided by its maximum over the candidates
    both = registry.create("utility", "ig_quality").score(cands, ctx)
    assert both == pytest.approx(0.5 * e / e.max() + 0.5 * np.array([1.0, 0.0]), rel=1e-5)


def test_area_factor_overlap_gate(registry) -> None:  # noqa: ANN001
    grid = two_rows()
    ctx = utility_ctx(grid)
    cands = [beam_candidate(0.005), beam_candidate(0.015)]
    util = registry.create("utility", "area_factor", {"overlap": 0.5, "tie_break": 0.0, "clearance": 0.0})
    values = util.score(cands, ctx)
    # beam 0 first meets an unknown voxel (reg = 0), beam 1 as well: both gated
    assert list(values) == [0.0, 0.0]
    grid.prob[0, 0, 0] = 0.9  # now beam 0 first meets an occupied voxel: oc/(oc+un) = 1 > h
    values = util.score(cands, ctx)
    assert values[1] == 0.0 and values[0] == 0.0  # and sees no unknown first: sur = 0
    # the tie-break keeps ranking gated candidates by sur = un_o / un_total
    util = registry.create("utility", "area_factor", {"overlap": 0.5, "tie_break": 1.0, "clearance": 0.0})
    grid.prob[0, 0, 0] = 0.5
    values = util.score(cands, ctx)
    un_total = int(np.count_nonzero((grid.prob >= 0.25) & (grid.prob < 0.75)))
    assert values == pytest.approx([1.0 / un_total, 1.0 / un_total])
    assert cands[0].diagnostics["reg"] == 0.0 and cands[0].diagnostics["pos"] == 1.0


def test_isler_family(registry) -> None:  # noqa: ANN001
    grid = two_rows()
    ctx = utility_ctx(grid)
    cands = [beam_candidate(0.005), beam_candidate(0.015)]
    occl = registry.create("utility", "occlusion_aware").score(cands, ctx)
    # row 0: P_v = 1, 0.5, 0.25, 0.125 before the surface voxel
    assert occl[0] == pytest.approx(1 + 0.5 + 0.25 + 0.125 * h(0.99), rel=1e-5)
    unobs = registry.create("utility", "unobserved_voxel").score(cands, ctx)
    assert unobs[0] == pytest.approx(1.75)
    assert unobs[1] == pytest.approx(0.95**3 * (1 + 0.5 + 0.25), rel=1e-5)
    rear = registry.create("utility", "rear_side_voxel").score(cands, ctx)
    assert list(rear) == [1, 0]
    rear_h = registry.create("utility", "rear_side_entropy").score(cands, ctx)
    assert rear_h[0] == pytest.approx(0.125, rel=1e-5)
    avg = registry.create("utility", "average_entropy").score(cands, ctx)
    assert avg[0] == pytest.approx((3 + h(0.99)) / 4, rel=1e-5)
    prox = registry.create("utility", "proximity_count").score(cands, ctx)
    # w = exp(-distance to the occupied voxel / 1 cm): 3, 2, 1 voxels away, times P_v
    assert prox[0] == pytest.approx(np.exp(-3) + 0.5 * np.exp(-2) + 0.25 * np.exp(-1), rel=1e-4)


def test_random_utility_is_uniform_and_seeded(registry) -> None:  # noqa: ANN001
    ctx = utility_ctx(two_rows())
    cands = [beam_candidate(0.005 + 0.001 * i) for i in range(4)]
    util = registry.create("utility", "random")
    ctx.rng = np.random.default_rng(7)
    draws = np.array([util.score(cands, ctx) for _ in range(400)])
    assert draws.shape == (400, 4) and draws.min() >= 0.0 and draws.max() < 1.0
    assert draws.mean() == pytest.approx(0.5, abs=0.03)  # uniform on [0, 1): mean 1/2, sd of the mean 0.007
    picks = np.bincount(np.argmax(draws, axis=1), minlength=4)
    assert np.all((picks > 70) & (picks < 130))  # each candidate chosen about 100 times (binomial sd 8.7)
    ctx.rng = np.random.default_rng(7)
    assert np.array_equal(util.score(cands, ctx), draws[0])  # the session's seed decides
