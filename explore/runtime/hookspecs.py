"""Every hook that a plugin package can implement (pluggy project name ``explore``).

A package declares the entry point group ``explore.plugins`` pointing at a module (or
object) with ``@hookimpl`` functions (``from explore.api import hookimpl``), exactly as the
built-in plugin package does. Hook implementations must not give their parameters default values.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pluggy

PROJECT = "explore"
ENTRY_POINT_GROUP = "explore.plugins"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


class Specs:
    """Hook specifications."""

    @hookspec
    def explore_register_plugins(self, register: Callable[..., Any]) -> None:
        """Register plugins by calling ``register(factory, kind=..., name=..., params=...)``.

        ``factory`` is a class or callable that takes the validated parameters as keyword
        arguments. ``kind``, ``name`` and ``params`` default to the factory's attributes of
        the same names; the one-line doc is the first line of its docstring.
        ``register.default(kind, name, params=None, role="")`` declares the plugin the library
        uses where a run names none (a third-party default replaces a built-in one).
        """

    @hookspec
    def explore_register_commands(self, app: Any) -> None:
        """Add sub-commands to the ``explore`` typer application."""
