# ruff: noqa: E501 - a table of cases, one per line
"""Writes the bad-input catalogue's world, tree, mesh, results and database files (run once; the files are committed).

    python tests/bad_inputs/make_cases.py

Each world and tree file starts with ``# expect: TEXT``: the one error line must contain TEXT.
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

HERE = Path(__file__).parent

GOOD_WORLD = """name: {name}
environment:
  - name: pedestal
    box: [0.10, 0.10, 0.50]
    position: [0.0, 0.0, 0.25]
objects:
  - name: bunny
    source: bunny.obj
    size: 0.15
    rpy_deg: [90, 0, 0]
    position: [0.0, 0.0]
    on_top_of: pedestal
region:
  min: [-0.13, -0.13, 0.50]
  max: [0.13, 0.13, 0.72]
robot:
  plugin: free_flyer
sensor:
  plugin: laser_striper
"""

# name -> (expected text, replacements (old, new) applied to GOOD_WORLD, or the whole text)
WORLDS: dict[str, tuple[str, list[tuple[str, str]] | str]] = {
    "malformed": ("malformed YAML", [("min: [-0.13", "min: [[-0.13")]),
    "list_document": ("expected a mapping", "- a\n- b\n"),
    "scalar_document": ("expected a mapping", "just text\n"),
    "empty_file": ("expected a mapping", ""),
    "unknown_top_field": ("unknown field", [("robot:", "robots: 1\nrobot:")]),
    "missing_region": ("region: missing", [("region:\n  min: [-0.13, -0.13, 0.50]\n  max: [0.13, 0.13, 0.72]\n", "")]),
    "region_inverted": ("max must be greater", [("max: [0.13, 0.13, 0.72]", "max: [0.13, 0.13, 0.40]")]),
    "region_nan": ("not a finite number", [("min: [-0.13", "min: [.nan")]),
    "region_inf": ("not a finite number", [("max: [0.13", "max: [.inf")]),
    "region_short": ("expected a list of 3 numbers", [("min: [-0.13, -0.13, 0.50]", "min: [-0.13, -0.13]")]),
    "region_strings": ("expected a number", [("min: [-0.13, -0.13, 0.50]", "min: [a, b, c]")]),
    "region_bool": ("expected a number", [("min: [-0.13, -0.13, 0.50]", "min: [true, -0.13, 0.5]")]),
    "objects_mapping": ("expected a list", [("objects:\n  - name: bunny", "objects:\n  bunny:\n    name: bunny")]),
    "object_no_name": ("name: missing", [("  - name: bunny\n", "  - source_x: 1\n")]),
    "object_empty_name": ("expected a non-empty string", [("name: bunny", "name: ''")]),
    "object_path_name": ("objects[0].name: '../../evil' is not a valid body name", [("name: bunny", "name: ../../evil")]),
    "environment_spaced_name": ("environment[0].name: 'the pedestal' is not a valid body name",
                                [("- name: pedestal", "- name: the pedestal"), ("on_top_of: pedestal", "on_top_of: the pedestal")]),
    "object_no_position": ("position: missing", [("    position: [0.0, 0.0]\n", "")]),
    "object_xy_without_support": ("give x, y, z", [("    on_top_of: pedestal\n", "")]),
    "object_on_unknown_body": ("no body named", [("on_top_of: pedestal", "on_top_of: shelf")]),
    "object_two_shapes": ("exactly one of box", [("source: bunny.obj", "source: bunny.obj\n    sphere: 0.1")]),
    "env_no_shape": ("exactly one of box", [("    box: [0.10, 0.10, 0.50]\n", "")]),
    "box_negative": ("extents must be positive", [("box: [0.10, 0.10, 0.50]", "box: [0.10, -0.10, 0.50]")]),
    "box_zero": ("extents must be positive", [("box: [0.10, 0.10, 0.50]", "box: [0, 0.10, 0.50]")]),
    "cylinder_no_radius": ("radius: missing", [("box: [0.10, 0.10, 0.50]", "cylinder: {length: 0.5}")]),
    "cylinder_unknown": ("unknown field", [("box: [0.10, 0.10, 0.50]", "cylinder: {radius: 0.1, length: 0.5, r: 1}")]),
    "sphere_zero": ("must be positive", [("box: [0.10, 0.10, 0.50]", "sphere: 0")]),
    "object_too_small": ("objects[0].size: the object is 1e-09 m across", [("size: 0.15", "size: 1.0e-9")]),
    "position_huge": ("is beyond ±10000", [("position: [0.0, 0.0, 0.25]", "position: [0.0, 1.0e+30, 0.25]")]),
    "source_missing": ("file not found", [("source: bunny.obj", "source: no_such_mesh.obj")]),
    "source_name_too_long": ("File name too long", [("source: bunny.obj", "source: " + "y" * 300 + ".obj")]),
    "source_bad_suffix": ("unsupported file type", [("source: bunny.obj", "source: ../meshes/notes.txt")]),
    "source_obj_garbage": ("cannot read mesh", [("source: bunny.obj", "source: ../meshes/garbage.obj")]),
    "source_obj_bad_face": ("a face refers to a vertex", [("source: bunny.obj", "source: ../meshes/bad_face.obj")]),
    "source_obj_nan_vertex": ("not a finite number", [("source: bunny.obj", "source: ../meshes/nan_vertex.obj")]),
    "source_obj_zero_area": ("every triangle has zero area",
                             [("source: bunny.obj", "source: ../meshes/zero_area.obj")]),
    "source_obj_empty": ("no triangles", [("source: bunny.obj", "source: ../meshes/empty.obj")]),
    "source_ply_garbage": ("cannot read mesh", [("source: bunny.obj", "source: ../meshes/garbage.ply")]),
    "source_stl_garbage": ("cannot read mesh", [("source: bunny.obj", "source: ../meshes/garbage.stl")]),
    "source_urdf_garbage": ("pybullet cannot load it", [("source: bunny.obj", "source: ../meshes/garbage.urdf")]),
    "source_sdf_several_models": ("stadium.sdf holds 3 models", [("source: bunny.obj", "source: stadium.sdf")]),
    "source_urdf_no_visual": ("no visual geometry", [("source: bunny.obj", "source: ../meshes/no_visual.urdf")]),
    "source_is_folder": ("file not found", [("source: bunny.obj", "source: ../meshes")]),
    "source_in_millimetres": ("is its mesh in millimetres?", [("source: bunny.obj", "source: ../meshes/box_mm.obj"), ("    size: 0.15\n", "")]),
    "scale_negative": ("must be positive", [("size: 0.15", "scale: -1")]),
    "scale_and_size": ("either size or scale", [("size: 0.15", "size: 0.15\n    scale: 2")]),
    "scale_list_short": ("expected a list of 3 numbers", [("size: 0.15", "scale: [1, 2]")]),
    "size_string": ("expected a number", [("size: 0.15", "size: big")]),
    "known_not_bool": ("expected true or false", [("on_top_of: pedestal", "on_top_of: pedestal\n    known: maybe")]),
    "color_short": ("expected a list of 3 or 4 numbers", [("on_top_of: pedestal", "on_top_of: pedestal\n    color: [1, 0]")]),
    "color_0_255": ("divide by 255", [("on_top_of: pedestal", "on_top_of: pedestal\n    color: [255, 0, 0]")]),
    "color_negative": ("components lie in [0, 1]", [("on_top_of: pedestal", "on_top_of: pedestal\n    color: [0.5, -0.1, 0, 1]")]),
    "specular_above_one": ("mirror share of the reflected light lies in [0, 1]", [("on_top_of: pedestal", "on_top_of: pedestal\n    specular: 1.5")]),
    "specular_word": ("specular: expected a number", [("on_top_of: pedestal", "on_top_of: pedestal\n    specular: shiny")]),
    "rpy_strings": ("expected a number", [("rpy_deg: [90, 0, 0]", "rpy_deg: [ninety, 0, 0]")]),
    "duplicate_body_names": ("used by two bodies", [("name: bunny", "name: pedestal")]),
    "object_outside_region": ("region", [("max: [0.13, 0.13, 0.72]", "max: [0.13, 0.13, 0.60]")]),
    "object_not_over_support": ("is not over the top of 'pedestal'", [("position: [0.0, 0.0]", "position: [0.5, 0.0]")]),
    "objects_intersect": ("intersects objects[0] (bunny)",
                          [("region:", "  - {name: block, box: [0.06, 0.06, 0.06], position: [0.0, 0.0], on_top_of: pedestal}\nregion:")]),
    "robot_unknown": ("unknown robot 'roomba'", [("plugin: free_flyer", "plugin: roomba")]),
    "robot_starts_inside": ("robot.base: the robot starts inside 'bunny', 'pedestal'",
                            [("plugin: free_flyer", "plugin: arm\n  base: [0.0, 0.0, 0.0, 0.0]")]),
    "robot_unknown_param": ("unknown parameter", [("plugin: free_flyer", "plugin: free_flyer\n  params: {wheels: 4}")]),
    "robot_params_list": ("expected a mapping", [("plugin: free_flyer", "plugin: free_flyer\n  params: [1, 2]")]),
    "sensor_missing": ("sensor: missing", [("sensor:\n  plugin: laser_striper\n", "")]),
    "sensor_unknown": ("unknown sensor", [("plugin: laser_striper", "plugin: lidar9000")]),
    "sensor_wrong_unit": ("wrong unit 'm'", [("plugin: laser_striper", "plugin: laser_striper\n  params: {fan_deg: 5 m}")]),
    "sensor_unknown_unit": ("unknown unit", [("plugin: laser_striper", "plugin: laser_striper\n  params: {fan_deg: 5 zz}")]),
    "sensor_param_nan": ("not a finite number", [("plugin: laser_striper", "plugin: laser_striper\n  params: {fan_deg: .nan}")]),
    "sensor_param_string": ("expected a number", [("plugin: laser_striper", "plugin: laser_striper\n  params: {fan_deg: wide}")]),
    "sensor_empty_plugin": ("expected a non-empty string", [("plugin: laser_striper", "plugin: ''")]),
    "overview_same_point": ("eye and target are the same point",
                            [("sensor:\n", "overview: {eye: [0, 0, 1], target: [0, 0, 1]}\nsensor:\n")]),
    "overview_no_target": ("target: missing", [("sensor:\n", "overview: {eye: [0, 0, 1]}\nsensor:\n")]),
    "overview_unknown_field": ("unknown field", [("sensor:\n", "overview: {eye: [0, 0, 1], target: [0, 0, 0], up: 1}\nsensor:\n")]),
    "duplicate_key": ("duplicate key 'robot'", [("sensor:\n", "robot: free_flyer\nsensor:\n")]),
    "duplicate_nested_key": ("duplicate key 'size'", [("size: 0.15", "size: 0.15\n    size: 0.2")]),
    "number_key": ("a field name must be text, got '0E0'", [("sensor:\n", "0E0: 1\nsensor:\n")]),
    "alias_bomb": ("aliases expand this document beyond", "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
                   + "".join(f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
                             f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
                             f"*{chr(97 + i)}, *{chr(97 + i)}]\n" for i in range(9))),
    "recursive_alias": ("a recursive alias", "a: &a [1, *a]\n"),
    "deep_nesting": ("nested too deeply", "a: " + "[" * 3000 + "]" * 3000 + "\n"),
    "huge_region": ("would need", [("min: [-0.13, -0.13, 0.50]", "min: [-1000, -1000, 0.50]"),
                                   ("max: [0.13, 0.13, 0.72]", "max: [1000, 1000, 100]")]),
    "tab_indentation": ("malformed YAML", [("  - name: pedestal", "\t- name: pedestal")]),
    "binary_junk": ("not UTF-8 text", ""),
    "latin1_name": ("not UTF-8 text", ""),
    "description_list": ("description: expected text", [("robot:", "description: [a, b]\nrobot:")]),
    "description_empty_list": ("description: expected text", [("robot:", "description: []\nrobot:")]),
    "objects_zero": ("objects: expected a list", [(
        "objects:\n  - name: bunny\n    source: bunny.obj\n    size: 0.15\n    rpy_deg: [90, 0, 0]\n"
        "    position: [0.0, 0.0]\n    on_top_of: pedestal\n", "objects: 0\n")]),
    "robot_empty_name": ("robot: an empty name", [("robot:\n  plugin: free_flyer", "robot: ''")]),
    "sensor_params_zero": ("sensor.params: expected a mapping", [("plugin: laser_striper", "plugin: laser_striper\n  params: 0")]),
    "objects_empty": ("objects: no object to model", [(
        "objects:\n  - name: bunny\n    source: bunny.obj\n    size: 0.15\n    rpy_deg: [90, 0, 0]\n"
        "    position: [0.0, 0.0]\n    on_top_of: pedestal\n", "objects: []\n")]),
}

RUN_ONLY = {"huge_region", "objects_empty"}  # fine to look at (worlds show), rejected before a run

GOOD_TREE = """name: {name}
root:
  sequence: Model object
  memory: true
  children:
    - behaviour: start_modelling
    - behaviour: check_flag
      params: {{key: done}}
