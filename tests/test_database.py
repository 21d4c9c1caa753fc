"""Object database: round trip, seeding, concurrency, refusing bad files, the CLI."""

from __future__ import annotations

import multiprocessing
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from explore.core import BadInput
from explore.perception import ObjectDatabase
from explore.sim import TriMesh, box_mesh


def _mesh(size: float = 0.1) -> TriMesh:
    return box_mesh(np.array([size, size * 0.5, size * 0.8]))


def test_round_trip(tmp_path):
    path = tmp_path / "objects.db"
    descriptor = np.arange(12, dtype=float).reshape(3, 4)
    with ObjectDatabase.open(path) as db:
        record = db.add("box", _mesh(), provenance="modelled", world="tabletop", run="r1", scans=7, coverage=0.93,
                        descriptors={"vfh": (descriptor, {"bins": 308})})
        assert record.provenance == "modelled" and record.scans == 7
        db.set_location("box", "tabletop", np.eye(4), bbox=np.array([[0, 0, 0], [1, 1, 1]]))
        pose = np.eye(4)
        pose[:3, 3] = [0.1, 0.2, 0.3]
        db.set_location("box", "tabletop", pose)
    with ObjectDatabase.open(path, create=False) as db:
        assert db.names() == ["box"] and "box" in db and len(db) == 1
        record = db.get("box")
        assert np.allclose(record.mesh.vertices, _mesh().vertices)
        assert np.array_equal(record.mesh.triangles, _mesh().triangles)
        assert record.coverage == pytest.approx(0.93) and record.world == "tabletop" and record.run == "r1"
        assert np.allclose(record.extent, [0.1, 0.05, 0.08])
        array, params = db.descriptors("box")["vfh"]
        assert np.array_equal(array, descriptor) and params == {"bins": 308}
        assert np.allclose(record.location["pose"], pose)
        out = db.export("box", tmp_path / "out" / "box.ply")
        assert out.is_file()
        with pytest.raises(BadInput, match="exists"):
            db.add("box", _mesh())
        db.add("box", _mesh(0.2), replace=True)
        assert db.get("box").extent[0] == pytest.approx(0.2)
        assert len(list(db.mesh_dir.glob("*.ply"))) == 1  # the replaced mesh is gone
        models = db.models()
        assert [m.name for m in models] == ["box"]
        db.remove("box")
        assert db.names() == [] and not list(db.mesh_dir.glob("*.ply"))
        with pytest.raises(BadInput, match="no object"):
            db.get("box")
        with pytest.raises(BadInput, match="valid object name"):
            db.add("../evil", _mesh())
        with pytest.raises(BadInput, match="provenance"):
            db.add("x", _mesh(), provenance="stolen")


def test_missing_database_without_create(tmp_path):
    with pytest.raises(BadInput, match="no such object database"):
        ObjectDatabase.open(tmp_path / "none.db", create=False)
    assert not (tmp_path / "none.db").exists()


def test_seed_from_world(open_world, tmp_path):

    with open_world("tabletop") as sim, ObjectDatabase.open(tmp_path / "o.db") as db:
        truth = db.seed_from_world(sim)
        assert sorted(truth) == db.names() == ["duck", "mug"]
        for name, pose in truth.items():
            record = db.get(name)
            assert record.provenance == "given" and record.world == "tabletop"
            body = next(b for b in sim.objects() if b.name == name)
            # the stored mesh in its object frame, placed at the pose, is the ground truth
            placed = record.mesh.vertices + pose[:3, 3]
            assert np.allclose(placed, body.mesh.vertices, atol=1e-6)
            assert np.allclose(record.location["pose"], pose)
        db.seed_from_world(sim)  # idempotent
        assert len(db) == 2


def _writer(path: str, prefix: str, count: int) -> None:
    from explore.perception import ObjectDatabase
    from explore.sim import box_mesh

    with ObjectDatabase.open(path) as db:
        for i in range(count):
            db.add(f"{prefix}{i:02d}", box_mesh(np.array([0.05, 0.05, 0.05 + 0.001 * i])),
                   descriptors={"vfh": np.full(308, float(i))})


def test_concurrent_writers(tmp_path):
    path = tmp_path / "shared.db"
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_writer, args=(str(path), prefix, 20)) for prefix in ("a", "b")]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(120)
        assert worker.exitcode == 0
    with ObjectDatabase.open(path, create=False) as db:
        assert len(db) == 40
        assert db.connection.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        for name in db.names():
            record = db.get(name)
            assert record.mesh is not None and len(record.mesh.triangles) == 12
        assert len(list(db.mesh_dir.glob("*.ply"))) == 40
        assert not list(db.mesh_dir.glob(".tmp-*"))


