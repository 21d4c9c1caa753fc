"""Tree files: validation (one clear line), includes and cycles, decorators, failure reasons;
the CLI's exit codes for bad input; the worker that keeps long steps off the tick."""

from __future__ import annotations

import json
import threading

import pytest

from explore.core import BadInput, Param
from explore.runtime import ExploreBehaviour, Registry, RunConfig, build, execute, failure, hookimpl, load_tree, success


class Count(ExploreBehaviour):
    """Test behaviour: increments a counter; sets `done` after `until` calls."""

    name = "test_count"
    writes = ("done", "count")
    params = (Param("until", int, 3, "", "calls before done", low=1),)

    def work(self):
        count = (self.read("count", 0) if self.bb.is_registered("count") else 0) + 1
        self.write("count", count)
        self.write("done", count >= self.p["until"])
        return success(f"count {count}")

    def setup(self, **kwargs):
        super().setup(**kwargs)
        self.bb.register_key("count", access=__import__("py_trees").common.Access.READ)


class Fail(ExploreBehaviour):
    """Test behaviour that fails with a reason."""

    name = "test_fail"
    params = (Param("reason", str, "gripper on fire", "", "why"),)
    blocking = True

    def work(self):
        return failure(self.p["reason"])


GATES: dict[str, threading.Event] = {}


class Wait(ExploreBehaviour):
    """Test behaviour: a long step in the worker that ends when its gate opens (or after 30 s)."""

    name = "test_wait"
    blocking = True
    params = (Param("gate", str, "a", "", "name of the gate in GATES"),)

    def work(self):
        if GATES[self.p["gate"]].wait(timeout=30.0):
            return success("gate opened")
        return failure("gate never opened")


class _TestPlugins:
    @hookimpl
    def explore_register_plugins(self, register) -> None:
        register(Count)
        register(Fail)
        register(Wait)


@pytest.fixture(scope="module")
def reg() -> Registry:
    return Registry.load(extra=[("tests", _TestPlugins())])


def _write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


LOOP = """
name: loop
root:
  repeat_until: Loop
  until: done
  child:
    behaviour: test_count
    params: {until: 4}
"""


def test_shipped_trees_validate(registry) -> None:
    from explore.runtime import list_trees

    trees = list_trees()
    assert {"model_object"} <= {p.stem for p in trees}
    for path in trees:
        parsed = load_tree(path, registry)
        assert parsed.root.type in ("sequence", "selector", "parallel", "repeat_until")
        build(parsed.root, registry)


BAD_TREES = [
    ("root: {behaviour: scna}\n", "root.behaviour: unknown behaviour 'scna' ("),
    ("root: {behaviour: test_count, params: {until: -1}}\n", "root.params.until: -1 is below the minimum 1"),
    ("root: {behaviour: test_count, params: {untill: 2}}\n", "root.params.untill: unknown parameter"),
    ("root: {sequence: s, children: []}\n", "root.children: needs at least one child"),
    ("root: {sequence: s, selector: t, children: []}\n",
     "root: a node needs exactly one node type key; found sequence, selector"),
    ("root: {sequence: s, memroy: true, children: [{behaviour: test_count}]}\n", "root.memroy: unknown attribute"),
    ("root: {retry: r, child: {behaviour: test_count}}\n", "root.attempts: a retry node needs 'attempts'"),
    ("root: {timeout: t, seconds: -2, child: {behaviour: test_count}}\n",
     "root.seconds: must be a positive finite number, got -2"),
    ("root: {include: missing.yaml}\n", "root.include: 'missing.yaml': no such tree file"),
    ("root: [oops\n", "malformed YAML"),
]


@pytest.mark.parametrize(("text", "message"), BAD_TREES)
def test_bad_tree_is_rejected_with_one_line(tmp_path, reg, text, message) -> None:
    path = _write(tmp_path, "bad.yaml", text)
    with pytest.raises(BadInput) as error:
        load_tree(path, reg)
    assert message in error.value.line()
    assert "\n" not in error.value.line()


def test_include_cycle_is_reported(tmp_path, reg) -> None:
    _write(tmp_path, "a.yaml", "root: {sequence: a, children: [{include: b.yaml}]}\n")
    _write(tmp_path, "b.yaml", "root: {sequence: b, children: [{include: a.yaml}]}\n")
    with pytest.raises(BadInput, match=r"include cycle: a.yaml -> b.yaml -> a.yaml"):
        load_tree(tmp_path / "a.yaml", reg)


def test_include_inserts_the_subtree(tmp_path, reg) -> None:
    _write(tmp_path, "sub.yaml", "root: {behaviour: test_count, params: {until: 2}}\n")
    path = _write(tmp_path, "main.yaml", "root: {sequence: main, children: [{include: sub.yaml, name: Counted}]}\n")
    root = load_tree(path, reg).root
    assert [n.name for n in root.walk()] == ["main", "Counted"]
    assert root.children[0].params == {"until": 2}


