"""PVS pose validation (Kriegel thesis Sec. 3.4, Eq. 3.11)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from explore.core import look_at
from explore.perception import pvs_votes


class _FixedPVS:
    """Stand-in with the PVS query API: the occupancy p is the point's x coordinate."""

    def probability(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points)[:, 0]


def test_equation_3_11_counts_and_score():
    # p = 0.1, 0.2 (free), 0.5 (unknown), 0.75, 0.9 (occupied; 0.75 is occupied: p >= 0.75), 0.25 (unknown)
    vertices = np.column_stack([[0.1, 0.2, 0.5, 0.75, 0.9, 0.25], np.zeros(6), np.zeros(6)])
    result = pvs_votes(_FixedPVS(), vertices, np.eye(4))
    assert (result.free, result.unknown, result.occupied) == (2, 2, 2)
    assert result.score == pytest.approx((0.5 * 2 + 2) / (2 + 0.5 * 2 + 2))  # 0.6
    assert not result.accepted
    assert pvs_votes(_FixedPVS(), vertices, np.eye(4), threshold=0.6).accepted
    # Eq. 3.11 as printed: vertices only in unknown space give 1.0 (nothing contradicts the pose)
    assert pvs_votes(_FixedPVS(), np.full((4, 3), 0.5), np.eye(4)).score == pytest.approx(1.0)


def test_bad_input():
    with pytest.raises(ValueError):
        pvs_votes(_FixedPVS(), np.zeros((3, 2)), np.eye(4))
    with pytest.raises(ValueError):
        pvs_votes(_FixedPVS(), np.zeros((3, 3)), np.full((4, 4), np.nan))
    empty = pvs_votes(_FixedPVS(), np.zeros((0, 3)), np.eye(4))
    assert empty.score == 0.0 and not empty.accepted


@pytest.fixture(scope="module")
def scene(open_world):
    """tabletop after the overview scan, integrated into a 10 mm PVS."""
    from explore.mapping import PVS

    with open_world("tabletop", profile="ideal") as sim:
        pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.01)
        eye = np.array([0.0, -0.9, 1.35])
        pvs.integrate(sim.sensor.acquire(sim, look_at(eye, [0.0, 0.0, 0.65]), np.random.default_rng(0)))
        yield sim, pvs, eye


def test_right_pose_accepted_and_shifted_pose_rejected(scene):
    sim, pvs, eye = scene
    for body in sim.objects():
        vertices = body.mesh.vertices  # world frame: the right pose is the identity
        right = pvs_votes(pvs, vertices, np.eye(4))
        toward = eye - vertices.mean(axis=0)
        shifted = np.eye(4)
        shifted[:3, 3] = 0.05 * toward / np.linalg.norm(toward)  # 5 cm into observed free space
        wrong = pvs_votes(pvs, vertices, shifted)
        assert right.score >= 0.66 and right.accepted, (body.name, right)
        assert wrong.score < 0.66 and not wrong.accepted, (body.name, wrong)
        assert wrong.free > right.free


def test_plugin(registry, scene):
    sim, pvs, _ = scene
    validator = registry.plugins[("pose_validator", "pvs_votes")].create({"threshold": 0.9})
    duck = next(b for b in sim.objects() if b.name == "duck")
    result = validator.validate_hypothesis(SimpleNamespace(pose=np.eye(4)), pvs, duck.mesh.vertices)
    assert result.score == pytest.approx(pvs_votes(pvs, duck.mesh.vertices, np.eye(4)).score)
    assert result.accepted == (result.score >= 0.9)
    assert set(result.as_dict()) == {"score", "free", "unknown", "occupied", "accepted", "margin"}
    assert result.margin == pytest.approx(result.score - 0.9)
    with pytest.raises(ValueError):
        registry.plugins[("pose_validator", "pvs_votes")].create({"free_below": 0.8, "occupied_from": 0.7})


