"""``explore plugins list``."""

from __future__ import annotations

import dataclasses
from typing import Annotated

import typer

from explore.core import BadInput
from explore.runtime import KINDS

from .output import JsonOption, print_json, print_rows


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Inspect the registered plugins.", no_args_is_help=True)

    @sub.command("list")
    def list_plugins(
        kind: Annotated[str | None, typer.Option("--kind", "-k", help=f"Only this kind ({', '.join(KINDS)}).")] = None,
        params: Annotated[bool, typer.Option("--params", help="Also list every plugin's parameters.")] = False,
        as_json: JsonOption = False,
    ) -> None:
        """Print kind, name, origin package and a one-line doc of every plugin."""
        from .main import err_console, registry

        reg = registry()
        if kind is not None and kind not in KINDS:
            raise BadInput("--kind", None, f"unknown plugin kind {kind!r} (valid: {', '.join(KINDS)})")
        plugins = []
        for info in reg.of_kind(kind):
            clash = reg.clashes.get((info.kind, info.name))
            effective = reg.effective_defaults(info) if params or as_json else {}  # only where shown
            plugins.append((info, clash, [dataclasses.replace(p, default=effective[p.name]) for p in info.params
                                          if p.name in effective]))
        if as_json:
            print_json({"plugins": [
                {"kind": info.kind, "name": info.name, "origin": " + ".join(clash) if clash else info.origin,
                 "clash": bool(clash), "doc": info.doc,
                 "params": [{"name": p.name, "type": getattr(p.type, "__name__", str(p.type)), "default": p.default,
                             "unit": p.unit, "doc": p.doc} for p in defaults]}
                for info, clash, defaults in plugins
            ], "load_errors": reg.load_errors})
            return
        rows = []
        for info, clash, defaults in plugins:
            rows.append([info.kind, info.name, " + ".join(clash) + " (clash: unusable)" if clash else info.origin,
                         info.doc])
            rows += [["", "", "", f"  {p.describe()}"] for p in defaults] if params else []
        print_rows(("kind", "name", "origin", "doc"), rows)
        for name, error in reg.load_errors.items():
            err_console.print(f"could not load plugin package {name}: {error}", style="yellow")

    app.add_typer(sub, name="plugins")
