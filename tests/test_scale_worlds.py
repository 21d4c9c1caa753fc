"""The growing rooms of issue 23 (benchmarks/scale_worlds.py): every room loads in the simulation,
its objects stand on their tables inside the region, apart enough to be segmented, every third
one known, all different; the known tables are found by the patrol."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from scale_worlds import GROWTH, TABLE, write_world  # noqa: E402

from explore.sim import Simulation  # noqa: E402

pytestmark = pytest.mark.timeout(300)


@pytest.mark.parametrize("tables, objects", GROWTH)
def test_a_growing_room_loads_with_its_objects_apart_on_its_tables(registry, tmp_path: Path, tables: int,
                                                                   objects: int) -> None:
    from explore.scene import known_tables

    with Simulation(write_world(tmp_path, tables, objects), registry) as sim:
        bodies = sim.objects()
        assert len(bodies) == objects and len({b.source for b in sim.spec.objects}) == objects
        assert [b.known for b in bodies] == [k % 3 == 0 for k in range(objects)]
        assert len(known_tables(sim)) == tables
        lo_region, hi_region = sim.spec.region_min, sim.spec.region_max
        boxes = []
        for body in bodies:
            lo, hi = body.mesh.bounds
            assert np.all(lo >= lo_region) and np.all(hi <= hi_region), body.name
            assert lo[2] == pytest.approx(TABLE[2], abs=2e-3), body.name  # rests on a table top
            boxes.append((lo, hi))
        gaps = [np.max(np.maximum(a[0][:2] - b[1][:2], b[0][:2] - a[1][:2]))
                for a, b in itertools.combinations(boxes, 2)]
        assert min(gaps) >= 0.05, min(gaps)  # footprints 5 cm or more apart


def test_a_room_refuses_more_objects_than_its_tables_hold(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="do not fit"):
        write_world(tmp_path, 1, 13)
