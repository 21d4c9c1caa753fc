"""``explore plugins list``."""

from __future__ import annotations

import dataclasses
from typing import Annotated

import typer
from rich.table import Table

from explore.core import BadInput
from explore.runtime import KINDS


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Inspect the registered plugins.", no_args_is_help=True)

    @sub.command("list")
    def list_plugins(
        kind: Annotated[str | None, typer.Option("--kind", "-k", help=f"Only this kind ({', '.join(KINDS)}).")] = None,
        params: Annotated[bool, typer.Option("--params", help="Also list every plugin's parameters.")] = False,
    ) -> None:
        """Print kind, name, origin package and a one-line doc of every plugin."""
        from .main import console, registry

        reg = registry()
        if kind is not None and kind not in KINDS:
            raise BadInput("--kind", None, f"unknown plugin kind {kind!r} (valid: {', '.join(KINDS)})")
        table = Table(box=None, header_style="bold")
        for column in ("kind", "name", "origin", "doc"):
            table.add_column(column)
        for info in reg.of_kind(kind):
            clash = reg.clashes.get((info.kind, info.name))
            origin = " + ".join(clash) + " (clash: unusable)" if clash else info.origin
            table.add_row(info.kind, info.name, origin, info.doc)
            if params:
                effective = reg.effective_defaults(info)
                for p in info.params:
                    table.add_row("", "", "", f"  {dataclasses.replace(p, default=effective[p.name]).describe()}")
        console.print(table)
        for name, error in reg.load_errors.items():
            console.print(f"could not load plugin package {name}: {error}", style="yellow")

    app.add_typer(sub, name="plugins")
