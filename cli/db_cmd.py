"""``explore db list|show|add|remove|export``: the object database from the command line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from explore.core import BadInput, check_path_name

from .output import JsonOption, print_json, print_rows

DbOption = Annotated[
    Path | None,
    typer.Option("--db", help="Database file (default: $EXPLORE_DB or runs/objects.db)."),
]


def _open(db: Path | None, create: bool = False, readonly: bool = False):  # -> ObjectDatabase
    from explore.perception import ObjectDatabase, default_path

    return ObjectDatabase.open(db or default_path(), create=create, readonly=readonly)


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="The object database (SQLite + a folder of meshes).", no_args_is_help=True)

    @sub.command("list")
    def list_objects(db: DbOption = None, as_json: JsonOption = False) -> None:
        """List the objects: provenance, size, descriptors, where they came from."""
        with _open(db, readonly=True) as database:
            records = database.records()
        if as_json:
            print_json([rec.summary() for rec in records])
            return
        rows = []
        for rec in records:
            seen = rec.location or {}
            rows.append([
                rec.name, rec.provenance, str([round(x, 3) for x in rec.extent]), str(rec.triangles),
                ",".join(rec.descriptor_kinds) or "-", rec.world or "-", rec.run or "-",
                "-" if rec.scans is None else str(rec.scans),
                "-" if rec.coverage is None else f"{rec.coverage:.2f}",
                f"{seen.get('world') or '-'} {seen.get('time', '')}".strip() if seen else "-",
            ])
        print_rows(("name", "provenance", "extent [m]", "triangles", "descriptors", "world", "run", "scans",
                    "coverage", "last seen"), rows)

    @sub.command("show")
    def show(name: Annotated[str, typer.Argument(help="Object name.")], db: DbOption = None,
             as_json: JsonOption = False) -> None:
        """Print one object's record (JSON on a terminal too; ``--json``: no colour, one document)."""
        from .main import console

        with _open(db, readonly=True) as database:
            summary = database.get(name, load_mesh=False).summary()
        if as_json or not console.is_terminal:
            print_json(summary)
        else:
            console.print_json(json.dumps(summary, default=str))

    @sub.command("add")
    def add(
        name: Annotated[str, typer.Argument(help="Object name.")],
        mesh: Annotated[Path, typer.Argument(help="Mesh file (OBJ, PLY, STL) in the object frame.")],
        scale: Annotated[float, typer.Option("--scale", help="Multiply the vertices (e.g. 0.001 for mm).")] = 1.0,
        provenance: Annotated[str, typer.Option("--provenance", help="given or modelled.")] = "given",
        replace: Annotated[bool, typer.Option("--replace", help="Overwrite an object of the same name.")] = False,
        descriptors: Annotated[bool, typer.Option(
            "--descriptors/--no-descriptors", help="Store PPF and VFH descriptors (a few seconds per object).")] = True,
        world: Annotated[str | None, typer.Option("--world", help="World the object comes from (provenance).")] = None,
        db: DbOption = None,
    ) -> None:
        """Add an object from a mesh file (creates the database if needed)."""
        import math

        import numpy as np

        from explore.perception import PROVENANCES
        from explore.sim import TriMesh, read_mesh

        from .main import console

        if not math.isfinite(scale) or scale <= 0:
            raise BadInput("--scale", None, f"{scale} must be a positive number")
        if provenance not in PROVENANCES:
            raise BadInput("--provenance", None, f"{provenance!r} is not one of {', '.join(PROVENANCES)}")
        if check_path_name(mesh).is_dir():
            raise BadInput(str(mesh), None, "is a folder, expected a mesh file")
        if not mesh.is_file():
            raise BadInput(str(mesh), None, "no such mesh file")
        try:
            loaded = read_mesh(mesh)
        except (OSError, ValueError) as error:
            raise BadInput(str(mesh), None, f"cannot read the mesh: {error}") from None
        loaded = TriMesh(loaded.vertices * scale, loaded.triangles)
        lo, hi = loaded.bounds
        extent = float(np.max(hi - lo))
        if not 1e-3 <= extent <= 10.0:
            hint = "0.001 turns millimetres into metres" if extent > 10.0 else "at least 1 mm across"
            raise BadInput(str(mesh), "--scale", f"the mesh is {extent:.3g} m across with --scale {scale:g}: "
                                                 f"no object a robot models ({hint})")
        stored = {}
        with _open(db, create=True) as database:
            database.check_name(name)
            if name in database and not replace:
                raise BadInput(str(database.path), name,
                               "an object of this name exists (use --replace to overwrite it)")
            if descriptors and len(loaded.triangles):
                from explore.perception import Model, model_descriptors

                console.print(f"computing descriptors of {name} ...")
                stored = model_descriptors(Model(name, loaded))
            record = database.add(name, loaded, provenance=provenance, world=world, replace=replace,
                                  descriptors=stored)
            kinds = ", ".join(record.descriptor_kinds) or "no descriptors"
            triangles = f"{record.triangles} triangle" + ("" if record.triangles == 1 else "s")
            console.print(f"added {record.name} ({triangles}, {kinds}) to {database.path}")

    @sub.command("remove")
    def remove(name: Annotated[str, typer.Argument(help="Object name.")], db: DbOption = None) -> None:
        """Remove an object with its descriptors, locations and mesh."""
        from .main import console

        with _open(db) as database:
            database.remove(name)
            console.print(f"removed {name}")

    @sub.command("export")
    def export(
        name: Annotated[str, typer.Argument(help="Object name.")],
        out: Annotated[Path, typer.Option("--out", "-o", help="Output mesh (.ply, .obj or .stl).")],
        db: DbOption = None,
        replace: Annotated[bool, typer.Option("--replace", help="Overwrite the file if it exists.")] = False,
    ) -> None:
        """Write an object's mesh to a file (an existing file only with ``--replace``)."""
        from explore.core import check_output

        from .main import console

        check_output(out, "--out", suffixes=(".ply", ".obj", ".stl"), replace=replace)
        with _open(db, readonly=True) as database:
            path = database.export(name, out)
            console.print(f"wrote {path}")

    app.add_typer(sub, name="db")
