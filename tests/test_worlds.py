"""World files: every shipped world parses; placement; bad input is one line with exit 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explore.core import BadInput
from explore.sim import list_worlds, load_world_spec

SHIPPED = {"bunny_pedestal", "tabletop", "cluttered", "workcell", "two_tables"}


def test_required_worlds_are_shipped_and_parse() -> None:
    names = {p.stem for p in list_worlds()}
    assert SHIPPED <= names
    for path in list_worlds():
        spec = load_world_spec(path)
        assert spec.objects, path
        assert np.all(spec.region_max > spec.region_min)


def test_tabletop_has_six_objects_two_known() -> None:
    spec = load_world_spec("tabletop")
    assert len(spec.objects) == 6
    assert sorted(o.name for o in spec.objects if o.known) == ["duck", "mug"]


def test_numbers_with_an_exponent_and_no_dot_are_numbers(tmp_path) -> None:
    """YAML 1.1 reads ``15e-2`` as a string (it asks for ``15.0e-2``); world and tree files read it as
    YAML 1.2 and Python do, a number. Booleans stay true/false only."""
    from explore.core.user_files import parse_yaml

    assert parse_yaml("a: 15e-2\nb: -2E+3\nc: 1.5e-3\nd: e5\ne: on\nf: 7", "x") == \
        {"a": 0.15, "b": -2000.0, "c": 0.0015, "d": "e5", "e": "on", "f": 7}
    path = tmp_path / "bunny.yaml"
    path.write_text(Path(list_worlds()[0]).parent.joinpath("bunny_pedestal.yaml").read_text()
                    .replace("size: 0.15", "size: 15e-2"))
    assert load_world_spec(path).objects[0].size == pytest.approx(0.15)


def test_bunny_rests_on_the_pedestal_at_the_requested_size(bunny_sim) -> None:
    bunny = bunny_sim.object_mesh("bunny")
    lo, hi = bunny.bounds
    assert np.max(hi - lo) == pytest.approx(0.15, abs=1e-9)
    assert lo[2] == pytest.approx(0.5 + 5e-4, abs=1e-9)
    np.testing.assert_allclose(0.5 * (lo[:2] + hi[:2]), [0.0, 0.0], atol=1e-9)
    assert [b.name for b in bunny_sim.objects()] == ["bunny"]
    assert len(bunny_sim.environment_ids()) == 1


def test_bodies_dropped_into_a_shelf_bin_rest_on_its_sloped_floor(open_world) -> None:
    """In the Kiva pod (one mesh of four levels of bins) x, y, z with on_top_of drops a body from z
    straight down: every body's nearest vertex ends 0.5 mm (the contact gap) above the floor of the
    bin below it, which slopes by 2 cm from front to back, not on the pod's roof 2.37 m up."""
    from explore.sim import RayCaster

    with open_world("kiva_pod") as sim:
        pod = RayCaster([b.mesh for b in sim.bodies if not b.is_object], nthreads=1)
        for body in sim.objects():
            vertices = body.mesh.vertices
            fall, _, _ = pod.cast(vertices, np.tile([0.0, 0.0, -1.0], (len(vertices), 1)))
            assert np.nanmin(np.where(np.isfinite(fall), fall, np.nan)) == pytest.approx(5e-4, abs=1e-6), body.name
            assert 0.79 < vertices[:, 2].min() < 0.83, body.name


def test_urdf_bodies_match_pybullet(open_world) -> None:
    from explore.sim import p

    with open_world("tabletop") as sim:
        for body in sim.objects():
            lo, hi = body.mesh.bounds
            aabb_lo, aabb_hi = (np.array(v) for v in p.getAABB(body.body_id, -1, physicsClientId=sim.client))
            # pybullet's AABB adds a small margin around the collision shape
            assert np.all(lo > aabb_lo - 0.03) and np.all(hi < aabb_hi + 0.03), body.name
            assert body.mesh.bounds[0][2] >= 0.625 - 1e-6, body.name  # on the table top


@pytest.mark.parametrize("source", ["jenga/jenga.urdf", "domino/domino.urdf", "cube.obj"])
def test_a_turned_body_keeps_its_size(open_world, tmp_path, source) -> None:
    """``size`` is the largest extent in the body's own frame, for URDFs as for meshes: the same
    block turned 60° about z in a re-arranged world is the same block (a jenga block sized after its
    rotation came out 0.8 of its length)."""
    extents = []
    for yaw in (0, 60):
        path = tmp_path / f"turned{yaw}.yaml"
        turned = f"source: {source}, size: 0.1, rpy_deg: [0, 0, {yaw}],"
        path.write_text(GOOD.replace("source: bunny.obj, size: 0.1,", turned))
        with open_world(path) as sim:
            lo, hi = sim.object_mesh("bunny").bounds
            extents.append(hi - lo)
    assert np.max(extents[0]) == pytest.approx(0.1, abs=1e-6)
    assert extents[1][2] == pytest.approx(extents[0][2], abs=1e-6)  # the same height
    (a, b), c, s = extents[0][:2], np.cos(np.radians(60)), np.sin(np.radians(60))
    np.testing.assert_allclose(extents[1][:2], [a * c + b * s, a * s + b * c], rtol=1e-3)  # the same block, turned


