"""The reach limit of issue 20 (benchmarks/reach_limit.py): the sensor's cone from its beams, and which
surface samples a sensor pose sees (cone, range, incidence, occlusion) on a plate with numbers."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from reach_limit import sensor_cone, visible_from  # noqa: E402

from explore.sim import RayCaster, TriMesh  # noqa: E402

pytestmark = pytest.mark.timeout(120)


def _square(half: float, z: float, x0: float = 0.0) -> TriMesh:
    v = np.array([[x0 - half, -half, z], [x0 + half, -half, z], [x0 + half, half, z], [x0 - half, half, z]])
    return TriMesh(v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32))


def test_a_pose_sees_the_plate_inside_its_cone_and_range_and_not_behind_an_occluder(registry) -> None:
    striper = registry.get("sensor", "laser_striper").create({})
    axis, half_angle = sensor_cone(striper)
    np.testing.assert_allclose(axis, [0.0, 0.0, 1.0], atol=1e-9)  # beams fan about the optical (z) axis
    assert math.degrees(half_angle) == pytest.approx(12.0, abs=0.01)  # half the 24 deg fan
    grid = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 81), np.linspace(-0.1, 0.1, 81)), -1).reshape(-1, 2)
    points = np.column_stack([grid, np.zeros(len(grid))])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down from 0.3 m
    pose[2, 3] = 0.3
    lateral = np.hypot(points[:, 0], points[:, 1])
    in_cone = np.arctan2(lateral, 0.3) <= half_angle  # a 6.4 cm disc
    seen = visible_from(pose, points, normals, striper, RayCaster([_square(0.2, 0.0)]), axis, half_angle)
    np.testing.assert_array_equal(seen, in_cone)
    # a 2 cm square 10 cm below the sensor, centred over x = 2 cm: a line of sight crosses its height at a
    # third of the way, so it hides x in [3, 9] cm, |y| <= 3 cm (samples on the shadow's edge left out)
    occluded = visible_from(pose, points, normals, striper, RayCaster([_square(0.2, 0.0), _square(0.01, 0.2, 0.02)]),
                            axis, half_angle)
    offset = np.abs(points[:, :2] / 3.0 - [0.02, 0.0]).max(axis=1)
    shadow, clear = in_cone & (offset < 0.0099), in_cone & (offset > 0.0101)
    assert shadow.sum() > 100 and not occluded[shadow].any() and occluded[clear].all()
    # out of range (0.6 m away, the striper reaches 0.5 m) and seen from behind: nothing
    far = pose.copy()
    far[2, 3] = 0.6
    assert not visible_from(far, points, normals, striper, RayCaster([_square(0.2, 0.0)]), axis, half_angle).any()
    assert not visible_from(pose, points, -normals, striper, RayCaster([_square(0.2, 0.0)]), axis, half_angle).any()
