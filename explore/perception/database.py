"""The object database: an SQLite file (rollback journal: one file, nothing beside it at rest) with a folder
of meshes beside it.

Layout: ``objects.db`` plus ``objects.meshes/`` (one binary PLY per object). The schema is
versioned with ``PRAGMA user_version`` and stamped with ``PRAGMA application_id`` so that a
foreign SQLite file is recognised. Tables:

- ``objects``: name (unique), mesh file, provenance (``given`` | ``modelled``), world, run,
  number of scans, coverage estimate, creation time;
- ``descriptors``: per object and kind (``ppf``, ``vfh``, ...) an ``np.save`` blob and the
  parameters it was computed with;
- ``locations``: last known poses (world, 4x4 world_T_model, bounding box, time).

Safety rules (DESIGN.md "never destroys data"): a file that is not an explore object
database -- random bytes, a corrupted SQLite image, another program's SQLite file, a newer
schema -- raises :class:`~explore.core.errors.BadInput` and is neither written nor modified (it is
validated through a read-only connection before anything writes). Concurrent writers are
serialised by SQLite (busy timeout, ``BEGIN IMMEDIATE`` transactions); each mesh is written
atomically (temporary file + ``os.replace``) *before* its row is committed, so a row never
points at a missing or half-written mesh.
"""

from __future__ import annotations

import io
import json
import os
import sqlite3
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import OBJECT_NAME, OBJECT_NAME_RULE, BadInput, Pose, brief, check_path_name
from explore.perception.colour import COLOUR_KIND, material_signature
from explore.perception.database_files import (
    APPLICATION_ID,
    BUSY_TIMEOUT_S,
    SCHEMA,
    SCHEMA_VERSION,
    check_identity,
    is_locked,
    refused,
    validate_existing,
    write_mesh_atomic,
)
from explore.perception.recognition import Model
from explore.sim import TriMesh, read_mesh

if TYPE_CHECKING:
    from explore.perception.recognition import Model
    from explore.sim import GroundTruthBody, Simulation

PROVENANCES = ("given", "modelled")
DEFAULT_DB = "runs/objects.db"  # beside the runs that fill it, not in whatever folder a command starts in


class NameTaken(BadInput):
    """:meth:`ObjectDatabase.add` of a name the database already holds (another run sharing it may
    have added it since the caller looked)."""


@dataclass(frozen=True)
class ObjectRecord:
    """One row of ``objects`` (the mesh is loaded by :meth:`ObjectDatabase.get`)."""

    name: str
    mesh_file: Path
    provenance: str
    world: str | None
    run: str | None
    scans: int | None
    coverage: float | None
    vertices: int
    triangles: int
    extent: tuple[float, float, float]
    created: str
    descriptor_kinds: tuple[str, ...] = ()
    mesh: TriMesh | None = None
    location: dict[str, Any] | None = None

    def summary(self) -> dict[str, Any]:
        """A JSON-friendly description (for ``explore db show``)."""
        return {
            "name": self.name,
            "provenance": self.provenance,
            "world": self.world,
            "run": self.run,
            "scans": self.scans,
            "coverage": self.coverage,
            "mesh_file": str(self.mesh_file),
            "vertices": self.vertices,
            "triangles": self.triangles,
            "extent_m": list(self.extent),
            "created": self.created,
            "descriptors": list(self.descriptor_kinds),
            "location": self.location,
        }


