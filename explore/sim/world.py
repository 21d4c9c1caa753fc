"""World files: a YAML description of the support, objects, robot, sensor and region.

The format is documented in ``worlds/README.md``. :func:`load_world_spec` validates a file
and returns a :class:`WorldSpec`; every problem is a :class:`BadInput` naming the file and
the field. Loading the spec into pybullet and building the ground truth is the job of
:mod:`explore.sim.simulation`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import OBJECT_NAME, OBJECT_NAME_RULE, Array, BadInput, brief, check_path_name, load_yaml

MESH_SUFFIXES = (".obj", ".stl", ".ply")
TOP_LEVEL_FIELDS = ("name", "description", "environment", "objects", "region", "robot", "sensor", "overview")
BODY_SUFFIXES = MESH_SUFFIXES + (".urdf", ".sdf")


def repo_root() -> Path:
    """The source tree's top folder (worlds/, trees/ live there)."""
    return Path(__file__).resolve().parents[2]


def pybullet_data_path() -> Path:
    import pybullet_data

    return Path(pybullet_data.getDataPath())


@dataclass(frozen=True)
class BodySpec:
    """One body of the world: a primitive or a mesh/URDF/SDF file with pose and scale."""

    name: str
    position: Array
    rpy_deg: Array
    shape: str  # "box" | "cylinder" | "sphere" | "file"
    dims: Array = field(default_factory=lambda: np.zeros(3))  # box extents / (radius, length)
    source: Path | None = None
    scale: Array = field(default_factory=lambda: np.ones(3))
    size: float | None = None  # requested largest extent (m); resolved when loading
    on: str | None = None  # name of the body it rests on
    known: bool = False
    color: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)
    drop: bool = False  # on a body with z given: falls from z onto the surface below, not onto the body's top
    specular: float = 0.0  # share of the light the surface reflects as a mirror (glossy: glazed, polished)


@dataclass(frozen=True)
class PluginSpec:
    plugin: str
    params: dict[str, Any]
    base: Array | None = None  # robot base pose [x, y, z, yaw_deg]


@dataclass(frozen=True)
class WorldSpec:
    """A validated world file."""

    path: Path
    name: str
    description: str
    environment: tuple[BodySpec, ...]
    objects: tuple[BodySpec, ...]
    region_min: Array
    region_max: Array
    robot: PluginSpec
    sensor: PluginSpec
    overview: Array | None  # a pose [eye(3), target(3)] for the first look

    @property
    def region_size(self) -> Array:
        return self.region_max - self.region_min

    @property
    def region_center(self) -> Array:
        return 0.5 * (self.region_min + self.region_max)


def world_search_path() -> list[Path]:
    paths = [Path(p) for p in os.environ.get("EXPLORE_WORLDS", "").split(os.pathsep) if p]
    return paths + [Path.cwd() / "worlds", repo_root() / "worlds"]


def find_world(name_or_path: str | Path) -> Path:
    """Resolve a world given as a path or as a name in the world search path."""
    candidate = check_path_name(name_or_path)
    if candidate.suffix in (".yaml", ".yml") and candidate.is_file():
        return candidate
    if candidate.is_file() and candidate.suffix.lower() in BODY_SUFFIXES:
        raise BadInput(str(name_or_path), None, f"a {candidate.suffix} file, not a world: a world is a YAML "
                                                f"file whose bodies name such files as `source:` (see worlds/)")
    for folder in world_search_path():
        for suffix in (".yaml", ".yml", ""):
            path = folder / f"{name_or_path}{suffix}"
            if path.is_file():
                return path
    if candidate.is_dir():
        raise BadInput(str(name_or_path), None, "is a folder, not a world file")
    if candidate.is_file():  # any other file given by its path: its parser says what is wrong with it
        return candidate
    names = ", ".join(sorted(p.stem for p in list_worlds()))
    raise BadInput(str(name_or_path), None, f"no such world file (shipped worlds: {names})")


def list_worlds() -> list[Path]:
    seen: dict[str, Path] = {}
    for folder in world_search_path():
        for path in sorted(folder.glob("*.yaml")):
            seen.setdefault(path.stem, path)
    return list(seen.values())


WORLD_LIMIT = 1e4  # the largest magnitude of any number in a world file


