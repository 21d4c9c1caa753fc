"""Typed plugin parameters with defaults and units, validated for the CLI and YAML files.

A plugin declares ``params = (Param("max_range", float, 0.5, unit="m", doc=...), ...)``.
Values may be written as plain numbers (in the declared unit) or as strings with a unit
(``"5 mm"``, ``"45 deg"``), which are converted to the declared unit; a unit of the wrong
dimension, a wrong type, NaN/inf or a value out of bounds is a :class:`BadInput`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from explore.core.errors import BadInput, brief
from explore.core.user_files import parse_yaml

# factor to the SI base of each dimension
_UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0),
    "cm": ("length", 1e-2),
    "mm": ("length", 1e-3),
    "rad": ("angle", 1.0),
    "deg": ("angle", math.pi / 180.0),
    "s": ("time", 1.0),
    "ms": ("time", 1e-3),
    "min": ("time", 60.0),
    "Hz": ("frequency", 1.0),
    "m/s": ("speed", 1.0),
    "mm/s": ("speed", 1e-3),
    "rad/s": ("angular_speed", 1.0),
    "deg/s": ("angular_speed", math.pi / 180.0),
    "px": ("pixels", 1.0),
    "%": ("ratio", 0.01),
}
_QUANTITY = re.compile(r"^\s*([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([A-Za-z%/]+)?\s*$")


@dataclass(frozen=True)
class Param:
    """One declared parameter of a plugin."""

    name: str
    type: type
    default: Any
    unit: str = ""
    doc: str = ""
    choices: tuple[Any, ...] | None = None
    low: float | None = None
    high: float | None = None
    length: int | None = None  # for list parameters: exact number of items
    # for a choice parameter (a profile): the values each choice gives other parameters, under
    # those given explicitly (``profile: kinect`` then ``noise_scale: 2`` keeps the rest of kinect)
    presets: Mapping[str, Mapping[str, Any]] | None = field(default=None, compare=False, hash=False)

    def describe(self) -> str:
        unit = f" [{self.unit}]" if self.unit else ""
        choices = f" one of {list(self.choices)}" if self.choices else ""
        if self.presets:
            choices += " (presets: " + "; ".join(
                f"{name}: " + ", ".join(f"{k}={v}" for k, v in values.items()) if values else f"{name}: defaults"
                for name, values in self.presets.items()) + ")"
        return f"{self.name}: {self.type.__name__}{unit} = {self.default!r}{choices}  {self.doc}"

    def convert(self, value: Any, source: str, field: str) -> Any:
        """Return ``value`` converted to this parameter's type and unit, or raise BadInput."""
        if value is None and self.default is not None:  # e.g. ``--set key=``
            expected = f"one of {list(self.choices)}" if self.choices else _KIND.get(self.type, self.type.__name__)
            raise BadInput(source, field, f"is empty: expected {expected}")
        if self.type is list:
            if not isinstance(value, list | tuple):
                raise BadInput(source, field, f"expected a list, got {brief(value)}")
            if self.length is not None and len(value) != self.length:
                raise BadInput(source, field, f"expected {self.length} values, got {len(value)}")
            return [_number(v, float, self.unit, source, f"{field}[{i}]") for i, v in enumerate(value)]
        if self.type in (int, float):
            out = _number(value, self.type, self.unit, source, field)
            if self.type is int and self.low is not None:
                self_low = int(self.low) if float(self.low).is_integer() else self.low
            else:
                self_low = self.low
            if self.low is not None and out < self.low:
                raise BadInput(source, field, f"{out} is below the minimum {self_low} {self.unit}".rstrip())
            if self.high is not None and out > self.high:
                raise BadInput(source, field, f"{out} is above the maximum {self.high} {self.unit}".rstrip())
        elif self.type is bool:
            if isinstance(value, bool):
                out = value
            elif isinstance(value, str) and value.lower() in ("true", "yes", "1", "on"):
                out = True
            elif isinstance(value, str) and value.lower() in ("false", "no", "0", "off"):
                out = False
            else:
                raise BadInput(source, field, f"expected true or false, got {brief(value)}")
        elif self.type is str:
            if not isinstance(value, str):
                raise BadInput(source, field, f"expected a string, got {brief(value)}")
            out = value
        elif self.type is dict:
            if not isinstance(value, Mapping):
                raise BadInput(source, field, f"expected a mapping, got {brief(value)}")
            out = dict(value)
        else:
            out = value
        if self.choices is not None and out not in self.choices:
            raise BadInput(source, field, f"{out!r} is not one of {list(self.choices)}")
        return out


