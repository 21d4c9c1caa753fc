"""Plugin registry: entry-point discovery, lookup, duplicates, parameter validation."""

from __future__ import annotations

import pytest

from explore.core import BadInput, Param, RegistryError, validate_params
from explore.runtime import Registry, hookimpl


def test_builtins_are_found_through_the_entry_point(registry) -> None:
    from importlib import metadata

    eps = [ep for ep in metadata.entry_points(group="explore.plugins") if ep.dist.name == "explore-nbv"]
    assert [ep.value for ep in eps] == ["explore_plugins"]
    info = registry.get("sensor", "depth_camera")
    assert info.origin == "explore-nbv"
    assert info.doc.startswith("Pinhole depth camera")
    assert {"laser_striper", "depth_camera"} <= set(registry.names("sensor"))


def test_unknown_name_lists_the_valid_names(registry) -> None:
    with pytest.raises(RegistryError) as error:
        registry.get("sensor", "lidar", "world.yaml", "sensor")
    line = error.value.line()
    assert "world.yaml: sensor: unknown sensor 'lidar'" in line
    assert "depth_camera" in line and "laser_striper" in line


class _Duplicate:
    """A second laser striper."""

    kind = "sensor"
    name = "laser_striper"
    params = ()


class _Plugin:
    @hookimpl
    def explore_register_plugins(self, register) -> None:
        register(_Duplicate)


def test_a_name_clash_fails_only_lookups_of_that_name_with_both_origins() -> None:
    reg = Registry.load(extra=[("thirdparty", _Plugin())])
    assert reg.clashes == {("sensor", "laser_striper"): ["explore-nbv", "thirdparty"]}
    with pytest.raises(RegistryError) as error:
        reg.create("sensor", "laser_striper", {}, "world.yaml", "sensor")
    assert "laser_striper' is registered by explore-nbv and thirdparty" in error.value.line()
    assert reg.create("sensor", "depth_camera", {}).width == 320  # every other plugin still works


def test_a_package_that_failed_to_load_is_named_with_its_error(registry) -> None:
    reg = Registry.load()
    reg.load_errors["acme-nbv:plugins"] = "ModuleNotFoundError: No module named 'acme_missing'"
    with pytest.raises(RegistryError) as error:
        reg.get("strategy", "acme/fast", "--strategy")
    line = error.value.line()
    assert "unknown strategy 'acme/fast'" in line
    assert "acme-nbv:plugins failed to load (ModuleNotFoundError: No module named 'acme_missing')" in line


def test_defaults_are_declared_by_plugin_packages_and_a_third_party_one_wins() -> None:
    class _Defaults:
        @hookimpl
        def explore_register_plugins(self, register) -> None:
            register.default("recognizer", "vfh_mean_distance")

    assert Registry.load().default("recognizer") == ("ppf", {})
    assert Registry.load().default("registrar", "scans") == ("pose_graph", {})
    reg = Registry.load(extra=[("acme", _Defaults())])
    assert reg.default("recognizer") == ("vfh_mean_distance", {})
    with pytest.raises(RegistryError, match="no installed plugin package declares a default segmenter for x"):
        reg.default("segmenter", "x")


def test_every_plugin_subclasses_the_public_contract_of_its_kind(registry) -> None:
    from explore.api import CONTRACTS

    for info in registry.of_kind():
        assert issubclass(info.factory, CONTRACTS[info.kind]), (info.kind, info.name)


def test_plugins_list_params_shows_a_strategys_effective_defaults(registry) -> None:
    info = registry.get("strategy", "ig/bs_hr")
    values = registry.effective_defaults(info)
    assert values["utility_params"]["omega"] == 0.0  # the strategy's override
    assert values["utility_params"]["beam_stride"] == 4  # the utility's own default
    assert values["termination_params"]["coverage"] == 0.8


class _Extra:
    """An extra sensor from a third-party package."""

    kind = "sensor"
    name = "extra_sensor"
    params = (Param("gain", float, 1.0, "", "a gain", low=0.0),)

    def __init__(self, gain: float) -> None:
        self.gain = gain


class _ExtraPlugin:
    @hookimpl
    def explore_register_plugins(self, register) -> None:
        register(_Extra)


def test_third_party_plugin_is_listed_with_its_origin_and_created_with_params() -> None:
    reg = Registry.load(extra=[("acme-sensors", _ExtraPlugin())])
    info = reg.get("sensor", "extra_sensor")
    assert info.origin == "acme-sensors"
    assert reg.create("sensor", "extra_sensor", {"gain": "2.5"}).gain == 2.5
    with pytest.raises(BadInput, match="below the minimum"):
        reg.create("sensor", "extra_sensor", {"gain": -1})
    with pytest.raises(BadInput, match=r"unknown parameter \(valid: gain\)"):
        reg.create("sensor", "extra_sensor", {"gian": 1})
    with pytest.raises(BadInput, match=r"unknown parameter \(YAML reads 'gain:2' as one name: write 'gain: \.\.\.'\)"):
        reg.create("sensor", "extra_sensor", {"gain:2": None})  # what YAML makes of {gain:2}


def test_parameters_convert_units_and_reject_wrong_ones() -> None:
    declared = [
        Param("max_range", float, 0.5, "m"),
        Param("fan", float, 24.0, "deg"),
        Param("beams", int, 224),
        Param("noise", str, "none", choices=("none", "kinect")),
    ]
    values = validate_params(declared, {"max_range": "450 mm", "fan": "0.5 rad", "beams": 100}, "f.yaml")
    assert values["max_range"] == pytest.approx(0.45)
    assert values["fan"] == pytest.approx(28.6479, abs=1e-3)
    assert values["noise"] == "none"
    for bad, message in [
        ({"max_range": "3 kg"}, "unknown unit"),
        ({"max_range": "3 s"}, "wrong unit 's': expected m"),
        ({"max_range": float("nan")}, "not a finite number"),
        ({"beams": 2.5}, "expected an integer"),
        ({"noise": "gauss"}, "is not one of"),
        ({"max_range": [1]}, "expected a number"),
    ]:
        with pytest.raises(BadInput, match=message):
            validate_params(declared, bad, "f.yaml")


def test_plugins_list_cli_shows_kind_name_origin_doc(capsys) -> None:
    from explore_cli.main import main

    assert main(["plugins", "list", "--kind", "sensor"]) == 0
    out = capsys.readouterr().out
    assert "laser_striper" in out and "explore" in out and "sensor" in out
    assert main(["plugins", "list", "--kind", "nonsense"]) == 2
