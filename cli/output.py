"""Lists and records on stdout: a table on a terminal, plain aligned columns when piped, JSON on request.

Nothing is cut: a terminal table folds long cells instead of ending them with "…", and piped
output is never wrapped (a pipe has no width).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer
from rich.table import Table

JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON (one document on stdout) instead of a table.")]


def print_json(data: Any) -> None:
    """One JSON document on stdout (no colour, no wrapping)."""
    sys.stdout.write(json.dumps(data, indent=1, default=str) + "\n")


def print_rows(columns: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
    """``rows`` under ``columns``: a rich table on a terminal, aligned plain text otherwise."""
    from .main import console

    if console.is_terminal:
        table = Table(box=None, header_style="bold")
        for column in columns:
            table.add_column(column, overflow="fold")
        for row in rows:
            table.add_row(*row)
        console.print(table)
        return
    widths = [max([len(c)] + [len(r[i]) for r in rows]) for i, c in enumerate(columns)]
    for row in (list(columns), *rows):
        sys.stdout.write("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() + "\n")
