"""explore compare: a 2x2x2 grid end to end, resume after an interrupt, crash and timeout
records, summary numbers vs results.csv, bad arguments, Ray vs local, report.html in Chromium.

The runs use small test plugins defined here (loaded by the runs' processes through
``--plugin tests/test_compare.py:TEST_PLUGINS``): a fake modelling behaviour whose numbers
depend only on world, strategy, planner and seed, so results are exactly reproducible.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from explore.core import Param
from explore.runtime import ExploreBehaviour, hookimpl, success

HERE = Path(__file__).resolve()
PLUGIN = f"{HERE}:TEST_PLUGINS"
EXPLORE = Path(sys.executable).parent / "explore"


# -- test plugins -----------------------------------------------------------------------------
class GreedyStrategy:
    """Test strategy: each scan covers `rate` of what is still missing (plus seeded noise)."""

    kind = "strategy"
    name = "test_greedy"
    params = (Param("rate", float, 0.45, "", "share of the rest covered per scan"),)

    def __init__(self, rate: float) -> None:
        self.rate = rate


class RandomStrategy(GreedyStrategy):
    """Test strategy: slower than test_greedy."""

    name = "test_random"
    params = (Param("rate", float, 0.25, "", "share of the rest covered per scan"),)


class CrashStrategy(GreedyStrategy):
    """Test strategy whose run process aborts (a crash)."""

    name = "test_crash"


class HangStrategy(GreedyStrategy):
    """Test strategy whose run never ends (a timeout)."""

    name = "test_hang"


class StraightPlanner:
    """Test motion planner: straight moves, always succeeds."""

    kind = "motion_planner"
    name = "test_straight"
    params = ()
    detour = 1.0
    success = 1.0


class DetourPlanner(StraightPlanner):
    """Test motion planner: 40 % longer moves, 75 % success."""

    name = "test_detour"
    detour = 1.4
    success = 0.75


class FakeOutputs:
    """Metrics provider for the run directory (what a modelling session would report)."""

    def __init__(self, metrics: dict) -> None:
        self.metrics = metrics

    def run_outputs(self, out_dir: Path) -> dict:
        return self.metrics


class FakeModel(ExploreBehaviour):
    """Test behaviour: a deterministic fake modelling run driven by strategy, planner and seed."""

    name = "test_fake_model"
    blocking = True
    params = (Param("delay", float, 0.0, "s", "sleep per scan", low=0.0),)

    def work(self):
        ctx = self.context
        config = ctx.config
        strategy_name = config.strategy or "test_greedy"
        strategy = ctx.registry.create("strategy", strategy_name)
        if strategy_name == "test_crash":
            os.abort()
        if strategy_name == "test_hang":
            time.sleep(3600)
        planner = ctx.registry.get("motion_planner", config.planner or "test_straight").factory
        world = ctx.sim.spec.name
        rng = np.random.default_rng([config.seed, zlib.crc32(f"{world}/{strategy_name}".encode())])
        max_scans = config.max_scans or 12
        covered, estimate, curve, curve_estimate, selections = 0.0, 0.0, [], [], []
        for _ in range(max_scans):
            time.sleep(self.p["delay"])
            covered += (1.0 - covered) * strategy.rate * rng.uniform(0.6, 1.4)
            estimate = 0.9 * covered
            curve.append(round(covered, 6))
            curve_estimate.append(round(estimate, 6))
            selections.append(round(float(rng.uniform(0.01, 0.05)), 6))
            if estimate >= 0.8:
                break
        moves = len(curve) - 1
        collisions = int(np.sum(rng.random(moves) < 0.1 * planner.detour))
        ctx.state["fake"] = FakeOutputs({
            "scans": len(curve),
            "coverage": curve[-1],
            "coverage_estimate": curve_estimate[-1],
            "coverage_per_scan": curve,
            "coverage_estimate_per_scan": curve_estimate,
            "path_length_m": round(float(np.sum(rng.uniform(0.2, 0.5, moves)) * planner.detour), 6),
            "selection_s_mean": round(float(np.mean(selections)), 6),
            "selection_s_per_scan": selections,
            "collisions": collisions,
            "trajectories": moves,
            "planning_success": planner.success,
            "planning_time_s": round(0.01 * moves * planner.detour, 6),
        })
        return success(f"{len(curve)} scans")


class Finish(ExploreBehaviour):
    """Test behaviour: a short blocking final step (for the time-per-step breakdown)."""

    name = "test_finish"
    blocking = True

    def work(self):
        time.sleep(0.05)
        return success("finished")


class _TestPlugins:
    @hookimpl
    def explore_register_plugins(self, register) -> None:
        for plugin in (GreedyStrategy, RandomStrategy, CrashStrategy, HangStrategy, StraightPlanner, DetourPlanner,
                       FakeModel, Finish):
            register(plugin)


TEST_PLUGINS = _TestPlugins()

TREE = """
name: fake_model
root:
  sequence: Fake mission
  memory: true
  children:
    - behaviour: test_fake_model
      name: Model
    - behaviour: test_finish
      name: Finish