GOOD = """
name: t
environment:
  - {name: pedestal, box: [0.1, 0.1, 0.5], position: [0, 0, 0.25]}
objects:
  - {name: bunny, source: bunny.obj, size: 0.1, position: [0, 0], on_top_of: pedestal}
region: {min: [-0.2, -0.2, 0.5], max: [0.2, 0.2, 0.8]}
sensor: laser_striper
"""

BAD = [
    ("name: [unclosed\n", "malformed YAML"),
    (GOOD.replace("bunny.obj", "nothing.obj"), "objects[0].source: file not found"),
    (GOOD.replace("size: 0.1,", "size: .nan,"), "objects[0].size: nan is not a finite number"),
    (
        GOOD.replace("position: [0, 0, 0.25]", "position: [0, .inf, 0.25]"),
        "environment[0].position[1]: inf is not a finite number",
    ),
    (GOOD.replace("size: 0.1,", "size: 0.5,"), "objects[0] (bunny): extends outside the region"),
    (GOOD.replace("sensor: laser_striper", "sensor: lidar"), "sensor: unknown sensor 'lidar' (valid: "),
    (
        GOOD.replace("sensor: laser_striper", "sensor: {plugin: laser_striper, params: {beams_per_stripe: many}}"),
        "sensor.params.beams_per_stripe: expected a number",
    ),
    (
        GOOD.replace("sensor: laser_striper", "sensor: {plugin: laser_striper, params: {fan_deg: 3 kg}}"),
        "sensor.params.fan_deg: unknown unit",
    ),
    (
        GOOD.replace("sensor: laser_striper", "sensor: {plugin: laser_striper, params: {colour: 1}}"),
        "sensor.params.colour: unknown parameter",
    ),
    (GOOD.replace("on_top_of: pedestal", "on_top_of: table"), "objects[0].on_top_of: no body named 'table'"),
    (GOOD.replace("region:", "regoin:"), "regoin: unknown field"),
    (GOOD.replace("position: [0, 0], on_top_of", "position: [0, 0, 0.3], on_top_of"),
     "objects[0].position: the body dropped from z = 0.25 (its lowest point) starts inside 'pedestal'"),
    (GOOD.replace("position: [0, 0], on_top_of", "position: [0.15, 0, 0.7], on_top_of"),
     "objects[0].position: nothing of 'pedestal' lies below the body dropped from z = 0.65"),
]


