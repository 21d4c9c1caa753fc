"""``explore tree show|validate|list``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from explore.core import BadInput, check_output

from .output import JsonOption, print_json, print_rows


def _load(tree: str):
    from explore.runtime import load_tree

    from .main import registry

    reg = registry()
    return load_tree(tree, reg), reg


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Inspect and validate behaviour-tree files.", no_args_is_help=True)

    @sub.command("validate")
    def validate(tree: Annotated[str, typer.Argument(help="Tree name or file.")]) -> None:
        """Check a tree file: node types, behaviours and their parameters, includes, cycles."""
        from .main import console

        parsed, _ = _load(tree)
        nodes = list(parsed.root.walk())
        behaviours = sum(1 for n in nodes if n.type == "behaviour")
        console.print(f"{parsed.path}: valid ({len(nodes)} nodes, {behaviours} behaviours)")

    @sub.command("show")
    def show(
        tree: Annotated[str, typer.Argument(help="Tree name or file.")],
        format: Annotated[str | None, typer.Option(
            "--format", "-f", help="unicode, dot or png (default: from the --out suffix, else unicode).")] = None,
        out: Annotated[Path | None, typer.Option(
            "--out", "-o", help="File for dot or png output (png: runs/TREE.png, dot: stdout by default).")] = None,
    ) -> None:
        """Print the tree (unicode), or write it as Graphviz dot or PNG."""
        import py_trees

        from explore.runtime import build, tree_dot, write_tree_diagram

        from .main import console

        if format is None:
            format = out.suffix.lower().lstrip(".") if out is not None and out.suffix.lower() in (".dot", ".png") \
                else "unicode"
        if format not in ("unicode", "dot", "png"):
            raise BadInput("--format", None, f"expected unicode, dot or png, got {format!r}")
        if format == "unicode" and out is not None:
            raise BadInput("--out", str(out), "the unicode tree is printed; write a file with a .dot or .png --out")
        parsed, reg = _load(tree)
        root = build(parsed.root, reg)
        if format == "unicode":
            console.print(py_trees.display.unicode_tree(root), markup=False, highlight=False)
            return
        if format == "dot" and out is None:
            console.print(tree_dot(root).to_string(), markup=False, highlight=False)
            return
        target = check_output(out or Path("runs") / f"{parsed.path.stem}.{format}", "--out", suffixes=(f".{format}",))
        target.parent.mkdir(parents=True, exist_ok=True)
        written = write_tree_diagram(root, target.parent, target.stem)
        wanted = [p for p in written if p.suffix == f".{format}"]
        if not wanted:
            raise BadInput("--format", None, "png needs the Graphviz 'dot' program (apt-get install graphviz)")
        if format == "png":
            (target.parent / f"{target.stem}.dot").unlink(missing_ok=True)
        console.print(f"-> {wanted[0]}")

    @sub.command("list")
    def list_(as_json: JsonOption = False) -> None:
        """List the tree files in ./trees, the shipped trees and $EXPLORE_TREES."""
        from explore.runtime import list_trees

        trees = [{"tree": path.stem, "file": str(path)} for path in list_trees()]
        if as_json:
            print_json(trees)
            return
        print_rows(("tree", "file"), [[t["tree"], t["file"]] for t in trees])

    app.add_typer(sub, name="tree")
