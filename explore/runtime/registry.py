"""Plugin registry: pluggy hooks, entry-point discovery, lookup by (kind, name).

Built-in plugins are found through the same ``explore.plugins`` entry point as third-party
packages. One broken plugin package does not break the CLI: its load error is recorded and
shown by ``explore plugins list`` (set ``EXPLORE_STRICT_PLUGINS=1`` to raise instead).
``EXPLORE_DISABLE_PLUGIN_AUTOLOAD=1`` skips third-party entry points (the built-ins stay).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import pluggy

from explore.core import Param, PluginCheckFailed, RegistryError, brief, valid_names, validate_params
from explore.runtime.hookspecs import ENTRY_POINT_GROUP, PROJECT, Specs

KINDS: tuple[str, ...] = (
    "sensor",
    "robot",
    "motion_planner",
    "view_generator",
    "utility",
    "termination",
    "strategy",
    "segmenter",
    "recognizer",
    "pose_validator",
    "registrar",
    "behaviour",
    "executor",
)
BUILTIN_DISTRIBUTION = "explore-nbv"  # the distribution name (PyPI's "explore" is an unrelated package)


@dataclass(frozen=True)
class PluginInfo:
    """A registered plugin: how to build it and what it accepts."""

    kind: str
    name: str
    factory: Callable[..., Any]
    params: tuple[Param, ...]
    doc: str
    origin: str  # distribution (package) that registered it

    def create(self, values: Mapping[str, Any] | None = None, source: str = "<params>") -> Any:
        """Validate ``values`` against the declared parameters and build the plugin."""
        return self.factory(**validate_params(self.params, values, source))


@dataclass
class Registry:
    """All plugins known in this process, by kind and name."""

    plugins: dict[tuple[str, str], PluginInfo] = field(default_factory=dict)
    load_errors: dict[str, str] = field(default_factory=dict)
    #: (kind, name) -> every origin that registered it, when more than one did (that name is unusable)
    clashes: dict[tuple[str, str], list[str]] = field(default_factory=dict)
    #: (kind, role) -> (plugin name, parameters, origin): the choice where a run names none
    defaults: dict[tuple[str, str], tuple[str, dict[str, Any], str]] = field(default_factory=dict)
    manager: pluggy.PluginManager | None = None

    @classmethod
    def load(
        cls,
        entry_points: bool = True,
        extra: Iterable[tuple[str, object]] = (),
        blocked: Sequence[str] = (),
    ) -> Registry:
        """Discover plugins through the ``explore.plugins`` entry points (and ``extra``)."""
        pm = pluggy.PluginManager(PROJECT)
        pm.add_hookspecs(Specs)
        registry = cls(manager=pm)
        origins: dict[str, str] = {}
        autoload = entry_points and not os.environ.get("EXPLORE_DISABLE_PLUGIN_AUTOLOAD")
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            dist = ep.dist.name if ep.dist is not None else ep.value
            is_builtin = dist == BUILTIN_DISTRIBUTION
            if ep.name in blocked or pm.is_registered(ep.name) or not (autoload or is_builtin):
                continue
            try:
                plugin = ep.load()
            except Exception as error:  # noqa: BLE001 - a broken package must not break the CLI
                if os.environ.get("EXPLORE_STRICT_PLUGINS"):
                    raise
                registry.load_errors[f"{dist}:{ep.name}"] = f"{type(error).__name__}: {error}"
                continue
            name = f"{dist}:{ep.name}"
            if pm.is_registered(plugin):  # the same module through a second (stale) distribution
                continue
            pm.register(plugin, name=name)
            origins[name] = dist
        if not any(d == BUILTIN_DISTRIBUTION for d in origins.values()):
            registry.load_errors[BUILTIN_DISTRIBUTION] = (
                "the built-in plugins are not installed (run ./run.sh setup, or pip install -e . in the source tree)")
        for name, plugin in extra:
            pm.register(plugin, name=name)
            origins[name] = name
        pm.check_pending()
        for impl in pm.hook.explore_register_plugins.get_hookimpls():
            origin = origins.get(impl.plugin_name, impl.plugin_name)
            impl.function(register=registry._registrar(origin))
        return registry

    def _registrar(self, origin: str) -> Callable[..., PluginInfo]:
        def default(kind: str, name: str, params: Mapping[str, Any] | None = None, role: str = "") -> None:
            """Declare ``name`` (with ``params``) the plugin of ``kind`` the library uses for ``role``
            when a run names none; a built-in default yields to a third-party one."""
            held = self.defaults.get((kind, role))
            if held is not None and held[2] != BUILTIN_DISTRIBUTION and origin != BUILTIN_DISTRIBUTION:
                raise RegistryError(origin, f"default {kind} {role!r}", f"declared twice: by {held[2]} and by {origin}")
            if held is None or held[2] == BUILTIN_DISTRIBUTION:
                self.defaults[(kind, role)] = (name, dict(params or {}), origin)

        def register(
            factory: Callable[..., Any],
            kind: str | None = None,
            name: str | None = None,
            params: Sequence[Param] | None = None,
            doc: str | None = None,
        ) -> PluginInfo:
            kind = kind or getattr(factory, "kind", None)
            name = name or getattr(factory, "name", None)
            if kind not in KINDS:
                raise RegistryError(origin, "kind", f"{kind!r} is not a plugin kind {list(KINDS)}")
            if not name:
                raise RegistryError(origin, kind, "plugin registered without a name")
            params = tuple(params if params is not None else getattr(factory, "params", ()))
            doc = doc if doc is not None else (factory.__doc__ or "").strip().splitlines()[:1]
            doc = doc if isinstance(doc, str) else (doc[0] if doc else "")
            info = PluginInfo(kind, name, factory, params, doc, origin)
            existing = self.plugins.get((kind, name))
            if existing is not None:  # only the commands that use this name fail (get() says why)
                origins = self.clashes.setdefault((kind, name), [existing.origin])
                origins.append(origin)
                return info
            self.plugins[(kind, name)] = info
            return info

        register.default = default  # type: ignore[attr-defined]
        return register

    def default(self, kind: str, role: str = "") -> tuple[str, dict[str, Any]]:
        """(name, parameters) of the plugin a package declared the default of ``kind`` for ``role``."""
        try:
            name, params, _ = self.defaults[(kind, role)]
        except KeyError:
            what = f"{kind} for {role}" if role else kind
            raise RegistryError("<plugins>", kind, f"no installed plugin package declares a default {what}") from None
        return name, dict(params)

    def planner_for(self, robot: Any) -> str:
        """The motion planner a robot (or robot class) moves with when a run names none: its own
        ``default_planner``, else the declared default motion planner."""
        return robot.default_planner or self.default("motion_planner")[0]

    def names(self, kind: str) -> list[str]:
        """Sorted names of the plugins of one kind."""
        return sorted(name for (k, name) in self.plugins if k == kind)

    def get(self, kind: str, name: str, source: str = "<lookup>", field: str | None = None) -> PluginInfo:
        """The plugin (kind, name); an unknown name fails with the list of valid names."""
        if kind not in KINDS:
            raise RegistryError(source, field, f"unknown plugin kind {kind!r} (valid: {', '.join(KINDS)})")
        if (kind, name) in self.clashes:
            origins = " and ".join(self.clashes[(kind, name)])
            raise RegistryError(source, field, f"{kind} {brief(name)} is registered by {origins}: uninstall or "
                                "rename one (or block a package with EXPLORE_BLOCK_PLUGINS)")
        try:
            return self.plugins[(kind, name)]
        except KeyError:
            hint = valid_names(name, self.names(kind), f"`explore plugins list --kind {kind}`")
            broken = "; ".join(f"{package} failed to load ({error})" for package, error in self.load_errors.items())
            hint = f"{hint}; {broken}" if broken else hint
            raise RegistryError(source, field, f"unknown {kind} {brief(name)} {hint}") from None

    def create(
        self,
        kind: str,
        name: str,
        params: Mapping[str, Any] | None = None,
        source: str = "<params>",
        field: str | None = None,
    ) -> Any:
        """Look up and build a plugin with validated parameters."""
        info = self.get(kind, name, source, field)
        prefix = f"{field}.params." if field else ""
        values = validate_params(info.params, params, source, prefix)
        try:
            return info.factory(**values)
        except ValueError as error:  # a plugin's own consistency check on its parameters
            raise PluginCheckFailed(source, f"{field or kind} {name}", str(error), kind) from None

    def effective_defaults(self, info: PluginInfo) -> dict[str, Any]:
        """The parameter values a plugin gets when a run sets none. A strategy's ``*_params`` are
        its parts' own defaults with the strategy's overrides merged over them."""
        values = {p.name: p.default for p in info.params}
        parts, overrides = getattr(info.factory, "parts", None), getattr(info.factory, "defaults", None)
        if info.kind != "strategy" or not parts or overrides is None:
            return values
        for key, kind, name, override in zip(("generator_params", "utility_params", "termination_params"),
                                              ("view_generator", "utility", "termination"), parts, overrides,
                                              strict=True):
            part = self.plugins.get((kind, name))
            own = {p.name: p.default for p in part.params} if part is not None else {}
            values[key] = {**own, **(override or {})}
        return values

    def of_kind(self, kind: str | None = None) -> list[PluginInfo]:
        """Plugins sorted by kind and name, optionally of one kind only."""
        items = [p for p in self.plugins.values() if kind is None or p.kind == kind]
        return sorted(items, key=lambda p: (KINDS.index(p.kind), p.name))
