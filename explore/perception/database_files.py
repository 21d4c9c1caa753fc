"""The object database's file rules: what an explore object database file is (SQLite header, application id,
schema version, tables), checked through a read-only connection before anything writes, so that a foreign or
corrupted file is refused and left untouched; meshes written atomically before their row is committed."""

from __future__ import annotations

import os
import sqlite3
import tempfile
from pathlib import Path

import numpy as np

from explore.core import BadInput
from explore.sim import TriMesh

SCHEMA_VERSION = 1

APPLICATION_ID = 0x45585052  # "EXPR"

SQLITE_MAGIC = b"SQLite format 3\x00"

BUSY_TIMEOUT_S = 30.0

SCHEMA = """
CREATE TABLE objects (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    mesh_file TEXT NOT NULL,
    provenance TEXT NOT NULL CHECK (provenance IN ('given', 'modelled')),
    world TEXT,
    run TEXT,
    scans INTEGER,
    coverage REAL,
    vertices INTEGER NOT NULL,
    triangles INTEGER NOT NULL,
    extent TEXT NOT NULL,
    created TEXT NOT NULL
);
CREATE TABLE descriptors (
    object_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
    kind TEXT NOT NULL,
    params TEXT NOT NULL,
    blob BLOB NOT NULL,
    created TEXT NOT NULL,
    PRIMARY KEY (object_id, kind)
);
CREATE TABLE locations (
    id INTEGER PRIMARY KEY,
    object_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
    world TEXT,
    pose TEXT NOT NULL,
    bbox TEXT,
    time TEXT NOT NULL
);
CREATE INDEX locations_object ON locations(object_id, id);
"""

_TABLES = {"objects", "descriptors", "locations"}


def _foreign(path: Path, why: str, error: sqlite3.Error | None = None) -> BadInput:
    message = f"not an explore object database ({why}); the file was left untouched"
    return BadInput(str(path), None, message) if error is None else refused(path, error, message)


def is_locked(error: sqlite3.Error) -> bool:
    """True for SQLite's "database is locked" / "busy": another connection held its lock past the busy timeout
    (the file is fine)."""
    return isinstance(error, sqlite3.OperationalError) and any(w in str(error) for w in ("locked", "busy"))


def refused(path: Path, error: sqlite3.Error, message: str) -> BadInput:
    """The one-line error for an SQLite failure: ``message``, unless another process kept the file locked (then
    that, not a corrupted or foreign file)."""
    if not is_locked(error):
        return BadInput(str(path), None, message)
    return BadInput(str(path), None, f"locked by another process for {BUSY_TIMEOUT_S:.0f} s (an explore run or "
                    "`explore db` command writing to it?); try again when it has finished; the file was left untouched")


def validate_existing(path: Path) -> None:
    """Refuse a file that is not an explore database, reading it through a read-only connection."""
    try:
        with open(path, "rb") as handle:
            header = handle.read(len(SQLITE_MAGIC))
    except OSError as error:
        raise BadInput(str(path), None, f"cannot read the object database: {error}") from None
    if len(header) == 0:
        return  # an empty file is an empty SQLite database (another process may be creating it)
    if header != SQLITE_MAGIC:
        raise _foreign(path, "not an SQLite file")
    # SQLite may create -wal/-shm side files even for a read-only look; remove the ones we made
    side = [Path(f"{path}{suffix}") for suffix in ("-wal", "-shm")]
    created = [p for p in side if not p.exists()]
    try:
        _check_readonly(path)
    except BadInput:
        for p in created:
            if p.exists() and p.stat().st_size <= 32768:
                p.unlink(missing_ok=True)
        raise


def _check_readonly(path: Path) -> None:
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=BUSY_TIMEOUT_S)
    except sqlite3.Error as error:
        raise _foreign(path, str(error), error) from None
    try:
        app = con.execute("PRAGMA application_id").fetchone()[0]
        version = con.execute("PRAGMA user_version").fetchone()[0]
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if version == 0 and app == 0 and not tables:
            return  # a fresh, empty SQLite file
        check_identity(path, app, version, tables)
        check = con.execute("PRAGMA quick_check").fetchone()[0]
        if check != "ok":
            raise _foreign(path, f"corrupted: {check}")
    except sqlite3.DatabaseError as error:
        raise _foreign(path, f"corrupted: {error}", error) from None
    finally:
        con.close()


def check_identity(path: Path, app: int, version: int, tables: set[str]) -> None:
    if app != APPLICATION_ID:
        raise _foreign(path, "an SQLite file of another program")
    if version > SCHEMA_VERSION:
        raise BadInput(str(path), None, f"schema version {version} is newer than this explore ({SCHEMA_VERSION})")
    if version < 1 or not _TABLES <= tables:
        raise _foreign(path, f"schema version {version} with tables {sorted(tables)}")


def write_mesh_atomic(mesh: TriMesh, target: Path) -> None:
    """Write a binary PLY next to ``target`` and rename it into place."""
    import open3d as o3d

    target.parent.mkdir(parents=True, exist_ok=True)
    o3d_mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(mesh.vertices, dtype=float)),
        o3d.utility.Vector3iVector(np.asarray(mesh.triangles, dtype=np.int32)),
    )
    fd, tmp = tempfile.mkstemp(suffix=".ply", prefix=".tmp-", dir=target.parent)
    os.close(fd)
    try:
        if not o3d.io.write_triangle_mesh(tmp, o3d_mesh, write_ascii=False):
            raise OSError(f"cannot write {target}")
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
