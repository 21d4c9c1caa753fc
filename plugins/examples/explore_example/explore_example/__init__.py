"""Example plugin package for explore: a strategy, a robot and a sensor, using only ``explore.api``.

Registered through the ``explore.plugins`` entry point declared in ``pyproject.toml``:

* ``travel_ig`` (utility) and ``example/travel_ig`` (strategy): information gain discounted by travel;
* ``turntable`` (robot): the classic object-modelling rig, the object on a turntable and the
  sensor on a vertical rail with a tilt joint;
* ``tof_camera`` (sensor): a time-of-flight camera with its own noise model.

``turntable_bunny.yaml`` next to this file is a world that uses them.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from explore.api import hookimpl

from .strategy import TravelIG, TravelStrategy
from .tof import TofCamera
from .turntable import Turntable

WORLD = Path(__file__).with_name("turntable_bunny.yaml")


@hookimpl
def explore_register_plugins(register: Callable[..., Any]) -> None:
    for plugin in (TravelIG, TravelStrategy, Turntable, TofCamera):
        register(plugin)
