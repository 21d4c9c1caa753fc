"""The public plugin API: one module, a contract per kind, documented, and layering enforced."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_every_kind_has_a_contract_in_the_api() -> None:
    import explore.api as api
    from explore.runtime import KINDS

    assert set(api.CONTRACTS) == set(KINDS)
    for name in api.__all__:
        assert hasattr(api, name), name


def test_a_plugin_that_leaves_out_part_of_its_contract_cannot_be_built() -> None:
    from explore.api import Utility

    class Incomplete(Utility):
        name = "incomplete"

    with pytest.raises(TypeError, match="abstract method"):
        Incomplete()


def test_a_registrar_states_its_role_and_a_step_refuses_another_role(open_world, registry, tmp_path) -> None:
    """A registrar's role fixes its ``register`` signature; a scene session given the scan-to-model
    ICP where it needs a pose graph says so in one line instead of calling it with scans."""
    from explore.api import BadInput, ScansRegistrar
    from explore.perception import ObjectDatabase
    from explore.scene import SceneSession

    class HalfAGraph(ScansRegistrar):
        name = "half"

        def register(self, scans, poses=None):  # noqa: ANN001, ANN202
            return None

    with pytest.raises(TypeError, match="incremental"):
        HalfAGraph()
    with open_world("scene_small") as sim, ObjectDatabase.open(tmp_path / "o.db") as db:
        with pytest.raises(BadInput, match="'icp' has role 'scan_to_model'; this step needs .* role 'scans'"):
            SceneSession(sim, registry, db, registrar="icp")


def test_writing_plugins_documents_every_contract_as_the_api_states_it() -> None:
    spec = importlib.util.spec_from_file_location("gen_contracts", ROOT / "docs" / "gen_contracts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = (ROOT / "docs" / "writing-plugins.md").read_text(encoding="utf-8")
    assert module.render() in text, "docs/writing-plugins.md is stale: run python docs/gen_contracts.py"
    for kind in ("robot", "sensor", "strategy", "executor"):
        assert f"### `{kind}`" in text


@pytest.mark.timeout(300)
def test_import_layers_hold() -> None:
    """import-linter: the library never imports plugins or the CLI; each layer imports only those below."""
    lint = Path(sys.executable).parent / "lint-imports"
    out = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=280)
    assert out.returncode == 0, out.stdout[-3000:]
    assert "3 kept, 0 broken" in out.stdout


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while component[-1:] != [v]:
                component.append(stack.pop())
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def test_the_library_has_no_import_cycles() -> None:
    """Not even through imports inside functions (only ``if TYPE_CHECKING:`` imports may point back)."""
    import grimp

    graph = grimp.build_graph("explore", exclude_type_checking_imports=True)
    edges = {m: graph.find_modules_directly_imported_by(m) for m in graph.modules}
    assert _cycles(edges) == []
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]  # the check can fail


def test_robots_declare_capabilities_and_the_library_reads_them(registry) -> None:
    from explore.api import Capability

    made = {name: registry.create("robot", name, {}) for name in registry.names("robot")}
    assert made["free_flyer"].has(Capability.FREE_FLYER)
    assert made["mobile_manipulator"].has(Capability.MOBILE_BASE) and made["mobile_manipulator"].has(Capability.ARM)
    assert not made["arm"].has(Capability.MOBILE_BASE)
    assert made["mobile_manipulator"].default_planner == "tuck_and_drive"
    laser = registry.create("robot", "mobile_base", {"laser_height": 0.3})
    assert laser.has(Capability.PLANAR_LASER) and not made["mobile_base"].has(Capability.PLANAR_LASER)


def test_a_sensor_noise_model_is_its_own_measure(registry) -> None:
    """The default measure adds sigma(d) noise; a sensor may override it (the example ToF camera does)."""
    sensor = registry.create("sensor", "depth_camera", {"noise": "kinect"})
    ranges = np.full(20000, 1.0)
    noisy = sensor.measure(ranges.copy(), np.ones_like(ranges), np.random.default_rng(0))
    assert np.std(noisy - ranges) == pytest.approx(1.425e-3, rel=0.03)  # Khoshelham sigma at 1 m


def _unresolved_explore_imports(files: list[Path]) -> list[str]:
    """``from explore... import name`` and ``import explore...`` statements (at any depth, the lazy ones
    inside functions too) whose module or name does not exist."""
    import ast
    import importlib

    missing = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "explore":
                pairs = [(node.module, alias.name) for alias in node.names]
            elif isinstance(node, ast.Import):
                pairs = [(alias.name, None) for alias in node.names if alias.name.split(".")[0] == "explore"]
            else:
                continue
            for module, name in pairs:
                try:
                    found = importlib.import_module(module)
                    if name is not None and not hasattr(found, name):
                        importlib.import_module(f"{module}.{name}")  # a submodule
                except ImportError:
                    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                    missing.append(f"{where}:{node.lineno}: {module}{'.' + name if name else ''}")
    return missing


def test_every_import_from_the_library_in_benchmarks_cli_and_plugins_resolves(tmp_path) -> None:
    """Benchmarks, the CLI and plugins import the library lazily inside functions, where a moved module is
    found only when someone runs that path; every such import must name a module and a name that exist."""
    files = [f for folder in ("benchmarks", "docs", "cli", "plugins") for f in sorted((ROOT / folder).rglob("*.py"))]
    assert len(files) > 40
    assert _unresolved_explore_imports(files) == []
    stale = tmp_path / "stale.py"
    stale.write_text("def f():\n    from explore import planning_clock\n", encoding="utf-8")
    assert _unresolved_explore_imports([stale]) == [f"{stale}:2: explore.planning_clock"]
