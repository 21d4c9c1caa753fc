"""The built-in plugins, registered through the ``explore.plugins`` entry point.

This module is what the entry point names; it registers every built-in exactly as a
third-party package would. Each module listed in ``BUILTIN_MODULES`` exposes ``PLUGINS``,
a list of plugin classes (or factories with ``kind``, ``name`` and ``params`` attributes).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from explore.runtime import hookimpl

BUILTIN_MODULES = (
    "sensors",
    "robots",
    "planners",
    "view_generators",
    "utilities",
    "nbvs_plugins",
    "terminations",
    "strategies",
    "segmenters",
    "recognizers",
    "pose_validators",
    "registrars",
    "behaviours",
    "scene_behaviours",
    "nbvs_behaviours",
    "executors",
)


@hookimpl
def explore_register_plugins(register: Callable[..., Any]) -> None:
    for module_name in BUILTIN_MODULES:
        module = importlib.import_module(f"{__name__}.{module_name}")
        for factory in module.PLUGINS:
            register(factory)
