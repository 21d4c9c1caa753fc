"""Shared fixtures: a plugin registry, simulations of the shipped worlds, a clean blackboard."""

from __future__ import annotations

import dataclasses
import faulthandler
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

if TYPE_CHECKING:
    from explore.sim import Simulation, WorldSpec

os.environ.setdefault("MPLBACKEND", "Agg")

SLOW_TIMEOUT = 900.0  # seconds for a test marked slow without its own timeout mark


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("slow") and not item.get_closest_marker("timeout"):
            item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT))


def _timeout_of(item: pytest.Item) -> float:
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    return float(item.config.getini("timeout") or 0)


@pytest.fixture(autouse=True)
def _hang_guard(request: pytest.FixtureRequest) -> Iterator[None]:
    """A last resort behind pytest-timeout: a C-level watchdog (no GIL needed) that dumps every
    thread's stack and ends the session when a test hangs inside native code holding the GIL,
    where pytest-timeout's Python handler can never run."""
    limit = _timeout_of(request.node)
    if limit > 0:
        faulthandler.dump_traceback_later(1.5 * limit + 30.0, exit=True, file=sys.stderr)
    yield
    faulthandler.cancel_dump_traceback_later()


@pytest.fixture(scope="session")
def registry():
    from explore.runtime import Registry

    return Registry.load()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@pytest.fixture(scope="session")
def open_world(registry) -> Callable[..., Simulation]:
    """The tests' one way to open a simulated world (a shipped world's name, a YAML path or a
    ``WorldSpec``) with the session's registry: ``with open_world("tabletop") as sim: ...``;
    ``profile`` replaces the sensor's profile (``"ideal"``: white noise only, for the tests that
    check an algorithm's precision on controlled data)."""
    from explore.sim import Simulation, WorldSpec, load_world_spec

    def factory(world: str | Path | WorldSpec, seed: int = 0, profile: str | None = None) -> Simulation:
        if profile is not None:
            spec = world if isinstance(world, WorldSpec) else load_world_spec(world)
            sensor = dataclasses.replace(spec.sensor, params={**spec.sensor.params, "profile": profile})
            world = dataclasses.replace(spec, sensor=sensor)
        return Simulation(str(world) if isinstance(world, Path) else world, registry, seed=seed)

    return factory


def _shared_world(name: str, scope: str = "module", profile: str | None = None):  # noqa: ANN202
    """A fixture ``name`` holding the shipped world ``name``, shared by the tests of a module."""

    @pytest.fixture(scope=scope, name=name)
    def fixture(open_world) -> Iterator[Simulation]:
        with open_world(name, profile=profile) as sim:
            yield sim

    return fixture


tabletop = _shared_world("tabletop", profile="ideal")  # the world's Kinect artefacts off (see open_world)
workcell = _shared_world("workcell")
two_tables = _shared_world("two_tables")
cluttered = _shared_world("cluttered")


@pytest.fixture
def bunny_sim(open_world) -> Iterator[Simulation]:
    with open_world("bunny_pedestal") as sim:
        yield sim


@pytest.fixture(autouse=True)
def _clean_blackboard() -> Iterator[None]:
    yield
    try:
        import py_trees
    except ImportError:  # pragma: no cover
        return
    py_trees.blackboard.Blackboard.clear()
