"""Tree files: validation (one clear line), includes and cycles, decorators, failure reasons."""

from __future__ import annotations

import json

import pytest

from explore.bt_behaviour import ExploreBehaviour, failure, success
from explore.errors import BadInput
from explore.hookspecs import hookimpl
from explore.params import Param
from explore.registry import Registry
from explore.run import RunConfig, execute
from explore.trees import build, load_tree


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


class _TestPlugins:
    @hookimpl
    def explore_register_plugins(self, register) -> None:
        register(Count)
        register(Fail)


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
    from explore.trees import list_trees

    trees = list_trees()
    assert {"model_object"} <= {p.stem for p in trees}
    for path in trees:
        parsed = load_tree(path, registry)
        assert parsed.root.type in ("sequence", "selector", "parallel", "repeat_until")
        build(parsed.root, registry)


BAD_TREES = [
    ("root: {behaviour: scna}\n", "root.behaviour: unknown behaviour 'scna' (valid: "),
    ("root: {behaviour: test_count, params: {until: -1}}\n", "root.params.until: -1 is below the minimum 1"),
    ("root: {behaviour: test_count, params: {untill: 2}}\n", "root.params.untill: unknown parameter"),
    ("root: {sequence: s, children: []}\n", "root.children: needs at least one child"),
    ("root: {sequence: s, selector: t, children: []}\n", "root: a node needs exactly one type key"),
    ("root: {sequence: s, memroy: true, children: [{behaviour: test_count}]}\n", "root.memroy: unknown attribute"),
    ("root: {retry: r, child: {behaviour: test_count}}\n", "root.attempts: a retry node needs 'attempts'"),
    ("root: {timeout: t, seconds: -2, child: {behaviour: test_count}}\n", "root.seconds: must be positive"),
    ("root: {include: missing.yaml}\n", "missing.yaml: no such tree file"),
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
