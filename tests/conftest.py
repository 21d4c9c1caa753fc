"""Shared fixtures: a plugin registry, simulations of the shipped worlds, a clean blackboard."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def registry():
    from explore.registry import Registry

    return Registry.load()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@pytest.fixture
def bunny_sim(registry) -> Iterator:
    from explore.simulation import Simulation

    with Simulation("bunny_pedestal", registry) as sim:
        yield sim


@pytest.fixture(autouse=True)
def _clean_blackboard() -> Iterator[None]:
    yield
    try:
        import py_trees
    except ImportError:  # pragma: no cover
        return
    py_trees.blackboard.Blackboard.clear()
