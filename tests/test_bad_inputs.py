"""The bad-input catalogue (tests/bad_inputs/): every case ends with its documented exit code (2 for bad
input) and one line of at most 300 characters, never a traceback, leaves no file or folder behind and
touches no user data. Plus the signals (SIGINT, SIGTERM) and property-based fuzzing of the parsers.

World and tree files carry ``# expect: TEXT`` on their first line; ``cli.txt`` holds the command lines.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from explore.core.errors import MAX_LINE, BadInput

BAD = Path(__file__).parent / "bad_inputs"
EXPLORE = Path(sys.executable).parent / "explore"


def _expect(path: Path) -> str:
    first = path.read_bytes().split(b"\n", 1)[0].decode()
    assert first.startswith("# expect: "), path
    return first[len("# expect: "):]


def _run_only(path: Path) -> bool:
    """A world that is fine to look at but not to run (``# only: run`` on its second line)."""
    return b"# only: run" in path.read_bytes().split(b"\n", 2)[1]


def _cli_cases() -> list[tuple[int, str, str]]:
    cases = []
    for line in (BAD / "cli.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            code, expect, args = (part.strip() for part in line.split("|", 2))
            cases.append((int(code), expect, args))
    return cases


SQLITE_SIDE_FILES = ("-shm", "-wal", "-journal")


def _snapshot(folder: Path) -> dict[str, str]:
    """Every file and folder under ``folder`` with a hash of its content; SQLite's side files, which a
    test in another worker reading a catalogue database opens and removes while this one lists, left out."""
    out = {}
    for path in sorted(folder.rglob("*")):
        if path.name.endswith(SQLITE_SIDE_FILES):
            continue
        key = str(path.relative_to(folder))
        out[key] = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def catalogue_snapshot() -> dict[str, str]:
    return _snapshot(BAD)


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """The case's working directory with {file}, {db} and {mesh}; EXPLORE_DB points into it."""
    from explore.perception.database import ObjectDatabase
    from explore.sim.meshes import box_mesh

    work = tmp_path / "work"
    work.mkdir()
    (work / "existing.txt").write_text("user data\n")
    db = work / "objects.db"
    with ObjectDatabase.open(db, create=True) as database:
        database.add("cube", box_mesh([0.05, 0.05, 0.05]), provenance="given")
    mesh = work / "cube.obj"
    mesh.write_text("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0 0 0.05\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    monkeypatch.chdir(work)
    monkeypatch.setenv("EXPLORE_DB", str(work / "default.db"))
    return {"tmp": str(work), "bad": str(BAD), "file": str(work / "existing.txt"), "db": str(db), "mesh": str(mesh),
            "long": "y" * 300}


def _main(argv: list[str], capfd) -> tuple[int, list[str], str]:
    """Run the CLI in this process; (exit code, stderr lines, stdout). An exception escaping it is a traceback."""
    from explore_cli.main import main

    code = main(argv)
    out, err = capfd.readouterr()
    return code, [line for line in err.splitlines() if line.strip()], out


def _check_one_line(code: int, lines: list[str], want_code: int, expect: str) -> None:
    assert code == want_code, lines
    if want_code == 0:
        assert not lines, lines
        return
    assert len(lines) == 1, lines
    assert len(lines[0]) <= MAX_LINE and "Traceback" not in lines[0], lines[0]
    assert expect in lines[0], lines[0]


@pytest.mark.parametrize("case", sorted(p.name for p in (BAD / "worlds").glob("*.yaml")))
def test_bad_world(case: str, sandbox, capfd, catalogue_snapshot) -> None:
    path = BAD / "worlds" / case
    expect = _expect(path)
    before = _snapshot(Path(sandbox["tmp"]))
    show, run = ["worlds", "show", str(path)], ["run", "model_object", "--world", str(path), "--out", "run", "-q"]
    for argv in ([run] if _run_only(path) else [show, run]):
        code, lines, _ = _main(argv, capfd)
        _check_one_line(code, lines, 2, expect)
    assert _snapshot(Path(sandbox["tmp"])) == before  # no run folder, no database left behind
    assert _snapshot(BAD) == catalogue_snapshot


@pytest.mark.parametrize("case", sorted(p.name for p in (BAD / "trees").glob("*.yaml")))
def test_bad_tree(case: str, sandbox, capfd, catalogue_snapshot) -> None:
    path = BAD / "trees" / case
    expect = _expect(path)
    before = _snapshot(Path(sandbox["tmp"]))
    for argv in (["tree", "validate", str(path)], ["run", str(path), "--world", "bunny_pedestal", "--out", "run"]):
        code, lines, _ = _main(argv, capfd)
        _check_one_line(code, lines, 2, expect)
    assert _snapshot(Path(sandbox["tmp"])) == before
    assert _snapshot(BAD) == catalogue_snapshot


@pytest.mark.parametrize(("code", "expect", "args"), _cli_cases(), ids=lambda v: str(v)[:60])
def test_bad_command_line(code: int, expect: str, args: str, sandbox, capfd, catalogue_snapshot) -> None:
    work = Path(sandbox["tmp"])
    before = _snapshot(work)
    argv = [arg.format(**sandbox) for arg in shlex.split(args)]
    got, lines, _ = _main(argv, capfd)
    _check_one_line(got, lines, code, expect)
    after = _snapshot(work)  # no folder left behind, the database and the user's file untouched
    assert after == before, sorted(set(after.items()) ^ set(before.items()))
    assert _snapshot(BAD) == catalogue_snapshot


def test_the_catalogue_is_large_and_covers_every_class() -> None:
    worlds = list((BAD / "worlds").glob("*.yaml"))
    trees = list((BAD / "trees").glob("*.yaml"))
    lines = _cli_cases()
    assert len(worlds) + len(trees) + len(lines) + len(SIGNAL_CASES) >= 150
    commands = {args.split()[0] for _, _, args in lines}
    assert {"run", "scan", "compare", "tree", "worlds", "plugins", "db"} <= commands


# -- signals: the results so far are written, one line, the documented exit code ----------------------
SIGNAL_CASES = [
    ("run", signal.SIGTERM, 143), ("run", signal.SIGINT, 130),
    ("compare", signal.SIGTERM, 143), ("compare", signal.SIGINT, 130),
]


@pytest.mark.slow
@pytest.mark.parametrize(("command", "sig", "code"), SIGNAL_CASES, ids=lambda v: str(v))
def test_a_signal_ends_with_the_results_so_far(command, sig, code, tmp_path) -> None:
    out = tmp_path / "out"
    if command == "run":
        args = [str(EXPLORE), "run", "model_object", "--world", "workcell", "--out", str(out), "-q"]
        ready = out / "trace.jsonl"
    else:
        args = [str(EXPLORE), "compare", "--tree", "model_object", "--worlds", "bunny_pedestal,duck_pedestal",
                "--seeds", "3", "--jobs", "1", "--out", str(out)]
        ready = out / "results.csv"
    # a suite started in the background without job control ignores SIGINT, and the child would inherit that
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if ready.exists() and (command == "compare" or '"event": "integrated"' in ready.read_text()):
            break  # a run: once its first scan is in the model (its 21 first trace lines come before any scan)
        time.sleep(0.2)
    time.sleep(2.0)
    process.send_signal(sig)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == code, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr and len([line for line in stderr.splitlines() if line.strip()]) <= 1, stderr
    if command == "run":
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["status"] == "interrupted"
        assert metrics["reason"] == ("terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted")
        assert (out / "pvs.npz").exists() and (out / "model.ply").exists()
        last = json.loads((out / "trace.jsonl").read_text().splitlines()[-1])
        assert last["event"] == "end" and last["status"] == "interrupted"
        assert stdout.strip().splitlines()[-1].startswith(("terminated", "interrupted"))
    else:
        assert "run the same command to resume" in stdout
        assert (out / "results.csv").exists()


# -- property-based fuzzing: any YAML document is a valid object or one BadInput line --------------
_LEAF = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                  st.text(max_size=12))
_DOC = st.recursive(_LEAF, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                        max_size=4), max_leaves=25)
_WORLD = yaml.safe_load((Path(__file__).parents[1] / "worlds" / "bunny_pedestal.yaml").read_text())
_TREE = yaml.safe_load((Path(__file__).parents[1] / "trees" / "model_object.yaml").read_text())


def _paths(value, prefix=()):
    yield prefix
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _paths(item, (*prefix, i))


def _mutated(document, path, new):
    import copy

    out = copy.deepcopy(document)
    if not path:
        return new
    target = out
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = new
    return out


def _one_bad_input_line(error: BadInput) -> None:
    line = error.line()
    assert "\n" not in line and len(line) <= MAX_LINE


_FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@_FUZZ
@given(data=st.data())
def test_world_parser_fuzzing(data, tmp_path_factory) -> None:
    from explore.sim.world import load_world_spec

    if data.draw(st.booleans()):
        document = data.draw(_DOC)
    else:
        path = data.draw(st.sampled_from(list(_paths(_WORLD))))
        document = _mutated(_WORLD, path, data.draw(_DOC))
    file = tmp_path_factory.mktemp("fuzz") / "world.yaml"
    file.write_text(yaml.safe_dump(document, allow_unicode=True), encoding="utf-8")
    try:
        load_world_spec(file)
    except BadInput as error:
        _one_bad_input_line(error)


@_FUZZ
@given(text=st.text(max_size=200))
def test_world_parser_fuzzing_raw_text(text, tmp_path_factory) -> None:
    from explore.sim.world import load_world_spec

    file = tmp_path_factory.mktemp("fuzz") / "world.yaml"
    file.write_text(text, encoding="utf-8")
    try:
        load_world_spec(file)
    except BadInput as error:
        _one_bad_input_line(error)


@_FUZZ
@given(data=st.data())
def test_tree_parser_fuzzing(data, registry, tmp_path_factory) -> None:
    from explore.runtime.trees import load_tree

    if data.draw(st.booleans()):
        document = data.draw(_DOC)
    else:
        path = data.draw(st.sampled_from(list(_paths(_TREE))))
        document = _mutated(_TREE, path, data.draw(_DOC))
    file = tmp_path_factory.mktemp("fuzz") / "tree.yaml"
    file.write_text(yaml.safe_dump(document, allow_unicode=True), encoding="utf-8")
    try:
        load_tree(file, registry)
    except BadInput as error:
        _one_bad_input_line(error)


def test_generated_files_are_current(tmp_path) -> None:
    """The committed catalogue is what make_cases.py writes (re-run it after changing a case)."""
    scratch = tmp_path / "bad_inputs"
    shutil.copytree(BAD, scratch)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    subprocess.run([sys.executable, str(scratch / "make_cases.py")], check=True, env=env, timeout=120)
    fresh = {k: v for k, v in _snapshot(scratch).items() if "databases" not in k}
    assert fresh == {k: v for k, v in _snapshot(BAD).items() if "databases" not in k}