"""
WORLDS = "bunny_pedestal,duck_pedestal"
# columns that measure time: everything else must be identical between executors
TIMING = ("elapsed_s", "wall_s", "selection_s_mean", "selection_s_per_scan", "planning_time_s")


def grid_args(tree: Path, out: Path, *extra: str) -> list[str]:
    return [
        "compare", "--tree", str(tree), "--worlds", WORLDS, "--strategies", "test_greedy,test_random",
        "--planners", "test_straight", "--seeds", "2", "--max-scans", "12", "--jobs", "2",
        "--plugin", PLUGIN, "--out", str(out), *extra,
    ]


def csv_rows(out: Path) -> list[dict]:
    from explore.runtime import read_results

    path = out / "results.csv"
    return read_results(path) if path.exists() else []


@pytest.fixture(scope="module")
def tree_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tree") / "fake_model.yaml"
    path.write_text(TREE)
    return path


@pytest.fixture(scope="module")
def compared(tmp_path_factory, tree_file) -> dict:
    """A 2 worlds x 2 strategies x 2 seeds comparison, interrupted once and resumed."""
    out = tmp_path_factory.mktemp("cmp") / "results"
    args = [str(EXPLORE), *grid_args(tree_file, out, "--set", "test_fake_model.delay=0.25")]
    first = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 120
    while not csv_rows(out) and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.1)
    first.send_signal(signal.SIGTERM)
    first_output, _ = first.communicate(timeout=60)
    # a run may complete while the driver is being stopped: resume counts it as finished too
    from explore.runtime import complete_metrics

    finished = {p.name for p in (out / "runs").iterdir() if complete_metrics(p) is not None}
    assert {r["run_id"] for r in csv_rows(out)} <= finished
    stamps = {
        run_id: {p.name: p.stat().st_mtime_ns for p in (out / "runs" / run_id).iterdir()} for run_id in finished
    }
    started = time.monotonic()
    second = subprocess.run(args, capture_output=True, text=True, timeout=300)
    return {
        "out": out, "first_code": first.returncode, "first_output": first_output, "finished_first": finished,
        "stamps": stamps, "second": second, "second_s": time.monotonic() - started,
    }


# -- tests ------------------------------------------------------------------------------------
@pytest.mark.slow
def test_grid_runs_end_to_end_and_resumes_after_an_interrupt(compared) -> None:
    out = compared["out"]
    assert compared["first_code"] == 143, compared["first_output"]
    assert "run the same command to resume" in compared["first_output"]
    finished = compared["finished_first"]
    assert 1 <= len(finished) < 8, "the interrupt should come after the first results"
    second = compared["second"]
    assert second.returncode == 0, second.stdout + second.stderr
    assert f"8 runs: {len(finished)} already finished, {8 - len(finished)} to run" in second.stdout
    rows = csv_rows(out)
    assert len(rows) == 8
    assert {r["status"] for r in rows} == {"success"}
    assert [r["run_id"] for r in rows] == sorted(r["run_id"] for r in rows)  # grid order
    assert {(r["world"], r["strategy"], r["seed"]) for r in rows} == {
        (w, s, k) for w in ("bunny_pedestal", "duck_pedestal") for s in ("test_greedy", "test_random") for k in (0, 1)
    }
    for run_id, stamps in compared["stamps"].items():  # finished runs are not repeated
        now = {name: (out / "runs" / run_id / name).stat().st_mtime_ns for name in stamps}
        assert now == stamps, run_id
    for row in rows:
        run_dir = out / "runs" / row["run_id"]
        assert json.loads((run_dir / "metrics.json").read_text())["status"] == "success"
        assert (run_dir / "trace.jsonl").exists() and (run_dir / "run.log").exists()
        assert isinstance(row["coverage_per_scan"], list) and row["scans"] == len(row["coverage_per_scan"])
    for name in ("summary.md", "summary.json", "report.html", "coverage_vs_scans.png", "scans_violin.png",
                 "time_per_step.png", "planners.png"):
        assert (out / name).stat().st_size > 0, name


def _recompute(rows: list[dict], n_at: int) -> dict:
    """Kriegel / Vasquez numbers per (world, strategy), straight from the CSV rows."""
    out = {}
    for world in {r["world"] for r in rows}:
        for strategy in {r["strategy"] for r in rows}:
            group = [r for r in rows if r["world"] == world and r["strategy"] == strategy]
            scans = np.array([r["scans"] for r in group], dtype=float)
            q1, q3 = np.percentile(scans, [25, 75])
            curves = [r["coverage_per_scan"] for r in group]
            collisions = sum(r["collisions"] for r in group)
            moves = sum(r["trajectories"] for r in group)
            out[(world, strategy)] = {
                "median_scans": float(np.median(scans)),
                "notch": 1.57 * (q3 - q1) / math.sqrt(len(group)),
                "coverage_at_termination": float(np.mean([r["coverage"] for r in group])),
                "coverage_at_n": float(np.mean([c[min(n_at, len(c)) - 1] for c in curves])),
                "path_length_m": float(np.mean([r["path_length_m"] for r in group])),
                "selection_s": float(np.mean([r["selection_s_mean"] for r in group])),
                "mean_coverage": float(np.mean([r["coverage"] for r in group])),
                "max_coverage": float(np.max([r["coverage"] for r in group])),
                "collision_rate": collisions / moves,
            }
    return out


@pytest.mark.slow
def test_summary_numbers_equal_those_recomputed_from_results_csv(compared) -> None:
    out = compared["out"]
    rows = csv_rows(out)
    expected = _recompute(rows, 12)
    summary = json.loads((out / "summary.json").read_text())
    markdown = (out / "summary.md").read_text()
    seen = 0
    for world in ("bunny_pedestal", "duck_pedestal"):
        for value in summary[f"kriegel-{world}"]["rows"]:
            want = expected[(world, value["method"])]
            for key in ("median_scans", "notch", "coverage_at_termination", "coverage_at_n", "path_length_m",
                        "selection_s"):
                assert value[key] == pytest.approx(want[key], abs=1e-9), (world, key)
            line = (
                f"| {value['method']} | 2 | {want['median_scans']:g} | ±{want['notch']:.2f} | "
                f"{100 * want['coverage_at_termination']:.2f} | {100 * want['coverage_at_n']:.2f} | "
                f"{want['path_length_m']:.2f} | {want['selection_s']:.3f} |"
            )
            assert line in markdown
            seen += 1
    for value in summary["vasquez"]["rows"]:
        want = expected[(value["world"], value["method"])]
        for key in ("mean_coverage", "max_coverage", "collision_rate"):
            assert value[key] == pytest.approx(want[key], abs=1e-9), key
        seen += 1
    assert seen == 8
    assert "c̄_a(12) %" in markdown and "Vasquez-Gomez Table 5 layout" in markdown


@pytest.mark.slow
def test_plot_only_redraws_the_report(compared, tmp_path, capsys) -> None:
    from explore_cli.main import main

    copy = tmp_path / "copy"
    shutil.copytree(compared["out"], copy)
    for name in ("summary.md", "summary.json", "report.html", "coverage_vs_scans.png", "scans_violin.png"):
        (copy / name).unlink()
    assert main(["compare", "--plot-only", str(copy)]) == 0
    for name in ("summary.md", "summary.json", "report.html", "coverage_vs_scans.png", "scans_violin.png"):
        assert (copy / name).stat().st_size > 0
    assert (copy / "summary.md").read_text() == (compared["out"] / "summary.md").read_text()


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


CHECK_SCRIPT = """
<script>
window.addEventListener('load', function () {
  var imgs = Array.from(document.images);
  var tables = Array.from(document.querySelectorAll('table'));
  var result = {
    images: imgs.length,
    rendered: imgs.filter(function (i) { return i.complete && i.naturalWidth > 0 && i.naturalHeight > 0; }).length,
    tables: tables.length,
    filled: tables.filter(function (t) { return t.rows.length > 1 && t.offsetHeight > 0; }).length,
    page_width: document.documentElement.scrollWidth,
    window_width: window.innerWidth
  };
  var pre = document.createElement('pre');
  pre.id = 'render-check';
  pre.textContent = JSON.stringify(result);
  document.body.appendChild(pre);
});
</script>
"""


@pytest.mark.slow
@pytest.mark.skipif(_chromium() is None, reason="Debian's chromium is not installed (apt-get install chromium)")
def test_report_renders_every_table_and_image_in_headless_chromium(compared, tmp_path) -> None:
    """Every image and table renders, and at 1000 px the page needs no sideways scrolling (wide tables
    scroll in their own box); the screenshot is kept beside the report."""
    page = (compared["out"] / "report.html").read_text()
    assert "src='http" not in page and "<link" not in page  # self-contained
    n_images, n_tables = page.count("<img "), page.count("<table ")
    assert n_images == 4 and n_tables >= 6
    probe = tmp_path / "report.html"
    probe.write_text(page.replace("</body>", CHECK_SCRIPT + "</body>"))
    chromium = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000", "--window-size=1000,1400"]
    done = subprocess.run([*chromium, "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120)
    match = re.search(r'<pre id="render-check">(.*?)</pre>', done.stdout)
    assert match, done.stderr[-2000:]
    result = json.loads(match.group(1))
    assert result["window_width"] == 1000 and result.pop("page_width") <= result.pop("window_width")
    assert result == {"images": n_images, "rendered": n_images, "tables": n_tables, "filled": n_tables}
    shot = tmp_path / "report_1000px.png"
    subprocess.run([*chromium, f"--screenshot={shot}", (compared["out"] / "report.html").as_uri()],
                   capture_output=True, timeout=120)
    from PIL import Image

    assert Image.open(shot).size == (1000, 1400)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.slow
def test_ray_executor_gives_the_same_results_as_local(compared, tree_file, tmp_path) -> None:
    """Against a head started with token authentication (a real cluster's set-up): the driver
    connects with the cluster's token file and gives the local executor's results."""
    import secrets

    port = _free_port()
    ray_bin = Path(sys.executable).parent / "ray"
    ray_tmp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay short
    token = tmp_path / "ray_token"
    token.write_text(secrets.token_hex(32))
    head_env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token)}
    driver_env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    head = subprocess.Popen(
        [str(ray_bin), "start", "--head", "--block", f"--port={port}", "--node-ip-address=127.0.0.1",
         "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={ray_tmp}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True, env=head_env,
    )
    try:
        out = tmp_path / "ray_results"
        args = [str(EXPLORE), *grid_args(tree_file, out, "--executor", "ray", "--ray-address", f"127.0.0.1:{port}",
                                         "--ray-token-file", str(token))]
        deadline = time.monotonic() + 60
        while True:  # the head needs a few seconds before it accepts drivers
            assert head.poll() is None, f"ray start failed: {head.stdout.read()[-2000:]}"
            done = subprocess.run(args, capture_output=True, text=True, timeout=240, env=driver_env)
            if done.returncode == 0 or time.monotonic() > deadline:
                break
            time.sleep(2)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        no_token = subprocess.run(args[:-2], capture_output=True, text=True, timeout=120, env=driver_env,
                                  cwd=tmp_path)
        lines = no_token.stderr.strip().splitlines()
        assert no_token.returncode == 2 and len(lines) == 1 and "token authentication" in lines[0], no_token.stderr
    finally:
        os.killpg(head.pid, signal.SIGKILL)  # the head and every Ray process it started (its group)
        head.wait()
        head.stdout.close()
        shutil.rmtree(ray_tmp, ignore_errors=True)
    local, remote = csv_rows(compared["out"]), csv_rows(out)
    assert len(remote) == 8
    strip = [{k: v for k, v in r.items() if k not in TIMING} for r in local]
    assert [{k: v for k, v in r.items() if k not in TIMING} for r in remote] == strip


def test_an_unreachable_ray_address_is_one_line_and_exit_2(tree_file, tmp_path) -> None:
    out = tmp_path / "unreached"
    args = [str(EXPLORE), *grid_args(tree_file, out, "--executor", "ray", "--ray-address", f"127.0.0.1:{_free_port()}")]
    t0 = time.monotonic()
    done = subprocess.run(args, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and time.monotonic() - t0 < 30
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--ray-address" in lines[0] and "no Ray head answers there" in lines[0], done.stderr
    assert not out.exists()


@pytest.mark.slow
def test_crash_and_timeout_are_recorded_and_do_not_stop_the_others(tree_file, tmp_path) -> None:
    from explore.runtime import Grid, compare, make_registry

    registry = make_registry([PLUGIN])
    grid = Grid(
        tree=str(tree_file), worlds=["bunny_pedestal"], strategies=["test_greedy", "test_crash", "test_hang"],
        planners=["test_straight", "test_detour"], seeds=[0], max_scans=6, timeout=20.0, plugins=[PLUGIN],
    )
    executor = registry.create("executor", "local", {"jobs": 2})
    rows = compare(grid, tmp_path / "out", executor)
    status = {(r["strategy"], r["planner"]): (r["status"], r["reason"]) for r in rows}
    for planner in ("test_straight", "test_detour"):
        assert status[("test_greedy", planner)][0] == "success"
        assert status[("test_crash", planner)] == ("crashed", status[("test_crash", planner)][1])
        assert status[("test_crash", planner)][1].startswith("killed by SIGABRT")
        assert status[("test_hang", planner)] == ("timeout", "timed out after 20 s")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    planners = {v["planner"]: v for v in summary["planners"]["rows"]}
    assert planners["test_detour"]["planning_success"] == pytest.approx(0.75)
    assert planners["test_straight"]["run_success"] == pytest.approx(1 / 3)
    runs = summary["runs"]["rows"]
    assert sum(v["crashed"] for v in runs) == 2 and sum(v["timeout"] for v in runs) == 2
    for row in rows:
        if row["status"] in ("crashed", "timeout"):
            error = json.loads((tmp_path / "out" / "runs" / row["run_id"] / "error.json").read_text())
            assert error == {"status": row["status"], "reason": row["reason"]}


BAD = [
    (["--strategies", "nope"], "--strategies: unknown strategy 'nope' ("),
    (["--worlds", ""], "--worlds: empty list"),
    (["--worlds", "atlantis"], "atlantis: no such world file"),
    (["--planners", "warp"], "unknown motion_planner 'warp'"),
    (["--executor", "slurm"], "unknown executor 'slurm' (valid: local, ray)"),
    (["--seeds", "0"], "--seeds: 0: needs at least 1 seed"),
    (["--seeds", "4-1"], "--seeds: 4-1: the range ends before it starts"),
    (["--seeds", "0-x"], "--seeds: 0-x: expected N, a range A-B or a list"),
    (["--seeds", "1,1"], "--seeds: 1,1: a seed is listed twice"),
]


def test_seeds_are_a_count_a_range_or_a_list() -> None:
    from explore_cli.compare_cmd import parse_seeds

    assert parse_seeds("3") == [0, 1, 2]
    assert parse_seeds("5-9") == [5, 6, 7, 8, 9]
    assert parse_seeds("0,3,7") == [0, 3, 7]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_bad_arguments_exit_2_with_one_line_before_any_run(tree_file, tmp_path, capsys, change, message) -> None:
    from explore_cli.main import main

    out = tmp_path / "never"
    args = grid_args(tree_file, out)
    for i in range(0, len(change), 2):
        if change[i] in args:
            args[args.index(change[i]) + 1] = change[i + 1]
        else:
            args += change[i : i + 2]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert len(err.splitlines()) == 1, err
    assert not out.exists()


def test_plot_only_without_results_is_bad_input(tmp_path, capsys) -> None:
    from explore_cli.main import main

    assert main(["compare", "--plot-only", str(tmp_path)]) == 2
    assert "no results.csv here" in capsys.readouterr().err


def test_report_of_crashed_runs_only_has_every_table_and_no_empty_plot(tmp_path) -> None:
    from explore.runtime import write_report

    rows = [
        {"run_id": f"w__s{i}", "world": "w", "strategy": f"s{i}", "planner": "default", "robot": "default",
         "seed": 0, "status": status, "reason": "boom", "wall_s": 1.0}
        for i, status in enumerate(("crashed", "timeout"))
    ]
    written = write_report(tmp_path, rows)
    assert set(written) == {"summary.md", "summary.json", "report.html"}
    summary = json.loads(written["summary.json"].read_text())
    assert [v["n"] for v in summary["kriegel-w"]["rows"]] == [0, 0]
    assert "| s0 | 0 | – | – | – | – | – | – |" in written["summary.md"].read_text()


def test_step_times_count_only_leaf_behaviours(tmp_path) -> None:
    from explore.runtime import step_times

    events = [
        ("Loop", "RUNNING", 0.0), ("Scan", "RUNNING", 0.0), ("Scan", "SUCCESS", 1.5), ("Plan", "RUNNING", 1.5),
        ("Plan", "SUCCESS", 2.0), ("Loop", "SUCCESS", 2.0), ("Loop", "RUNNING", 2.1), ("Scan", "RUNNING", 2.1),
        ("Scan", "SUCCESS", 3.1), ("Loop", "SUCCESS", 3.2),
    ]
    trace = tmp_path / "trace.jsonl"
    trace.write_text("\n".join(json.dumps({"t": t, "event": "status", "node": n, "status": s}) for n, s, t in events))
    assert step_times(trace) == pytest.approx({"Scan": 2.5, "Plan": 0.5})


@pytest.mark.slow
def test_real_model_object_grid_matches_its_runs_and_a_rerun(tmp_path) -> None:
    """No test plugins: the model_object tree with the free flyer, 2 worlds x 2 strategies x
    2 planners, 2 scans each. Every CSV row equals its run's metrics.json; the planner table
    carries the runs' real planning numbers; an ``explore run`` of one cell with the same seed
    gives the same coverage curve (same seeds, same results)."""
    out = tmp_path / "real"
    args = [str(EXPLORE), "compare", "--tree", "model_object", "--worlds", "bunny_pedestal,duck_pedestal",
            "--strategies", "ig_quality/bs_hr,random/sphere", "--planners", "straight_line,rrt_connect",
            "--seeds", "1", "--max-scans", "2", "--jobs", "2", "--out", str(out)]
    done = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    rows = csv_rows(out)
    assert len(rows) == 8 and {r["status"] for r in rows} == {"budget_exhausted"}  # 2 scans: the budget ends them
    assert {(r["world"], r["strategy"], r["planner"]) for r in rows} == {
        (w, s, p) for w in ("bunny_pedestal", "duck_pedestal") for s in ("ig_quality/bs_hr", "random/sphere")
        for p in ("straight_line", "rrt_connect")}
    for row in rows:
        metrics = json.loads((out / "runs" / row["run_id"] / "metrics.json").read_text())
        assert row["scans"] == metrics["scans"] == 2
        assert row["coverage_per_scan"] == pytest.approx(metrics["coverage_per_scan"], abs=1e-6)
        assert 0.2 < row["coverage_per_scan"][0] < row["coverage_per_scan"][1] <= 1.0  # real, rising coverage
        assert row["planning_success"] == pytest.approx(metrics["planning_success"])
        assert row["path_length_m"] == pytest.approx(metrics["path_length_m"]) and row["path_length_m"] > 0.0
    summary = json.loads((out / "summary.json").read_text())
    planners = {(v["world"], v["planner"]): v for v in summary["planners"]["rows"]}
    assert set(planners) == {(w, p) for w in ("bunny_pedestal", "duck_pedestal")
                             for p in ("straight_line", "rrt_connect")}
    for (world, planner), value in planners.items():
        group = [r for r in rows if r["world"] == world and r["planner"] == planner]
        assert value["runs"] == 2 and value["run_success"] == np.mean([r["status"] == "success" for r in group])
        assert value["planning_success"] == pytest.approx(np.mean([r["planning_success"] for r in group]))
    cell = next(r for r in rows if r["world"] == "duck_pedestal" and r["strategy"] == "ig_quality/bs_hr"
                and r["planner"] == "rrt_connect")
    again = subprocess.run([str(EXPLORE), "run", "model_object", "--world", "duck_pedestal", "--strategy",
                            "ig_quality/bs_hr", "--planner", "rrt_connect", "--seed", "0", "--max-scans", "2",
                            "--out", str(tmp_path / "again")], capture_output=True, text=True, timeout=300)
    assert again.returncode == 1, again.stdout + again.stderr  # the 2-scan budget ends it: not a success
    alone = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert alone["coverage_per_scan"] == pytest.approx(cell["coverage_per_scan"], abs=1e-6)
    assert alone["path_length_m"] == pytest.approx(cell["path_length_m"], abs=1e-6)


KNOWN_DUCK = """name: known_duck
environment:
  - {name: table, source: table/table.urdf, position: [0.0, 0.0, 0.3125]}
objects:
  - {name: duck, source: duck.obj, size: 0.10, rpy_deg: [90, 0, 0], position: [0.0, 0.0], on_top_of: table, known: true}
region: {min: [-0.2, -0.2, 0.625], max: [0.2, 0.2, 0.8]}
robot: {plugin: free_flyer}
sensor: {plugin: depth_camera, params: {width: 320, height: 240, min_range: 0.3, max_range: 2.0}}
overview: {eye: [0.0, -0.8, 1.3], target: [0.0, 0.0, 0.65]}
"""


def test_variants_are_named_settings_compared_like_strategies(tmp_path) -> None:
    """``--variant NAME: key=value; ...`` adds a dimension of named settings (Vasquez-Gomez's DU without noise
    beside DU-MU, a coarse beside a fine PVS): each variant's runs carry its settings over --set, its name in the
    run id and the variant column, and a row of their own in the summary's tables."""
    out = tmp_path / "variants"
    args = [str(EXPLORE), "compare", "--tree", "model_object", "--worlds", "bunny_pedestal", "--seeds", "1",
            "--max-scans", "2", "--jobs", "2", "--set", "strategy.termination_params={n_abort: 20}",
            "--variant", "coarse: resolution=0.01; start_modelling.noise=false", "--variant", "fine:",
            "--out", str(out)]
    done = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    rows = {r["variant"]: r for r in csv_rows(out)}
    assert set(rows) == {"coarse", "fine"}
    for name, row in rows.items():
        assert row["run_id"] == f"bunny_pedestal__default__default__default__{name}__seed000"
        metrics = json.loads((out / "runs" / row["run_id"] / "metrics.json").read_text())
        assert row["coverage"] == pytest.approx(metrics["coverage"]) and row["scans"] == 2
        given = {"strategy.termination_params": {"n_abort": 20}}
        if name == "coarse":
            given |= {"resolution": 0.01, "start_modelling.noise": False}
        assert metrics["settings"] == given
    summary = json.loads((out / "summary.json").read_text())
    assert [row["method"] for row in summary["vasquez"]["rows"]] == ["coarse", "fine"]


def test_scene_runs_of_a_grid_each_have_their_own_database(tmp_path, monkeypatch) -> None:
    """Two seeds of a scene tree at once: each run seeds and fills an object database in its own folder.
    They used to share the user's default ``runs/objects.db`` (in the folder compare was started from):
    each run saw the models the others had learned, in whatever order they ran, and two runs seeding
    the same known object at once crashed one of them ("an object of this name exists")."""
    from explore.perception import ObjectDatabase
    from explore.runtime import Grid, compare, make_registry

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("EXPLORE_DB", str(tmp_path / "mine.db"))
    world = tmp_path / "known_duck.yaml"
    world.write_text(KNOWN_DUCK)
    executor = make_registry().create("executor", "local", {"jobs": 2})
    rows = compare(Grid(tree="scene_exploration", worlds=[str(world)], seeds=[0, 1]), tmp_path / "out", executor)
    assert [r["status"] for r in rows] == ["success", "success"], [r["reason"] for r in rows]
    for row in rows:
        with ObjectDatabase.open(tmp_path / "out" / "runs" / row["run_id"] / "objects.db") as db:
            assert db.names() == ["duck"]
    assert not (tmp_path / "runs").exists() and not (tmp_path / "mine.db").exists()