@dataclass
class ObjectDatabase:
    """An open object database. Create it with :meth:`open`; use it as a context manager."""

    path: Path
    connection: sqlite3.Connection
    mesh_dir: Path
    _closed: bool = field(default=False, repr=False)

    # -- opening -------------------------------------------------------------------------
    @classmethod
    def open(cls, path: str | Path, create: bool = True, readonly: bool = False) -> ObjectDatabase:
        """Open (and with ``create`` initialise) the database at ``path``.

        ``readonly`` opens through a read-only connection and never writes (``explore db
        list|show|export``): an empty file is then refused instead of getting a schema.
        Raises BadInput for a missing file (``create=False`` or ``readonly``), a non-SQLite or
        corrupted file, a foreign SQLite database or a newer schema; such files are never modified.
        """
        path = check_path_name(path).expanduser()
        if path.exists() and path.is_dir():
            raise BadInput(str(path), None, "is a folder, expected an explore object database file")
        if not path.exists():
            if not create or readonly:
                raise BadInput(str(path), None, "no such object database (create one with `explore db add`)")
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as error:  # e.g. runs/ is a file (runs/objects.db is the default)
                raise BadInput(str(path), None, f"cannot create its folder {path.parent}: {error.strerror}") from None
        else:
            validate_existing(path)
        if readonly:
            return cls._open_readonly(path)
        try:
            connection = sqlite3.connect(
                f"{path.resolve().as_uri()}?mode=rwc", uri=True, timeout=BUSY_TIMEOUT_S,
                isolation_level=None, check_same_thread=False,
            )
        except sqlite3.Error as error:
            raise refused(path, error, f"cannot open the object database: {error}") from None
        db = cls(path, connection, path.with_suffix(".meshes"))
        try:
            db._initialise()
        except BaseException:
            connection.close()
            raise
        return db

    @classmethod
    def _open_readonly(cls, path: Path) -> ObjectDatabase:
        try:
            connection = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=BUSY_TIMEOUT_S,
                                         isolation_level=None, check_same_thread=False)
            app = connection.execute("PRAGMA application_id").fetchone()[0]
            version = connection.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.Error as error:
            raise refused(path, error, f"cannot open the object database: {error}") from None
        if version == 0 and app == 0 and not tables:
            connection.close()
            raise BadInput(str(path), None, "is empty, not an object database yet (`explore db add` creates one);"
                           " the file was left untouched")
        try:
            check_identity(path, app, version, tables)
        except BadInput:
            connection.close()
            raise
        return cls(path, connection, path.with_suffix(".meshes"))

    def _initialise(self) -> None:
        con = self.connection
        try:
            con.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
            with self._transaction():
                version = con.execute("PRAGMA user_version").fetchone()[0]
                app = con.execute("PRAGMA application_id").fetchone()[0]
                tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
                if version == 0 and app == 0 and not tables:
                    for statement in SCHEMA.split(";"):
                        if statement.strip():
                            con.execute(statement)
                    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                else:
                    check_identity(self.path, app, version, tables)
            if str(con.execute("PRAGMA journal_mode").fetchone()[0]).lower() != "delete":
                con.execute("PRAGMA journal_mode = DELETE")  # a file of an older version (WAL): one file at rest
            con.execute("PRAGMA foreign_keys = ON")
            con.execute("PRAGMA synchronous = NORMAL")
        except sqlite3.DatabaseError as error:
            raise refused(self.path, error, f"not an explore object database ({error})") from None
        self.mesh_dir.mkdir(parents=True, exist_ok=True)

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """``BEGIN IMMEDIATE`` ... ``COMMIT`` (rolled back on error); waits for other writers."""
        con = self.connection
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as error:
            if is_locked(error):
                raise refused(self.path, error, str(error)) from None
            raise
        try:
            yield con
        except BaseException:
            con.execute("ROLLBACK")
            raise
        con.execute("COMMIT")

    def close(self) -> None:
        if not self._closed:
            self.connection.close()
            self._closed = True

    def __enter__(self) -> ObjectDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- objects -------------------------------------------------------------------------
    def check_name(self, name: str) -> None:
        """BadInput unless ``name`` is a valid object name (callers check before costly work)."""
        _check_name(self.path, name)

    def add(
        self,
        name: str,
        mesh: TriMesh,
        provenance: str = "given",
        world: str | None = None,
        run: str | None = None,
        scans: int | None = None,
        coverage: float | None = None,
        descriptors: Mapping[str, np.ndarray | tuple[np.ndarray, Mapping[str, Any]]] | None = None,
        replace: bool = False,
    ) -> ObjectRecord:
        """Add an object (mesh in its object frame); ``replace`` overwrites one of the same name.

        ``descriptors`` maps a kind to an array or to ``(array, params)``.
        """
        self.check_name(name)
        if provenance not in PROVENANCES:
            raise BadInput(str(self.path), "provenance", f"{provenance!r} is not one of {list(PROVENANCES)}")
        vertices = np.asarray(mesh.vertices, dtype=float)
        if len(mesh.triangles) == 0 or not np.all(np.isfinite(vertices)):
            raise BadInput(str(self.path), name, "the mesh is empty or has non-finite vertices")
        if coverage is not None and not (0.0 <= coverage <= 1.0):
            raise BadInput(str(self.path), "coverage", f"{coverage} is not within [0, 1]")
        mesh_name = f"{name}-{uuid.uuid4().hex[:12]}.ply"
        write_mesh_atomic(mesh, self.mesh_dir / mesh_name)
        extent = json.dumps(np.round(vertices.max(0) - vertices.min(0), 6).tolist())
        old_file: str | None = None
        try:
            with self._transaction() as con:
                row = con.execute("SELECT id, mesh_file FROM objects WHERE name = ?", (name,)).fetchone()
                if row is not None:
                    if not replace:
                        raise NameTaken(str(self.path), name, "an object of this name exists (remove it first)")
                    old_file = row[1]
                    con.execute("DELETE FROM objects WHERE id = ?", (row[0],))
                cursor = con.execute(
                    "INSERT INTO objects (name, mesh_file, provenance, world, run, scans, coverage, vertices,"
                    " triangles, extent, created) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (name, mesh_name, provenance, world, run, scans, coverage, len(vertices),
                     len(mesh.triangles), extent, _now()),
                )
                for kind, value in (descriptors or {}).items():
                    array, params = value if isinstance(value, tuple) else (value, {})
                    _put_descriptor(con, cursor.lastrowid, kind, array, params)
        except BaseException:
            (self.mesh_dir / mesh_name).unlink(missing_ok=True)
            raise
        if old_file:
            (self.mesh_dir / old_file).unlink(missing_ok=True)
        return self.get(name, load_mesh=False)

    def names(self) -> list[str]:
        """Sorted object names."""
        return [r[0] for r in self.connection.execute("SELECT name FROM objects ORDER BY name")]

    def __contains__(self, name: object) -> bool:
        return self.connection.execute("SELECT 1 FROM objects WHERE name = ?", (name,)).fetchone() is not None

    def __len__(self) -> int:
        return int(self.connection.execute("SELECT COUNT(*) FROM objects").fetchone()[0])

    def records(self) -> list[ObjectRecord]:
        """Every object's metadata (without meshes), sorted by name."""
        return [self.get(name, load_mesh=False) for name in self.names()]

    def get(self, name: str, load_mesh: bool = True) -> ObjectRecord:
        """The object ``name`` (with its mesh unless ``load_mesh`` is False)."""
        row = self.connection.execute(
            "SELECT id, name, mesh_file, provenance, world, run, scans, coverage, vertices, triangles, extent,"
            " created FROM objects WHERE name = ?", (name,),
        ).fetchone()
        if row is None:
            known = ", ".join(self.names()) or "the database is empty"
            raise BadInput(str(self.path), name, f"no object of this name (known: {known})")
        kinds = tuple(r[0] for r in self.connection.execute(
            "SELECT kind FROM descriptors WHERE object_id = ? ORDER BY kind", (row[0],)))
        mesh = None
        if load_mesh:
            try:
                mesh = read_mesh(self.mesh_dir / row[2])
            except (OSError, ValueError) as error:
                raise BadInput(str(self.mesh_dir / row[2]), name, f"cannot read the mesh: {error}") from None
        return ObjectRecord(
            name=row[1], mesh_file=self.mesh_dir / row[2], provenance=row[3], world=row[4], run=row[5],
            scans=row[6], coverage=row[7], vertices=row[8], triangles=row[9],
            extent=tuple(json.loads(row[10])), created=row[11], descriptor_kinds=kinds, mesh=mesh,
            location=self.location(name),
        )

    def remove(self, name: str) -> None:
        """Delete an object with its descriptors, locations and mesh file."""
        with self._transaction() as con:
            row = con.execute("SELECT id, mesh_file FROM objects WHERE name = ?", (name,)).fetchone()
            if row is None:
                raise BadInput(str(self.path), name, "no object of this name")
            con.execute("DELETE FROM objects WHERE id = ?", (row[0],))
        (self.mesh_dir / row[1]).unlink(missing_ok=True)

    def export(self, name: str, out: str | Path) -> Path:
        """Write the object's mesh to ``out`` (PLY, OBJ or STL by suffix)."""
        import open3d as o3d

        out = Path(out)
        if out.suffix.lower() not in (".ply", ".obj", ".stl"):
            raise BadInput(str(out), None, "export to a .ply, .obj or .stl file")
        mesh = self.get(name).mesh
        assert mesh is not None
        out.parent.mkdir(parents=True, exist_ok=True)
        o3d_mesh = mesh.to_open3d()
        if not o3d.io.write_triangle_mesh(str(out), o3d_mesh):
            raise BadInput(str(out), None, "cannot write the mesh")
        return out

    # -- descriptors ---------------------------------------------------------------------
    def set_descriptor(self, name: str, kind: str, array: np.ndarray, params: Mapping[str, Any] | None = None) -> None:
        """Store (or replace) the descriptor ``kind`` of an object."""
        with self._transaction() as con:
            row = con.execute("SELECT id FROM objects WHERE name = ?", (name,)).fetchone()
            if row is None:
                raise BadInput(str(self.path), name, "no object of this name")
            _put_descriptor(con, row[0], kind, array, params or {})

    def descriptors(self, name: str) -> dict[str, tuple[np.ndarray, dict[str, Any]]]:
        """Every descriptor of an object: kind -> (array, params)."""
        out: dict[str, tuple[np.ndarray, dict[str, Any]]] = {}
        rows = self.connection.execute(
            "SELECT d.kind, d.blob, d.params FROM descriptors d JOIN objects o ON o.id = d.object_id"
            " WHERE o.name = ?", (name,),
        )
        for kind, blob, params in rows:
            try:
                out[kind] = (np.load(io.BytesIO(blob), allow_pickle=False), json.loads(params))
            except (ValueError, OSError) as error:
                raise BadInput(str(self.path), f"{name}.descriptors.{kind}", f"unreadable: {error}") from None
        return out

    # -- locations -----------------------------------------------------------------------
    def set_location(
        self, name: str, world: str | None, pose: Pose, bbox: np.ndarray | None = None, time: str | None = None
    ) -> None:
        """Record where an object was last seen (world_T_model and an optional (2, 3) box)."""
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise BadInput(str(self.path), f"{name}.pose", "expected a finite 4x4 pose")
        box = None if bbox is None else json.dumps(np.asarray(bbox, dtype=float).round(6).tolist())
        with self._transaction() as con:
            row = con.execute("SELECT id FROM objects WHERE name = ?", (name,)).fetchone()
            if row is None:
                raise BadInput(str(self.path), name, "no object of this name")
            con.execute(
                "INSERT INTO locations (object_id, world, pose, bbox, time) VALUES (?, ?, ?, ?, ?)",
                (row[0], world, json.dumps(pose.round(9).tolist()), box, time or _now()),
            )

    def location(self, name: str) -> dict[str, Any] | None:
        """The last recorded location of an object, or None."""
        found = self.locations(name, last=True)
        return found[0] if found else None

    def locations(self, name: str, last: bool = False) -> list[dict[str, Any]]:
        """Every recorded location of an object, oldest first (``last``: only the newest).

        The first one is where the object was when it was added (its model frame in that world).
        """
        rows = self.connection.execute(
            "SELECT l.world, l.pose, l.bbox, l.time FROM locations l JOIN objects o ON o.id = l.object_id"
            f" WHERE o.name = ? ORDER BY l.id {'DESC LIMIT 1' if last else 'ASC'}", (name,),
        ).fetchall()
        return [{"world": r[0], "pose": json.loads(r[1]), "bbox": json.loads(r[2]) if r[2] else None, "time": r[3]}
                for r in rows]

    # -- recognisers ---------------------------------------------------------------------
    def models(self) -> list[Model]:
        """Every object as a :class:`~explore.perception.recognition.Model` (mesh + stored descriptors)."""
        out = []
        for name in self.names():
            record = self.get(name)
            assert record.mesh is not None
            out.append(Model(name, record.mesh, self.descriptors(name)))
        return out

    def seed_from_world(self, sim: Simulation, only_known: bool = True) -> dict[str, Pose]:
        """Add the world's known objects (provenance ``given``) in their object frames.

        Returns the ground-truth world_T_model of every added object (for metrics only).
        Objects already in the database are left as they are.
        """
        poses: dict[str, Pose] = {}
        for body in sim.objects():
            if only_known and not body.known:
                continue
            world_T_model, mesh = object_frame(body)
            rgb = sim.body_colour(body)
            signature = None if rgb is None else material_signature(rgb)
            colour = {} if signature is None else {COLOUR_KIND: signature.as_array()}
            if body.name not in self and self._seed(body.name, mesh, sim.spec.name, colour):
                self.set_location(body.name, sim.spec.name, world_T_model, np.vstack(body.mesh.bounds))
            poses[body.name] = world_T_model
        return poses

    def _seed(self, name: str, mesh: TriMesh, world: str, descriptors: Mapping[str, np.ndarray]) -> bool:
        """Add a known object; False when another run sharing the database added it meanwhile."""
        try:
            self.add(name, mesh, provenance="given", world=world, descriptors=descriptors)
        except NameTaken:
            return False
        return True


