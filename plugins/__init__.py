"""The built-in plugins, registered through the ``explore.plugins`` entry point.

This module is what the entry point names; it registers every built-in exactly as a
third-party package would.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from explore.hookspecs import hookimpl


@hookimpl
def explore_register_plugins(register: Callable[..., Any]) -> None:
    from .robots import FreeFlyer
    from .sensors import DepthCamera, LaserStriper

    for factory in (DepthCamera, LaserStriper, FreeFlyer):
        register(factory)