def _valid_db(path: Path) -> None:
    with ObjectDatabase.open(path) as db:
        for i in range(30):
            db.add(f"o{i}", _mesh(), descriptors={"ppf": np.random.default_rng(i).normal(size=(200, 7))})


@pytest.mark.parametrize("damage", ["random_bytes", "page_garbage", "truncated", "text"])
def test_corrupted_file_refused_and_untouched(tmp_path, damage):
    path = tmp_path / "objects.db"
    if damage == "random_bytes":
        path.write_bytes(np.random.default_rng(0).bytes(10000))
    elif damage == "text":
        path.write_text("name,mesh\nduck,duck.obj\n")
    else:
        _valid_db(path)
        data = bytearray(path.read_bytes())
        if damage == "page_garbage":
            data[4096 : 4096 + 2000] = np.random.default_rng(1).bytes(2000)
        else:
            data = data[: len(data) // 3]
        path.write_bytes(bytes(data))
    before = path.read_bytes()
    with pytest.raises(BadInput, match="not an explore object database"):
        ObjectDatabase.open(path)
    assert path.read_bytes() == before
    assert not Path(str(path) + "-wal").exists()


def test_foreign_sqlite_refused(tmp_path):
    path = tmp_path / "other.db"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE objects (name TEXT)")
    con.execute("INSERT INTO objects VALUES ('x')")
    con.commit()
    con.close()
    before = path.read_bytes()
    with pytest.raises(BadInput, match="another program"):
        ObjectDatabase.open(path)
    assert path.read_bytes() == before


def test_newer_schema_refused(tmp_path):
    path = tmp_path / "objects.db"
    _valid_db(path)
    con = sqlite3.connect(path)
    con.execute("PRAGMA user_version = 99")
    con.commit()
    con.close()
    before = path.read_bytes()
    with pytest.raises(BadInput, match="newer"):
        ObjectDatabase.open(path)
    assert path.read_bytes() == before


@pytest.mark.parametrize("lock", ["EXCLUSIVE", "IMMEDIATE"])
def test_a_database_locked_past_the_busy_timeout_is_said_to_be_locked_not_corrupted(tmp_path, monkeypatch, lock):
    """Another process holding the file's lock (a run adding its models) is not a damaged file: opening and
    writing say "locked", and the other process's data stays."""
    from explore.perception import database, database_files

    path = tmp_path / "objects.db"
    with ObjectDatabase.open(path) as db:
        db.add("box", _mesh())
    monkeypatch.setattr(database, "BUSY_TIMEOUT_S", 0.2)
    monkeypatch.setattr(database_files, "BUSY_TIMEOUT_S", 0.2)
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute(f"BEGIN {lock}")
    try:
        with pytest.raises(BadInput, match="locked by another process") as error:
            with ObjectDatabase.open(path) as db:
                db.add("other", _mesh())
        assert "corrupt" not in str(error.value)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    with ObjectDatabase.open(path, create=False) as db:
        assert db.names() == ["box"]


def test_cli_exit_codes(tmp_path, capsys, monkeypatch):
    from explore_cli.main import main

    from explore.sim import read_mesh

    monkeypatch.chdir(tmp_path)
    db = str(tmp_path / "cli.db")
    mesh = tmp_path / "cube.ply"
    ObjectDatabase.open(tmp_path / "scratch.db").close()
    import open3d as o3d

    o3d.io.write_triangle_mesh(str(mesh), _mesh().to_open3d())
    assert main(["db", "add", "cube", str(mesh), "--scale", "0.5", "--db", db]) == 0
    assert main(["db", "list", "--db", db]) == 0
    assert "cube" in capsys.readouterr().out
    assert main(["db", "show", "cube", "--db", db]) == 0
    assert '"provenance": "given"' in capsys.readouterr().out
    assert main(["db", "export", "cube", "--out", str(tmp_path / "out.obj"), "--db", db]) == 0
    assert np.allclose(np.ptp(read_mesh(tmp_path / "out.obj").vertices, axis=0), [0.05, 0.025, 0.04])
    (tmp_path / "mine.ply").write_text("the user's own file\n")  # kept unless --replace
    assert main(["db", "export", "cube", "--out", str(tmp_path / "mine.ply"), "--db", db]) == 2
    assert (tmp_path / "mine.ply").read_text() == "the user's own file\n"
    assert main(["db", "export", "cube", "--out", str(tmp_path / "mine.ply"), "--db", db, "--replace"]) == 0
    assert len(read_mesh(tmp_path / "mine.ply").vertices) == 8
    capsys.readouterr()
    # bad input: one line on stderr, exit code 2
    for argv in (
        ["db", "show", "nothing", "--db", db],
        ["db", "add", "cube", str(mesh), "--db", db],
        ["db", "add", "x", str(tmp_path / "missing.obj"), "--db", db],
        ["db", "add", "x", str(mesh), "--scale", "-1", "--db", db],
        ["db", "remove", "nothing", "--db", db],
        ["db", "list", "--db", str(tmp_path / "absent.db")],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.startswith("error:") and len(err.splitlines()) == 1, err
    garbage = tmp_path / "garbage.db"
    garbage.write_bytes(b"\x00not a database" * 100)
    before = garbage.read_bytes()
    assert main(["db", "add", "cube", str(mesh), "--db", str(garbage)]) == 2
    assert "not an explore object database" in capsys.readouterr().err
    assert garbage.read_bytes() == before
    # $EXPLORE_DB and the default runs/objects.db (nothing lands in the current folder by surprise)
    monkeypatch.setenv("EXPLORE_DB", db)
    assert main(["db", "remove", "cube"]) == 0
    monkeypatch.delenv("EXPLORE_DB")
    assert main(["db", "add", "cube", str(mesh)]) == 0
    assert (tmp_path / "runs" / "objects.db").is_file() and not (tmp_path / "objects.db").exists()
    capsys.readouterr()
    shutil.rmtree(tmp_path / "runs")
    (tmp_path / "runs").write_text("a file where the default database's folder would go")
    for argv in (["db", "add", "cube", str(mesh)], ["tree", "show", "model_object", "--format", "png"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "runs" in err, err
    assert (tmp_path / "runs").read_text().startswith("a file")


def test_reading_never_modifies_a_file(tmp_path, capsys):
    """`db list/show/export` open read-only: an empty file is refused and stays empty (no schema written)."""
    from explore_cli.main import main

    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    for argv in (["db", "list", "--db", str(empty)], ["db", "show", "x", "--db", str(empty)],
                 ["db", "export", "x", "--out", str(tmp_path / "x.ply"), "--db", str(empty)]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "is empty" in err and len(err.splitlines()) == 1
        assert empty.read_bytes() == b""
    assert not list(tmp_path.glob("empty.db-*")) and not (tmp_path / "empty.meshes").exists()
    path = tmp_path / "full.db"
    with ObjectDatabase.open(path) as db:
        db.add("box", _mesh())
    before = path.read_bytes()
    with ObjectDatabase.open(path, readonly=True) as db:
        assert db.names() == ["box"]
        with pytest.raises(sqlite3.OperationalError):
            db.connection.execute("DELETE FROM objects")
    assert path.read_bytes() == before


def test_locations_history(tmp_path):
    with ObjectDatabase.open(tmp_path / "o.db") as db:
        db.add("box", _mesh())
        assert db.locations("box") == [] and db.location("box") is None
        for x in (0.1, 0.2, 0.3):
            pose = np.eye(4)
            pose[0, 3] = x
            db.set_location("box", "w", pose)
        assert [loc["pose"][0][3] for loc in db.locations("box")] == [0.1, 0.2, 0.3]
        assert db.location("box")["pose"][0][3] == 0.3  # last known
        assert db.locations("box", last=True)[0]["pose"][0][3] == 0.3


def test_db_add_stores_descriptors_and_provenance(tmp_path, capsys):
    """`explore db add` stores the PPF model clouds and VFH signatures a recogniser then reuses."""
    import open3d as o3d
    from explore_cli.main import main

    from explore.perception import PPFRecognizer, VFHRecognizer

    mesh = tmp_path / "box.ply"
    o3d.io.write_triangle_mesh(str(mesh), _mesh().to_open3d())
    db = tmp_path / "d.db"
    assert main(["db", "add", "box", str(mesh), "--world", "lab", "--db", str(db)]) == 0
    assert "ppf, vfh" in capsys.readouterr().out
    assert main(["db", "add", "bare", str(mesh), "--no-descriptors", "--db", str(db)]) == 0
    with ObjectDatabase.open(db, create=False) as database:
        record = database.get("box")
        assert record.descriptor_kinds == ("ppf", "vfh") and record.world == "lab" and record.provenance == "given"
        assert database.get("bare").descriptor_kinds == ()
        model = next(m for m in database.models() if m.name == "box")
    ppf = PPFRecognizer()
    stored = model.descriptors["ppf"][0]
    assert np.allclose(ppf.table(model).cloud.points, stored[stored[:, 6] > 0.5, :3])  # read, not recomputed
    vfh = VFHRecognizer()
    assert np.allclose(vfh.model_data(model).signatures, model.descriptors["vfh"][0][:, :308])
