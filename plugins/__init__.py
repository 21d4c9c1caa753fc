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
    "mobile_robots",
    "planners",
    "view_generators",
    "boundary_hole",
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


#: (kind, plugin, parameters, role): what the library uses where a run names no plugin
DEFAULTS = (
    ("robot", "free_flyer", {}, "world"),  # a world file without a robot: Kriegel's free-flying sensor
    ("motion_planner", "rrt_connect", {}, ""),  # a robot without a default planner of its own
    ("strategy", "ig_quality/bs_hr", {}, ""),  # Kriegel's best strategy (thesis Table 4.5)
    ("registrar", "icp", {}, "scan_to_model"),  # the thesis' local ICP of a scan to the model
    ("registrar", "pose_graph", {}, "scans"),  # a scene's views on a noisy base
    ("segmenter", "plane_clusters", {"scale": "table"}, ""),  # Görner's table-top segmentation
    ("recognizer", "ppf", {}, ""),
    ("pose_validator", "pvs_votes", {}, ""),  # Kriegel Eq. 3.11
)


@hookimpl
def explore_register_plugins(register: Callable[..., Any]) -> None:
    for module_name in BUILTIN_MODULES:
        module = importlib.import_module(f"{__name__}.{module_name}")
        for factory in module.PLUGINS:
            register(factory)
    for kind, name, params, role in DEFAULTS:
        register.default(kind, name, params, role)