class _Fields:
    """Typed access to a YAML mapping that reports BadInput with the field path."""

    def __init__(self, data: Any, source: str, prefix: str) -> None:
        if not isinstance(data, dict):
            raise BadInput(source, prefix or None, f"expected a mapping, got {type(data).__name__}")
        self.data, self.source, self.prefix = data, source, prefix
        self.used: set[str] = set()

    def where(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise BadInput(self.source, self.where(key), "missing")
            return default
        return self.data[key]

    def optional(self, key: str, default: Any) -> Any:
        """The value of an optional field; an empty one (``key:`` or ``null``) is the default too."""
        value = self.get(key, None)
        return default if value is None else value

    def vector(self, key: str, n: int | tuple[int, ...], default: Any = ...) -> Array:
        value = self.get(key, default)
        sizes = (n,) if isinstance(n, int) else n
        if not isinstance(value, list | tuple) or len(value) not in sizes:
            raise BadInput(
                self.source,
                self.where(key),
                f"expected a list of {' or '.join(map(str, sizes))} numbers, got {brief(value)}",
            )
        return np.array([self._finite(v, f"{self.where(key)}[{i}]") for i, v in enumerate(value)])

    def number(self, key: str, default: Any = ..., positive: bool = False) -> float:
        value = self._finite(self.get(key, default), self.where(key))
        if positive and value <= 0:
            raise BadInput(self.source, self.where(key), f"must be positive, got {value}")
        return value

    def _finite(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BadInput(self.source, where, f"expected a number, got {brief(value)}")
        if not math.isfinite(value):
            raise BadInput(self.source, where, f"{value} is not a finite number")
        if abs(value) > WORLD_LIMIT:  # pybullet and the voxel indices overflow long before inf
            raise BadInput(self.source, where, f"{brief(value)} is beyond ±{WORLD_LIMIT:g} (metres, degrees)")
        return float(value)

    def string(self, key: str, default: Any = ...) -> str:
        value = self.get(key, default)
        if not isinstance(value, str) or not value:
            raise BadInput(self.source, self.where(key), f"expected a non-empty string, got {brief(value)}")
        return value

    def boolean(self, key: str, default: Any = ...) -> bool:
        value = self.get(key, default)
        if not isinstance(value, bool):
            raise BadInput(self.source, self.where(key), f"expected true or false, got {brief(value)}")
        return value

    def check_unknown(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise BadInput(
                self.source, self.where(unknown[0]), f"unknown field (valid: {', '.join(sorted(self.used))})"
            )


def resolve_source(source: str, world_dir: Path, where: str, file: str) -> Path:
    """A mesh/URDF path: beside the world file first, then in pybullet_data."""
    for base in (world_dir, pybullet_data_path()):
        path = (base / source).resolve()
        try:
            found = path.is_file()
        except OSError as error:  # e.g. a name longer than the file system allows
            raise BadInput(file, where, f"cannot use {brief(source)}: {error.strerror or error}") from None
        if found:
            if path.suffix.lower() not in BODY_SUFFIXES:
                raise BadInput(file, where, f"unsupported file type {path.suffix!r} (use {', '.join(BODY_SUFFIXES)})")
            return path
    raise BadInput(file, where, f"file not found: {source!r} (looked beside the world and in pybullet_data)")


def _body(data: Any, file: str, prefix: str, world_dir: Path, is_object: bool) -> BodySpec:
    f = _Fields(data, file, prefix)
    name = f.string("name")
    if not OBJECT_NAME.match(name):  # a known object's name becomes its database key and mesh file name
        raise BadInput(file, f.where("name"), f"{brief(name)} is not a valid body name ({OBJECT_NAME_RULE})")
    position = f.vector("position", (2, 3))
    rpy = f.vector("rpy_deg", 3, [0.0, 0.0, 0.0])
    on = f.string("on_top_of", None) if f.has("on_top_of") else None
    drop = on is not None and len(position) == 3
    if len(position) == 2:
        if on is None:
            raise BadInput(file, f.where("position"), "give x, y, z, or x, y together with on_top_of")
        position = np.append(position, 0.0)
    kinds = [k for k in ("box", "cylinder", "sphere", "source") if f.has(k)]
    if len(kinds) != 1:
        raise BadInput(file, prefix, "needs exactly one of box, cylinder, sphere, source")
    shape, dims, source = kinds[0], np.zeros(3), None
    if shape == "box":
        dims = f.vector("box", 3)
        if np.any(dims <= 0):
            raise BadInput(file, f.where("box"), "extents must be positive")
    elif shape == "cylinder":
        cyl = _Fields(f.get("cylinder"), file, f.where("cylinder"))
        dims = np.array([cyl.number("radius", positive=True), cyl.number("length", positive=True), 0.0])
        cyl.check_unknown()
    elif shape == "sphere":
        dims = np.array([f.number("sphere", positive=True), 0.0, 0.0])
    else:
        source = resolve_source(f.string("source"), world_dir, f.where("source"), file)
        shape = "file"
    scale = np.ones(3)
    if f.has("scale"):
        raw = f.get("scale")
        scale = np.full(3, f.number("scale", positive=True)) if not isinstance(raw, list) else f.vector("scale", 3)
        if np.any(scale <= 0):
            raise BadInput(file, f.where("scale"), "must be positive")
    size = f.number("size", positive=True) if f.has("size") else None
    if size is not None and f.has("scale"):
        raise BadInput(file, f.where("size"), "give either size or scale, not both")
    known = f.boolean("known", False) if is_object else False
    color = tuple(float(c) for c in f.vector("color", (3, 4), [0.7, 0.7, 0.7, 1.0]))
    if not all(0.0 <= c <= 1.0 for c in color):
        raise BadInput(file, f.where("color"), f"RGB(A) components lie in [0, 1], got {brief(list(color))}"
                       + (" (0-255 values? divide by 255)" if max(color) > 1.0 else ""))
    color = color if len(color) == 4 else (*color, 1.0)
    specular = f.number("specular", 0.0)
    if not 0.0 <= specular <= 1.0:
        raise BadInput(file, f.where("specular"), f"the mirror share of the reflected light lies in [0, 1], "
                       f"got {brief(specular)}")
    f.check_unknown()
    return BodySpec(name, position, rpy, shape, dims, source, scale, size, on, known, color, drop, specular)


def _plugin(data: Any, file: str, key: str) -> PluginSpec:
    if isinstance(data, str):
        if not data:
            raise BadInput(file, key, "an empty name (leave the field out for the default)")
        return PluginSpec(data, {})
    f = _Fields(data, file, key)
    plugin = f.string("plugin")
    params = f.optional("params", {})
    if not isinstance(params, dict):
        raise BadInput(file, f.where("params"), f"expected a mapping, got {brief(params)}")
    base = f.vector("base", 4) if f.has("base") else None
    f.check_unknown()
    return PluginSpec(plugin, dict(params), base)


def load_world_spec(path_or_name: str | Path) -> WorldSpec:
    """Read and validate a world file (structure, types, finiteness, files, names)."""
    path = find_world(path_or_name)
    file = str(path)
    f = _Fields(load_yaml(path), file, "")
    unknown = sorted(set(f.data) - set(TOP_LEVEL_FIELDS))
    if unknown:
        raise BadInput(file, unknown[0], f"unknown field (valid: {', '.join(TOP_LEVEL_FIELDS)})")
    name = f.string("name", path.stem)
    description = f.optional("description", "")
    if not isinstance(description, str):
        raise BadInput(file, "description", f"expected text, got {brief(description)}")
    environment = tuple(
        _body(item, file, f"environment[{i}]", path.parent, False) for i, item in enumerate(_list(f, "environment"))
    )
    objects = tuple(_body(item, file, f"objects[{i}]", path.parent, True) for i, item in enumerate(_list(f, "objects")))
    names = [b.name for b in environment + objects]
    for i, body_name in enumerate(names):
        if body_name in names[:i]:
            raise BadInput(file, f"name {body_name!r}", "used by two bodies")
    env_names = {b.name for b in environment}
    for kind, bodies in (("environment", environment), ("objects", objects)):
        for i, body in enumerate(bodies):
            if body.on is not None and body.on not in env_names | ({b.name for b in objects} - {body.name}):
                raise BadInput(file, f"{kind}[{i}].on_top_of", f"no body named {body.on!r}")
    region = _Fields(f.get("region"), file, "region")
    rmin, rmax = region.vector("min", 3), region.vector("max", 3)
    region.check_unknown()
    if np.any(rmax <= rmin):
        raise BadInput(file, "region", "max must be greater than min on every axis")
    robot_field = f.optional("robot", None)
    robot = PluginSpec("", {}) if robot_field is None else _plugin(robot_field, file, "robot")  # "": the default
    sensor = _plugin(f.get("sensor"), file, "sensor")
    overview = None
    if f.has("overview"):
        ov = _Fields(f.get("overview"), file, "overview")
        overview = np.concatenate([ov.vector("eye", 3), ov.vector("target", 3)])
        ov.check_unknown()
        if np.linalg.norm(overview[:3] - overview[3:]) < 1e-6:
            raise BadInput(file, "overview", "eye and target are the same point (the view has no direction)")
    f.check_unknown()
    return WorldSpec(path, name, description, environment, objects, rmin, rmax, robot, sensor, overview)


def _list(f: _Fields, key: str) -> list:
    value = f.optional(key, [])
    if not isinstance(value, list):
        raise BadInput(f.source, key, f"expected a list, got {brief(value)}")
    return value