def object_frame(body: GroundTruthBody | TriMesh) -> tuple[Pose, TriMesh]:
    """The object frame of a ground-truth body: world axes, origin at its bounding-box centre.

    Returns ``(world_T_model, mesh in the object frame)``.
    """
    mesh = body if isinstance(body, TriMesh) else body.mesh
    lo, hi = mesh.bounds
    world_T_model = np.eye(4)
    world_T_model[:3, 3] = 0.5 * (lo + hi)
    return world_T_model, TriMesh(mesh.vertices - world_T_model[:3, 3], mesh.triangles)


def default_path() -> Path:
    """``$EXPLORE_DB`` or ``runs/objects.db`` (the runs folder of the current folder)."""
    return Path(os.environ.get("EXPLORE_DB") or DEFAULT_DB)


# -- helpers -------------------------------------------------------------------------------
def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _check_name(path: Path, name: str) -> None:
    if not isinstance(name, str) or not OBJECT_NAME.match(name):
        raise BadInput(str(path), "name", f"{brief(name)} is not a valid object name ({OBJECT_NAME_RULE})")


def _put_descriptor(con: sqlite3.Connection, object_id: int, kind: str, array: np.ndarray,
                    params: Mapping[str, Any]) -> None:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array), allow_pickle=False)
    con.execute(
        "INSERT OR REPLACE INTO descriptors (object_id, kind, params, blob, created) VALUES (?, ?, ?, ?, ?)",
        (object_id, kind, json.dumps(dict(params), sort_keys=True), buffer.getvalue(), _now()),
    )