@pytest.mark.parametrize(("text", "message"), BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_bad_world_is_one_clear_line(open_world, tmp_path, text, message) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(BadInput) as error:
        open_world(load_world_spec(path)).close()
    line = error.value.line()
    assert line.startswith(str(path)) and message in line, line
    assert "\n" not in line


def test_bodies_touching_load_and_bodies_passing_through_each_other_do_not(open_world, tmp_path) -> None:
    """Two 4 cm cubes side by side with a 1 mm gap load; overlapping by 1 cm their faces cross
    along a 4 cm segment, a corner lies 1 cm inside the other, and the world is refused, naming
    both. A ball pressed 0.8 mm into its support only touches it."""
    from explore.sim.meshes import box_mesh
    from explore.sim.simulation import depth_behind, surface_crossings

    cube = box_mesh([0.04, 0.04, 0.04])
    apart = surface_crossings(cube, type(cube)(cube.vertices + [0.041, 0.0, 0.0], cube.triangles))
    crossing = surface_crossings(cube, type(cube)(cube.vertices + [0.03, 0.0, 0.0], cube.triangles))
    assert len(apart) == 0
    assert np.ptp(crossing, axis=0).max() == pytest.approx(0.04, abs=1e-6)
    moved = type(cube)(cube.vertices + [0.03, 0.0, 0.0], cube.triangles)
    assert depth_behind(moved, cube) == pytest.approx(0.01, abs=1e-6)  # its left face 1 cm inside
    pair = GOOD.replace("box: [0.1, 0.1, 0.5]", "box: [0.3, 0.3, 0.5]").replace(
        "region:", "  - {name: cube, box: [0.04, 0.04, 0.04], position: [0.0, %s], on_top_of: pedestal}\nregion:")
    path = tmp_path / "pair.yaml"
    path.write_text(pair % "0.09")  # beside the bunny (0.1 m long), not in it
    open_world(load_world_spec(path)).close()
    path.write_text(pair % "0.0")
    with pytest.raises(BadInput, match=r"objects\[1\] \(cube\): intersects objects\[0\] \(bunny\)"):
        open_world(load_world_spec(path)).close()
    # a 3 cm ball pressed 0.8 mm into the pedestal top (a hand-set height): touching, not intersecting
    path.write_text(GOOD.replace("region:", "  - {name: ball, sphere: 0.015, position: [0.06, 0.06, 0.5142]}\nregion:"))
    open_world(load_world_spec(path)).close()


def test_a_mesh_beyond_pybullets_limits_loads_and_keeps_its_surface(open_world, tmp_path) -> None:
    """A scanned object of 180 000 triangles (pybullet takes at most 524 288 indices) loads: the ground truth
    keeps every triangle, pybullet gets a decimated copy whose surface lies where the mesh's does (200 rays
    from above meet the 5 cm sphere within 0.1 mm of its radius)."""
    import open3d as o3d

    from explore.sim.bullet import p
    from explore.sim.simulation import PYBULLET_MAX_TRIANGLES

    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=300)
    assert len(sphere.triangles) > PYBULLET_MAX_TRIANGLES
    o3d.io.write_triangle_mesh(str(tmp_path / "dense.ply"), sphere)
    path = tmp_path / "dense.yaml"
    path.write_text(GOOD.replace("source: bunny.obj", f"source: {tmp_path / 'dense.ply'}"))
    with open_world(load_world_spec(path)) as sim:
        body = next(b for b in sim.bodies if b.name == "bunny")
        assert len(body.mesh.triangles) == len(sphere.triangles)
        centre = body.mesh.vertices.mean(axis=0)
        directions = np.random.default_rng(0).normal(size=(200, 3))
        directions[:, 2] = np.abs(directions[:, 2])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        rays = p.rayTestBatch((centre + 0.2 * directions).tolist(), [centre.tolist()] * 200,
                              physicsClientId=sim.client)
        assert {ray[0] for ray in rays} == {body.body_id}
        radius = np.linalg.norm(np.array([ray[3] for ray in rays]) - centre, axis=1)
        assert np.abs(radius - 0.05).max() < 1e-4


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", "from explore_cli.main import run; run()", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def test_cli_bad_world_exits_2_with_one_line_and_no_traceback(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(GOOD.replace("size: 0.1,", "size: .nan,"))
    result = _cli("worlds", "show", str(path))
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "objects[0].size" in lines[0] and "Traceback" not in result.stderr


def test_cli_scan_writes_ply_and_png(tmp_path) -> None:
    out, png = tmp_path / "scan.ply", tmp_path / "scan.png"
    result = _cli(
        "scan",
        "--world",
        "bunny_pedestal",
        "--look-from",
        "0.3,0,0.6",
        "--look-at",
        "0,0,0.56",
        "--out",
        str(out),
        "--png",
        str(png),
    )
    assert result.returncode == 0, result.stderr
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(str(out))
    assert len(cloud.points) > 5000
    assert png.stat().st_size > 10000
    assert "pybullet build time" not in result.stdout + result.stderr
    bad = _cli("scan", "--world", "bunny_pedestal", "--look-from", "0.3,nan,0.6", "--look-at", "0,0,0.56")
    assert bad.returncode == 2 and "--look-from" in bad.stderr and "Traceback" not in bad.stderr
    again = ["scan", "--world", "bunny_pedestal", "--look-from", "0.2,0,0.6", "--look-at", "0,0,0.56",
             "--out", str(out)]
    before = out.read_bytes()
    kept = _cli(*again)  # an existing file is the user's: only --replace overwrites it
    assert kept.returncode == 2 and "exists: use --replace" in kept.stderr and out.read_bytes() == before
    assert _cli(*again, "--replace").returncode == 0 and out.read_bytes() != before


def test_worlds_list_and_show(tmp_path) -> None:
    result = _cli("worlds", "show", "bunny_pedestal")
    assert result.returncode == 0, result.stderr
    assert "bunny" in result.stdout and "laser_striper" in result.stdout and "region" in result.stdout
    assert _cli("worlds", "show", "atlantis").returncode == 2


def test_worlds_list_marks_a_broken_file_and_lists_the_others(tmp_path) -> None:
    import os

    (tmp_path / "broken.yaml").write_bytes(b"name: broken\nregion: [oops\n")
    (tmp_path / "mine.yaml").write_text((Path(__file__).parents[1] / "worlds" / "duck_pedestal.yaml").read_text()
                                        .replace("name: duck_pedestal", "name: mine"))
    explore = Path(sys.executable).parent / "explore"
    done = subprocess.run([str(explore), "worlds", "list"], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "EXPLORE_WORLDS": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert "bunny_pedestal" in done.stdout and "mine" in done.stdout
    assert "broken world file:" in done.stdout and "malformed YAML" in done.stdout
