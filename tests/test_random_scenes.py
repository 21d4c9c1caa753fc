"""The unseen tables of benchmarks/random_scenes.py: every scene loads, its five objects are different
``random_urdfs`` shapes that no world, benchmark or test named, two known, each resting on the table
inside the region and apart from the others."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from random_scenes import NAMED, scene_world  # noqa: E402

from explore.sim import Simulation  # noqa: E402

pytestmark = pytest.mark.timeout(300)


@pytest.mark.parametrize("index", range(8))
def test_an_unseen_scene_loads_with_its_objects_apart_on_the_table(registry, tmp_path: Path, index: int) -> None:
    world = scene_world(index)
    path = tmp_path / f"{world['name']}.yaml"
    path.write_text(yaml.safe_dump(world, sort_keys=False))
    with Simulation(str(path), registry) as sim:
        bodies = sim.objects()
        assert len({b.name for b in bodies}) == 5 and not {b.name[1:] for b in bodies} & NAMED
        assert [b.known for b in bodies] == [True, True, False, False, False]
        boxes = [b.mesh.bounds for b in bodies]
        for lo, hi in boxes:
            assert np.all(lo >= sim.spec.region_min) and np.all(hi <= sim.spec.region_max)
            assert lo[2] == pytest.approx(0.625, abs=3e-3)  # on the table top
        for (lo_a, hi_a), (lo_b, hi_b) in itertools.combinations(boxes, 2):
            assert np.max(np.maximum(lo_a[:2] - hi_b[:2], lo_b[:2] - hi_a[:2])) > 0.05  # segmentable apart
