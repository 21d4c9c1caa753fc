"""The ``explore`` command line (typer).

Exit codes: 0 success, 1 the mission failed (reported, not crashed), 2 bad input.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from explore import __version__
from explore.core import MAX_LINE, BadInput, MissionFailed, Terminated

app = typer.Typer(
    name="explore",
    help="Active scene exploration: run trees, inspect plugins and worlds, scan, compare.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help texts are plain: "[m]" is a unit, not markup
)
# markup off by default: user text (names, paths, messages) is printed as it is; "[b]" or ":x:" stay text
console = Console(markup=False, emoji=False, highlight=False, soft_wrap=True)  # lines are not cut or wrapped
err_console = Console(stderr=True, soft_wrap=True, markup=False, emoji=False, highlight=False)


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


def _builtin_command_names() -> set[str]:
    names = {group.name for group in app.registered_groups}
    for command in app.registered_commands:
        names.add(command.name or command.callback.__name__.replace("_", "-"))
    return names


_plugin_commands_added = False


def plugin_commands(argv: list[str]) -> None:
    """Add the sub-commands of plugin packages (their ``explore_register_commands`` hook).

    Loaded only when the command line names no built-in command (a plugin's command, help,
    or a mistake), so the built-in commands start as fast as without plugins. A package whose
    hook fails is named in one line; the other commands still work.
    """
    global _plugin_commands_added
    first = next((arg for arg in argv if not arg.startswith("-")), None)
    if _plugin_commands_added or (first is not None and first in _builtin_command_names()):
        return
    _plugin_commands_added = True
    manager = registry().manager
    for impl in manager.hook.explore_register_commands.get_hookimpls():
        try:
            impl.function(app=app)
        except Exception as error:  # noqa: BLE001 - one broken package must not break the CLI
            err_console.print(f"warning: plugin {impl.plugin_name}: its commands failed to load: "
                              f"{type(error).__name__}: {error}")


def main(argv: list[str] | None = None) -> int:
    """Run the CLI and return its exit code.

    0 success, 1 the mission failed, 2 bad input or a usage error (one line on stderr, never a
    traceback), 130 interrupted (SIGINT), 143 terminated (SIGTERM). A bare group (``explore``,
    ``explore db``) prints its help and exits 0.
    """
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    try:
        plugin_commands(sys.argv[1:] if argv is None else argv)
        result = app(args=argv, prog_name="explore", standalone_mode=False)
    except BadInput as error:
        return _error_line(f"error: {error.line()}", 2)
    except MissionFailed as error:
        return _error_line(f"mission failed: {error}", 1)
    except typer.Exit as error:
        return int(error.exit_code)
    except typer.Abort:
        return _error_line("aborted", 130)
    except typer.TyperException as error:  # usage errors, raised by typer's own bundled click
        if type(error).__name__ == "NoArgsIsHelpError":  # typer printed the help already
            return 0
        return _error_line(_usage_line(error), 2)
    except Terminated:
        return _error_line("terminated", 143)
    except KeyboardInterrupt:
        return _error_line("interrupted", 130)
    return int(result) if isinstance(result, int) else 0


def _error_line(line: str, code: int) -> int:
    line = " ".join(line.split())
    if len(line) > MAX_LINE:
        line = line[: MAX_LINE - 1] + "…"
    err_console.print(line, markup=False, highlight=False)
    return code


def _usage_line(error: Exception) -> str:
    """A usage error as one line: the command, what is wrong and where help is."""
    ctx = getattr(error, "ctx", None)
    command = ctx.command_path if ctx is not None else "explore"
    message = " ".join(error.format_message().split())  # type: ignore[attr-defined]
    return f"error: {command}: {message} (see: {command} --help)"


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


def run() -> None:
    """Console-script entry point."""
    signal.signal(signal.SIGTERM, _raise_terminated)
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # nanobind (ompl) prints leak warnings at interpreter exit; skip the teardown noise
    os._exit(code)


def registry():
    """A registry for this CLI invocation (plugins may be blocked with EXPLORE_BLOCK_PLUGINS)."""
    from explore.runtime import Registry

    blocked = [b for b in os.environ.get("EXPLORE_BLOCK_PLUGINS", "").split(",") if b]
    return Registry.load(blocked=blocked)


def out_path(path: Path) -> Path:
    """An output file path checked by :func:`explore.core.output_paths.check_output`, its folder created now."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