def test_repeat_until_runs_until_the_flag_and_writes_outputs(tmp_path, reg) -> None:
    path = _write(tmp_path, "loop.yaml", LOOP)
    result = execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    assert result.status == "success"
    assert result.reason == "done after 4 iterations"
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["status"] == "success" and metrics["tree"] == "loop" and metrics["world"] == "bunny_pedestal"
    events = [json.loads(line) for line in (tmp_path / "run" / "trace.jsonl").read_text().splitlines()]
    assert events[0]["event"] == "start" and events[-1]["event"] == "end"
    assert (tmp_path / "run" / "tree.dot").exists()


def test_failing_behaviour_reports_its_reason(tmp_path, reg) -> None:
    text = """
root:
  sequence: Mission
  children:
    - behaviour: test_count
    - behaviour: test_fail
      name: Grasp
      params: {reason: gripper on fire}
"""
    path = _write(tmp_path, "fail.yaml", text)
    result = execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    assert result.status == "failure"
    assert result.reason == "Grasp: gripper on fire"
    trace = (tmp_path / "run" / "trace.jsonl").read_text()
    assert '"reason": "gripper on fire"' in trace
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["reason"] == "Grasp: gripper on fire"


def test_a_step_run_before_the_one_that_writes_its_input_says_which_does(tmp_path, registry) -> None:
    """A user's tree that recognises before it starts the scene failed with "AttributeError: 'NoneType'
    object has no attribute 'session'"; now the step names the key and the behaviours that write it."""
    text = """
root:
  sequence: Mission
  children:
    - behaviour: recognise_objects
    - behaviour: start_scene
"""
    path = _write(tmp_path, "order.yaml", text)
    result = execute(RunConfig(tree=str(path), world="scene_small", out=tmp_path / "run"), registry)
    assert result.status == "failure"
    assert result.reason == ("recognise_objects: needs 'scene', which no step before it has written "
                             "(written by start_scene)")


def test_run_refuses_to_overwrite_a_run(tmp_path, reg) -> None:
    path = _write(tmp_path, "loop.yaml", LOOP)
    execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    before = (tmp_path / "run" / "metrics.json").read_text()
    with pytest.raises(BadInput, match="already holds a run"):
        execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    assert (tmp_path / "run" / "metrics.json").read_text() == before


def test_unknown_set_key_is_bad_input(tmp_path, reg) -> None:
    path = _write(tmp_path, "loop.yaml", LOOP)
    with pytest.raises(BadInput, match="--set: bogus.key: unknown setting"):
        execute(RunConfig(tree=str(path), world="bunny_pedestal", settings={"bogus.key": 1}, out=tmp_path / "r"), reg)
    config = RunConfig(tree=str(path), world="bunny_pedestal", settings={"test_count.until": 2}, out=tmp_path / "r2")
    assert execute(config, reg).reason == "done after 2 iterations"


def test_a_long_step_does_not_block_the_tick(tmp_path, reg) -> None:
    """The gate opens only from the tick callback: a step that blocked the tick would never end."""
    GATES["a"] = threading.Event()
    path = _write(tmp_path, "wait.yaml", "root: {behaviour: test_wait, params: {gate: a}}\n")
    ticks_while_running = []

    def on_tick(root, context) -> None:
        if root.status.value == "RUNNING":
            ticks_while_running.append(1)
            if len(ticks_while_running) >= 3:
                GATES["a"].set()

    result = execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg, on_tick)
    assert result.status == "success" and result.reason == "gate opened"
    assert len(ticks_while_running) >= 3


def test_a_timed_out_step_does_not_hold_up_the_next(tmp_path, reg) -> None:
    """The timed-out step keeps waiting in its thread; the fallback's step runs in a fresh one."""
    GATES["stuck"], GATES["free"] = threading.Event(), threading.Event()
    GATES["free"].set()
    text = """
root:
  selector: Try
  memory: true
  children:
    - timeout: Limit
      seconds: 0.2
      child: {behaviour: test_wait, name: Stuck, params: {gate: stuck}}
    - behaviour: test_wait
      name: Fallback
      params: {gate: free}
"""
    path = _write(tmp_path, "timeout.yaml", text)
    try:
        result = execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    finally:
        GATES["stuck"].set()  # let the abandoned step end
    assert result.status == "success"
    events = [json.loads(line) for line in (tmp_path / "run" / "trace.jsonl").read_text().splitlines()]
    assert any(e["event"] == "abandoned" and e["node"] == "Stuck" for e in events)
    assert any(e["event"] == "status" and e["node"] == "Fallback" and e["status"] == "SUCCESS" for e in events)


