"""The ``explore`` command line (typer).

Exit codes: 0 success, 1 the mission failed (reported, not crashed), 2 bad input.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import click
import typer
from rich.console import Console

from explore import __version__
from explore.errors import BadInput, MissionFailed

app = typer.Typer(
    name="explore",
    help="Active scene exploration: run trees, inspect plugins and worlds, scan, compare.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
console = Console()
err_console = Console(stderr=True, soft_wrap=True)


def _version(value: bool) -> None:
    if value:
        console.print(f"explore {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Active scene exploration with a robot and a range sensor."""


def _register_subcommands() -> None:
    from . import plugins_cmd, scan_cmd, worlds_cmd

    plugins_cmd.register(app)
    worlds_cmd.register(app)
    scan_cmd.register(app)
    for optional in ("run_cmd", "tree_cmd", "db_cmd", "compare_cmd"):
        try:
            module = __import__(f"explore_cli.{optional}", fromlist=["register"])
        except ModuleNotFoundError as error:
            if error.name != f"explore_cli.{optional}":
                raise
            continue
        module.register(app)
        if hasattr(module, "register_demo"):
            module.register_demo(app)


_register_subcommands()


def main(argv: list[str] | None = None) -> int:
    """Run the CLI and return its exit code (bad input: one line on stderr, code 2)."""
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    try:
        result = app(args=argv, prog_name="explore", standalone_mode=False)
    except BadInput as error:
        err_console.print(f"error: {error.line()}", markup=False, highlight=False)
        return 2
    except MissionFailed as error:
        err_console.print(f"mission failed: {error}", markup=False, highlight=False)
        return 1
    except click.exceptions.Exit as error:
        return int(error.exit_code)
    except click.exceptions.Abort:
        err_console.print("aborted")
        return 130
    except click.ClickException as error:
        error.show()
        return 2
    except KeyboardInterrupt:
        err_console.print("interrupted")
        return 130
    return int(result) if isinstance(result, int) else 0


def run() -> None:
    """Console-script entry point."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # nanobind (ompl) prints leak warnings at interpreter exit; skip the teardown noise
    os._exit(code)


def registry():
    """A registry for this CLI invocation (plugins may be blocked with EXPLORE_BLOCK_PLUGINS)."""
    from explore.registry import Registry

    blocked = [b for b in os.environ.get("EXPLORE_BLOCK_PLUGINS", "").split(",") if b]
    return Registry.load(blocked=blocked)


def out_path(path: Path) -> Path:
    """A writable output path (its folder is created); refuse to write into a folder path."""
    if path.exists() and path.is_dir():
        raise BadInput(str(path), None, "is a folder, expected a file path")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
