"""The strategy contract: a view generator, a utility and a termination, each with parameters.

A strategy plugin is a recipe: building it yields a :class:`Strategy` value (plugin names and
parameters of its three parts) that a modelling session turns into plugins with
:meth:`Strategy.build`. :func:`make_strategy` writes the plugin class of a fixed recipe.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from explore.core import Param
from explore.core.plugin import Plugin


@dataclass
class Strategy:
    """A resolved strategy: plugin names and parameters of its three parts."""

    name: str
    generator: str
    utility: str
    termination: str
    generator_params: dict[str, Any] = field(default_factory=dict)
    utility_params: dict[str, Any] = field(default_factory=dict)
    termination_params: dict[str, Any] = field(default_factory=dict)

    def build(self, registry: Any) -> tuple[Any, Any, Any]:
        """Create the generator, utility and termination plugins."""
        src = f"strategy {self.name}"
        return (
            registry.create("view_generator", self.generator, self.generator_params, src, "generator"),
            registry.create("utility", self.utility, self.utility_params, src, "utility"),
            registry.create("termination", self.termination, self.termination_params, src, "termination"),
        )


OVERRIDES = (
    Param("generator_params", dict, {}, "", "overrides of the view generator's parameters"),
    Param("utility_params", dict, {}, "", "overrides of the utility's parameters"),
    Param("termination_params", dict, {}, "", "overrides of the termination's parameters"),
)


class StrategyPlugin(Plugin):
    """Contract of kind ``strategy``: its constructor sets :attr:`strategy`.

    ``parts`` names the (generator, utility, termination) plugins and ``defaults`` their
    parameter defaults (dicts), so ``explore plugins list --params`` can show the effective
    values; the ``*_params`` overrides of a run are merged over them.
    """

    kind = "strategy"
    params = OVERRIDES
    parts: tuple[str, str, str] = ("", "", "")
    defaults: tuple[dict | None, dict | None, dict | None] = (None, None, None)
    strategy: Strategy


def make_strategy(name: str, doc: str, generator: str, utility: str, termination: str,
                  generator_params: dict | None = None, utility_params: dict | None = None,
                  termination_params: dict | None = None) -> type:
    """A :class:`StrategyPlugin` class with fixed parts and default parameters."""

    def __init__(self: Any, generator_params: dict, utility_params: dict, termination_params: dict) -> None:
        self.strategy = Strategy(
            name, generator, utility, termination,
            {**(defaults[0] or {}), **generator_params},
            {**(defaults[1] or {}), **utility_params},
            {**(defaults[2] or {}), **termination_params},
        )

    defaults = (generator_params, utility_params, termination_params)
    cls = type(
        "Strategy_" + name.replace("/", "_"),
        (StrategyPlugin,),
        {"name": name, "__doc__": doc, "__init__": __init__,
         "parts": (generator, utility, termination), "defaults": defaults},
    )
    return cls