def test_under_kinect_artefacts_the_votes_decide_wherever_the_view_saw(open_world) -> None:
    """The same check with the world's Kinect profile and the scene exploration's flying-pixel
    filter. A missing return clears nothing there (a projector shadow cannot be told from empty
    space), so a pose shifted into a shadow meets unknown space, which Eq. 3.11 does not count
    against it: every right pose is accepted, and every shifted pose is rejected unless most of
    its vertices fall where the view gave no evidence (then q_h has to decide)."""
    from explore.mapping import PVS
    from explore.perception import filter_depth_scan

    with open_world("tabletop") as sim:
        pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.01)
        eye = np.array([0.0, -0.9, 1.35])
        pvs.integrate(filter_depth_scan(sim.sensor.acquire(sim, look_at(eye, [0.0, 0.0, 0.65]),
                                                           np.random.default_rng(0))))
        rejected = 0
        for body in sim.objects():
            vertices = body.mesh.vertices
            toward = eye - vertices.mean(axis=0)
            shifted = np.eye(4)
            shifted[:3, 3] = 0.05 * toward / np.linalg.norm(toward)
            right, wrong = pvs_votes(pvs, vertices, np.eye(4)), pvs_votes(pvs, vertices, shifted)
            assert right.accepted, (body.name, right)
            assert not wrong.accepted or wrong.unknown > wrong.free + wrong.occupied, (body.name, wrong)
            rejected += not wrong.accepted
        assert rejected >= 5


CUBE_TABLE = """
name: cube_table
environment:
  - {name: table, source: table/table.urdf, position: [0.0, 0.0, 0.3125]}
objects:
  - {name: cube, source: cube_small.urdf, size: 0.0366, rpy_deg: [0, 0, 30], position: [0.0, 0.0], on_top_of: table}
region: {min: [-0.2, -0.2, 0.625], max: [0.2, 0.2, 0.75]}
robot: {plugin: free_flyer}
sensor: {plugin: depth_camera, params: {profile: ideal, width: 320, height: 240, min_range: 0.3, max_range: 2.0}}
"""


def test_a_model_with_few_vertices_votes_with_samples_of_its_faces(open_world, tmp_path) -> None:
    """A 3.7 cm cube has 8 vertices, all on edges, whose 5 mm voxels the beams grazing past it see
    free: each vertex is an eighth of the vote, and poses within 2 mm / 2° of the truth (what
    recognition gives) fall to v_h 0.625 and are rejected. Samples on its faces (one per voxel
    area) carry the vote: every such pose is accepted, and a pose 2 cm towards a camera, in
    seen free space, is still rejected."""
    from scipy.spatial.transform import Rotation

    from explore.mapping import PVS
    from explore.perception import vote_points

    path = tmp_path / "cube_table.yaml"
    path.write_text(CUBE_TABLE)
    with open_world(path) as sim:
        pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.005)
        rng = np.random.default_rng(0)
        eyes = [np.array([0.5 * np.cos(a), 0.5 * np.sin(a), 1.0]) for a in np.radians([-90, 30, 150])]
        for eye in eyes:
            pvs.integrate(sim.sensor.acquire(sim, look_at(eye, [0.0, 0.0, 0.65]), rng))
        mesh = next(b for b in sim.objects() if b.name == "cube").mesh  # world frame: the truth is the identity
    points = vote_points(mesh, 0.005)
    centre = mesh.vertices.mean(axis=0)
    vertex_votes, sample_votes = [], []
    for dx, dy, yaw in np.array(np.meshgrid([-2, -1, 0, 1, 2], [-2, -1, 0, 1, 2], [-2, -1, 0, 1, 2])).reshape(3, -1).T:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("z", yaw, degrees=True).as_matrix()
        pose[:3, 3] = centre - pose[:3, :3] @ centre + [dx * 1e-3, dy * 1e-3, 0.0]
        vertex_votes.append(pvs_votes(pvs, mesh.vertices, pose).score)
        sample_votes.append(pvs_votes(pvs, points, pose).score)
    shifted = np.eye(4)
    shifted[:3, 3] = 0.02 * (eyes[0] - centre) / np.linalg.norm(eyes[0] - centre)
    assert len(mesh.vertices) == 8 and len(points) > 300
    assert min(vertex_votes) < 0.66, min(vertex_votes)
    assert min(sample_votes) > 0.9, min(sample_votes)
    assert not pvs_votes(pvs, points, shifted).accepted
    assert np.array_equal(points, vote_points(mesh, 0.005))  # the same samples every time