"""

TREES: dict[str, tuple[str, list[tuple[str, str]] | str]] = {
    "malformed": ("malformed YAML", [("memory: true", "memory: [true")]),
    "not_mapping": ("a tree file is a mapping", "- sequence: s\n"),
    "empty": ("a tree file is a mapping", ""),
    "no_root": ("root: missing", "name: x\n"),
    "unknown_top_field": ("unknown field", [("root:", "roots: 1\nroot:")]),
    "root_list": ("a node is a mapping", "root: [1, 2]\n"),
    "unknown_behaviour": ("unknown behaviour 'scna'", [("start_modelling", "scna")]),
    "unknown_node_type": ("exactly one node type key", [("sequence: Model object", "seqence: Model object")]),
    "two_types": ("exactly one node type key", [("sequence: Model object", "sequence: Model object\n  selector: x")]),
    "unknown_attribute": ("unknown attribute", [("memory: true", "memory: true\n  memroy: true")]),
    "memory_string": ("expected bool", [("memory: true", "memory: yes please")]),
    "children_mapping": ("expected list", [("children:\n    - behaviour: start_modelling\n    - behaviour: check_flag\n"
                                            "      params: {key: done}", "children: {a: 1}")]),
    "no_children": ("needs at least one child", [("children:\n    - behaviour: start_modelling\n    - behaviour: "
                                                  "check_flag\n      params: {key: done}", "children: []")]),
    "param_unknown": ("unknown parameter", [("params: {key: done}", "params: {kye: done}")]),
    "param_wrong_type": ("expected true or false", [("params: {key: done}", "params: {key: done, expect: perhaps}")]),
    "params_list": ("expected dict", [("params: {key: done}", "params: [key, done]")]),
    "behaviour_number": ("expected a behaviour name", [("- behaviour: start_modelling", "- behaviour: 42")]),
    "retry_no_attempts": ("needs 'attempts'", "root: {retry: r, child: {behaviour: start_modelling}}\n"),
    "retry_zero": ("must be a positive finite number", "root: {retry: r, attempts: 0, child: {behaviour: start_modelling}}\n"),
    "retry_bool": ("expected int", "root: {retry: r, attempts: true, child: {behaviour: start_modelling}}\n"),
    "timeout_nan": ("must be a positive finite number", "root: {timeout: t, seconds: .nan, child: {behaviour: start_modelling}}\n"),
    "timeout_inf": ("must be a positive finite number", "root: {timeout: t, seconds: .inf, child: {behaviour: start_modelling}}\n"),
    "timeout_negative": ("must be a positive finite number", "root: {timeout: t, seconds: -1, child: {behaviour: start_modelling}}\n"),
    "repeat_until_on_max": ("expected success or failure",
                            "root: {repeat_until: r, until: done, on_max: maybe, child: {behaviour: start_modelling}}\n"),
    "parallel_policy": ("expected success_on_all or success_on_one",
                        "root: {parallel: p, policy: first, children: [{behaviour: start_modelling}]}\n"),
    "until_unwritten": ("no behaviour of the tree writes 'don'",
                        "root: {repeat_until: r, until: don, child: {behaviour: start_modelling}}\n"),
    "node_name_list": ("expected the node's name", [("sequence: Model object", "sequence: [Model object]")]),
    "tree_name_list": ("name: expected text", "name: [a]\nroot: {behaviour: start_modelling}\n"),
    "flag_unwritten": ("root.children[1].params.key: no behaviour of the tree writes 'dnoe'",
                       [("params: {key: done}", "params: {key: dnoe}")]),
    "for_each_empty_as": ("root.as: an empty blackboard key",
                          "root: {for_each: f, items: unknown, as: '', child: {behaviour: start_modelling}}\n"),
    "for_each_no_as": ("needs 'as'", "root: {for_each: f, items: xs, child: {behaviour: start_modelling}}\n"),
    "one_shot_on": ("expected completion or success", "root: {one_shot: o, on: never, child: {behaviour: start_modelling}}\n"),
    "missing_include": ("root.children[1].include: 'no_such_tree.yaml': no such tree file",
                        [("- behaviour: check_flag\n      params: {key: done}", "- include: no_such_tree.yaml")]),
    "include_number": ("expected a tree name or file", [("- behaviour: check_flag\n      params: {key: done}", "- include: 7")]),
    "include_cycle": ("include cycle", "root: {include: include_cycle.yaml}\n"),
    "include_bad_file": ("malformed YAML", "root: {include: ../trees_included/broken.yaml}\n"),
    "include_latin1": ("not UTF-8 text", "root: {include: ../trees_included/latin1.yaml}\n"),
    "duplicate_key": ("duplicate key 'memory'", [("memory: true", "memory: true\n  memory: false")]),
    "alias_bomb": ("aliases expand this document beyond", WORLDS["alias_bomb"][1]),
    "binary_junk": ("not UTF-8 text", ""),
}


def _text(template: str, name: str, spec: list[tuple[str, str]] | str) -> str:
    if isinstance(spec, str):
        return spec
    text = template.format(name=name)
    for old, new in spec:
        assert old in text, (name, old)
        text = text.replace(old, new)
    return text


def write_cases() -> None:
    for folder, cases, template in (("worlds", WORLDS, GOOD_WORLD), ("trees", TREES, GOOD_TREE)):
        out = HERE / folder
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        for name, (expect, spec) in cases.items():
            only = "# only: run\n" if name in RUN_ONLY else ""
            body = f"# expect: {expect}\n{only}".encode() + _text(template, name, spec).encode()
            if name == "binary_junk":
                body = f"# expect: {expect}\n".encode() + bytes(range(128, 256)) + b"\n"
            elif name == "latin1_name":
                body = f"# expect: {expect}\n".encode() + GOOD_WORLD.format(name="caf\xe9").encode("latin-1")
            (out / f"{name}.yaml").write_bytes(body)
    included = HERE / "trees_included"
    shutil.rmtree(included, ignore_errors=True)
    included.mkdir()
    (included / "broken.yaml").write_text("root: [oops\n")
    (included / "latin1.yaml").write_bytes("name: caf\xe9\nroot: {behaviour: start_modelling}\n".encode("latin-1"))
    meshes = HERE / "meshes"
    shutil.rmtree(meshes, ignore_errors=True)
    meshes.mkdir()
    (meshes / "notes.txt").write_text("not a mesh\n")
    (meshes / "garbage.obj").write_text("v 0 0 zero\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (meshes / "bad_face.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    (meshes / "nan_vertex.obj").write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (meshes / "zero_area.obj").write_text("v 0 0 0\nv 0.05 0 0\nv 0.1 0 0\nv 0.05 0 0\nf 1 2 3\nf 2 3 4\n")
    (meshes / "empty.obj").write_text("# nothing\n")
    (meshes / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    (meshes / "garbage.stl").write_bytes(b"solid x\nfacet normal 0 0\nendsolid\n")
    (meshes / "garbage.urdf").write_text("<robot name='x'><link name='a'><visual>")
    corners = [(x, y, z) for x in (0, 80) for y in (0, 60) for z in (0, 40)]  # a box in millimetres
    faces = [(1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2), (3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4)]
    (meshes / "box_mm.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    (meshes / "no_visual.urdf").write_text("<robot name='x'><link name='a'/></robot>\n")
    write_results()
    write_databases()


def write_results() -> None:
    """Folders with a bad results.csv for ``explore compare --plot-only``."""
    out = HERE / "results"
    shutil.rmtree(out, ignore_errors=True)
    cases = {
        "latin1": "run_id,status\nr1,succ\xe8s\n".encode("latin-1"),
        "not_a_table": b"just some words\nand more\n",
        "binary": bytes(range(256)),
        "no_status_column": b"run_id,world\nr1,w\n",
        "bad_quotes": b'run_id,status,reason\nr1,success,"never closed\n',
        "unknown_status": b"run_id,status\nr1,success\nr2,banana\n",
        "empty_run_id": b"run_id,status\n,success\n",
        "coverage_word": b"run_id,status,coverage\nr1,success,0.9\nr2,success,high\n",
        "coverage_nan": b"run_id,status,coverage\nr1,success,nan\n",
        "per_scan_not_list": b"run_id,status,coverage_per_scan\nr1,success,0.5\n",
    }
    for name, data in cases.items():
        (out / name).mkdir(parents=True)
        (out / name / "results.csv").write_bytes(data)
    grids = {"grid_garbage": b"not json {", "grid_list": b"[1, 2]\n"}  # a good results.csv, a damaged compare.json
    for name, data in grids.items():
        (out / name).mkdir(parents=True)
        (out / name / "results.csv").write_bytes(b"run_id,status,coverage\nr1,success,0.9\n")
        (out / name / "compare.json").write_bytes(data)


def write_databases() -> None:
    """Database files that are not explore object databases (or not intact ones)."""
    out = HERE / "databases"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    (out / "text.db").write_text("this is not a database\n")
    (out / "empty.db").write_bytes(b"")
    with sqlite3.connect(out / "other_app.db") as con:
        con.execute("CREATE TABLE contacts (name TEXT, phone TEXT)")
        con.execute("INSERT INTO contacts VALUES ('a', '1')")
    con.close()
    from explore.perception.database import ObjectDatabase
    from explore.sim.meshes import box_mesh

    good = out / "_good.db"
    with ObjectDatabase.open(good, create=True) as db:
        db.add("cube", box_mesh([0.05, 0.05, 0.05]), provenance="given")
    data = good.read_bytes()
    (out / "truncated.db").write_bytes(data[: len(data) // 3])
    future = out / "future_schema.db"
    future.write_bytes(data)
    with sqlite3.connect(future) as con:
        con.execute("PRAGMA user_version = 999")
    con.close()
    for path in out.glob("_good*"):
        shutil.rmtree(path) if path.is_dir() else path.unlink()


if __name__ == "__main__":
    write_cases()