def test_a_failure_before_the_first_scan_still_writes_metrics(tmp_path, reg) -> None:
    """Modelling started, then a step failed: no mesh to write, but metrics.json with the reason."""
    text = """
root:
  sequence: Mission
  children:
    - behaviour: start_modelling
    - behaviour: test_fail
      name: Calibrate
      params: {reason: no calibration target}
"""
    path = _write(tmp_path, "early.yaml", text)
    result = execute(RunConfig(tree=str(path), world="bunny_pedestal", out=tmp_path / "run"), reg)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert result.status == "failure" and metrics["reason"] == "Calibrate: no calibration target"
    assert metrics["scans"] == 0 and metrics["files"]["mesh"] is None and "output_errors" not in metrics
    assert not (tmp_path / "run" / "model.ply").exists() and (tmp_path / "run" / "pvs.npz").exists()


# -- the command line: bad input is one line on stderr and exit code 2 ---------------------------


def _cli(args: list[str], capsys) -> tuple[int, list[str]]:
    from explore_cli.main import main

    code = main(args)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return code, err


CLI_BAD_TREES = [
    ("root: {behaviour: scna}\n", "root.behaviour: unknown behaviour 'scna' ("),
    ("root: {behaviour: register_scan, params: {radius: -3 mm}}\n", "root.params.radius: "),
    ("root: {behaviour: plan_motion, params: {initail: true}}\n", "root.params.initail: unknown parameter"),
    ("root: {include: b.yaml}\n", "include cycle: a.yaml -> b.yaml -> a.yaml"),
    ("root: [oops\n", "malformed YAML"),
]


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize(("text", "message"), CLI_BAD_TREES)
def test_cli_rejects_a_bad_tree_with_exit_2(tmp_path, capsys, command, text, message) -> None:
    _write(tmp_path, "a.yaml", text)
    _write(tmp_path, "b.yaml", "root: {include: a.yaml}\n")
    out = tmp_path / "run"
    args = ["tree", "validate", str(tmp_path / "a.yaml")] if command == "validate" else [
        "run", str(tmp_path / "a.yaml"), "--world", "bunny_pedestal", "--out", str(out), "-q"]
    code, err = _cli(args, capsys)
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]
    assert not out.exists()


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--planner", "rrt_conect"], "--planner: unknown motion_planner 'rrt_conect' (valid: "),
        (["--robot", "tank"], "--robot: unknown robot 'tank' (valid: "),
        (["--sensor", "sonar"], "--sensor: unknown sensor 'sonar' (valid: "),
        (["--strategy", "ig/bogus"], "--strategy: unknown strategy 'ig/bogus' (did you mean "),
        (["--set", "planner.time_limit=-1"], "--set: planner.time_limit: "),
        (["--set", "register_scan.iterations=0"], "--set: register_scan.iterations: "),
        (["--set", "tau=0.002"], "--set: tau: unknown setting"),
        (["--world", "atlantis"], "atlantis"),
        (["--rerun", "out.txt"], "--rerun: out.txt: expected a .rrd file"),
    ],
)
def test_cli_rejects_bad_names_before_creating_the_run(tmp_path, capsys, option, message) -> None:
    out = tmp_path / "run"
    world = [] if option[0] == "--world" else ["--world", "bunny_pedestal"]
    code, err = _cli(["run", "model_object", *world, *option, "--out", str(out), "-q"], capsys)
    assert code == 2
    assert len(err) == 1 and message in err[0]
    assert not out.exists()


def test_bad_input_never_touches_an_existing_folder(tmp_path, capsys) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    code, _ = _cli(["run", "model_object", "--world", "bunny_pedestal", "--planner", "nope", "--out", str(out)],
                   capsys)
    assert code == 2 and sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "keep me"


def test_tree_picture_labels_are_plain_text(tmp_path, registry) -> None:
    """py_trees' Unicode symbols (missing glyphs in Graphviz fonts) become words."""
    from explore.runtime import tree_dot

    root = build(load_tree("model_object", registry).root, registry)
    graph = tree_dot(root)
    labels = [n.get("label") for n in graph.get_nodes() if n.get("label")]
    assert '"Model object\\n(memory)"' in labels
    assert all(ch.isascii() for label in labels for ch in label)
    (legend,) = graph.get_subgraphs()  # a key of the node kinds beside the tree
    assert [n.get("label") for n in legend.get_nodes()] == ["sequence", "selector", "parallel", "decorator",
                                                              "behaviour"]


def test_run_refuses_a_folder_holding_a_file_it_would_write(tmp_path, reg) -> None:
    path = _write(tmp_path, "loop.yaml", LOOP)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "model.ply").write_text("the user's own model")
    (folder / "notes.txt").write_text("notes")
    with pytest.raises(BadInput, match="already holds model.ply, which a run would overwrite"):
        execute(RunConfig(tree=str(path), world="bunny_pedestal", out=folder), reg)
    assert (folder / "model.ply").read_text() == "the user's own model"
    assert sorted(p.name for p in folder.iterdir()) == ["model.ply", "notes.txt"]