_KIND = {int: "an integer", float: "a number", bool: "true or false", str: "a string", list: "a list",
         dict: "a mapping"}


def _number(value: Any, kind: type, unit: str, source: str, field: str) -> float | int:
    if isinstance(value, bool):
        raise BadInput(source, field, f"expected a number, got {brief(value)}")
    if isinstance(value, int | float):
        number = float(value)
    elif isinstance(value, str):
        match = _QUANTITY.match(value)
        if not match:
            raise BadInput(source, field, f"expected a number{_with(unit)}, got {brief(value)}")
        number = float(match.group(1))
        given = match.group(2)
        if given and given != unit:
            if given not in _UNITS:
                raise BadInput(source, field, f"unknown unit {given!r} in {brief(value)}")
            if not unit or unit not in _UNITS or _UNITS[given][0] != _UNITS[unit][0]:
                raise BadInput(source, field, f"wrong unit {given!r}: expected {unit or 'none'}")
            number = number * _UNITS[given][1] / _UNITS[unit][1]
    else:
        raise BadInput(source, field, f"expected a number{_with(unit)}, got {brief(value)}")
    if not math.isfinite(number):
        raise BadInput(source, field, f"{brief(value)} is not a finite number")
    if kind is int:
        if number != int(number):
            raise BadInput(source, field, f"expected an integer, got {brief(value)}")
        return int(number)
    return number


def _with(unit: str) -> str:
    return f" in {unit}" if unit else ""


def validate_params(
    declared: Iterable[Param], given: Mapping[str, Any] | None, source: str, prefix: str = ""
) -> dict[str, Any]:
    """Merge ``given`` over the declared defaults (and over the presets of a chosen profile),
    converting every value.

    Unknown names are a :class:`BadInput` that lists the valid ones.
    """
    declared = {p.name: p for p in declared}
    given = dict(given or {})
    unknown = sorted(set(given) - set(declared))
    if unknown:
        valid = ", ".join(sorted(declared)) or "none"
        name = str(unknown[0])
        key, sep, _ = name.partition(":")
        hint = f" (YAML reads '{name}' as one name: write '{key}: ...')" if sep and key.strip() in declared else ""
        raise BadInput(source, f"{prefix}{name}", f"unknown parameter{hint} (valid: {valid})")
    out = {name: p.default for name, p in declared.items()}
    for name, p in declared.items():
        if p.presets:
            choice = p.convert(given.get(name, p.default), source, f"{prefix}{name}")
            for key, value in p.presets.get(choice, {}).items():
                out[key] = declared[key].convert(value, source, f"{prefix}{name}={choice}: {key}")
    for name, value in given.items():
        out[name] = declared[name].convert(value, source, f"{prefix}{name}")
    return out


def parse_assignment(text: str, option: str = "--set") -> tuple[str, Any]:
    """Parse a CLI ``key=value`` override of ``option``; the value is read as YAML (numbers, lists, ...)."""
    if "=" not in text:
        raise BadInput(option, brief(text), "expected key=value")
    key, raw = text.split("=", 1)
    if not key.strip():
        raise BadInput(option, brief(text), "empty key")
    try:
        value = parse_yaml(raw, f"{option} {key.strip()}")
    except BadInput as error:
        if not error.message.startswith("malformed YAML"):
            raise
        value = raw  # not YAML: the text itself
    return key.strip(), value
