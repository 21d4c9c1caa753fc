"""Many runs at once: an ``explore compare`` grid through the Ray executor on a local
multi-process Ray cluster, killed half way and resumed, against the same grid run locally
(issue 23, item 5).

It starts a Ray head (2 CPUs, token authentication as a real cluster would have), runs the grid
with ``--executor ray``, kills the driver with SIGKILL once ``--kill-after`` runs are in
``results.csv``, resumes it with the same command, then runs the grid with the local executor
into another folder and compares: every row of ``results.csv`` (wall-clock columns aside) and
``summary.md`` (its timing columns aside). Prints a JSON report.

    .venv/bin/python benchmarks/ray_grid.py --seeds 17 --out /tmp/ray_grid   # 3 worlds x 4 strategies x 17 = 204 runs
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

EXPLORE = Path(sys.executable).parent / "explore"
RAY = Path(sys.executable).parent / "ray"
TIMING = ("elapsed_s", "wall_s", "selection_s_mean", "selection_s_per_scan", "planning_time_s", "planning_time_s_total")
WORLDS = "bunny_pedestal,duck_pedestal,teddy_pedestal"
STRATEGIES = "ig_quality/bs_hr,ig_quality/sphere,ig/bs,random/bs_hr"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def grid(out: Path, seeds: int, max_scans: int, *extra: str) -> list[str]:
    return [str(EXPLORE), "compare", "--tree", "model_object", "--worlds", WORLDS, "--strategies", STRATEGIES,
            "--seeds", str(seeds), "--max-scans", str(max_scans), "--jobs", "2", "--out", str(out), *extra]


def rows(out: Path) -> list[dict]:
    from explore.runtime import read_results

    path = out / "results.csv"
    return [{k: v for k, v in r.items() if k not in TIMING} for r in read_results(path)] if path.exists() else []


def summary_without_timing(out: Path) -> str:
    """summary.md without its wall-clock numbers: the columns whose header says "/ s" blanked,
    the "Time per step" table left out."""
    lines: list[str] = []
    timed: list[int] = []
    section = ""
    for line in (out / "summary.md").read_text().splitlines():
        if line.startswith("#"):
            section = line
        cells = line.split("|")
        if not line.startswith("|"):
            timed = []
        elif not timed:  # a table's header line
            timed = [i for i, c in enumerate(cells) if "/ s" in c] or [-1]
        if line.startswith("|") and "Time per step" in section:
            continue  # even its columns depend on the clock (a composite step whose child ends at its tick)
        lines.append("|".join("" if i in timed else c for i, c in enumerate(cells)))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=17, help="seeds per world x strategy (3 x 4 x 17 = 204 runs)")
    parser.add_argument("--max-scans", type=int, default=2)
    parser.add_argument("--kill-after", type=int, default=0, help="runs done before the kill (default: half)")
    parser.add_argument("--out", type=Path, default=None, help="results folder (default: a new temporary one)")
    args = parser.parse_args(argv)
    args.out = args.out or Path(tempfile.mkdtemp(prefix="ray_grid_"))
    total = 12 * args.seeds
    kill_after = args.kill_after or total // 2
    if args.out.exists() and any(args.out.iterdir()):
        parser.error(f"--out: {args.out} is not empty (the grid would resume an earlier one)")
    args.out.mkdir(parents=True, exist_ok=True)
    ray_out, local_out = args.out / "ray", args.out / "local"
    report: dict = {"runs": total, "worlds": WORLDS, "strategies": STRATEGIES, "seeds": args.seeds,
                    "max_scans": args.max_scans}

    port = free_port()
    ray_tmp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay short
    token = args.out / "ray_token"
    token.write_text(secrets.token_hex(32))
    head = subprocess.Popen(
        [str(RAY), "start", "--head", "--block", f"--port={port}", "--node-ip-address=127.0.0.1", "--num-cpus=2",
         "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={ray_tmp}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, start_new_session=True,
        env={**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token)},
    )
    driver_env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    command = grid(ray_out, args.seeds, args.max_scans, "--executor", "ray", "--ray-address", f"127.0.0.1:{port}",
                   "--ray-token-file", str(token))
    try:
        time.sleep(8)  # the head accepts drivers after a few seconds
        start = time.perf_counter()
        driver = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=driver_env,
                                  start_new_session=True)
        while driver.poll() is None and len(rows(ray_out)) < kill_after:
            time.sleep(1.0)
        done_before = len(rows(ray_out))
        os.killpg(driver.pid, signal.SIGKILL)
        driver.wait()
        report["killed_after_runs"] = done_before
        resumed = subprocess.run(command, capture_output=True, text=True, env=driver_env)
        report["ray_s"] = round(time.perf_counter() - start, 1)
        report["ray_exit"] = resumed.returncode
        if resumed.returncode not in (0, 1):
            report["ray_error"] = resumed.stderr[-2000:]
    finally:
        os.killpg(head.pid, signal.SIGKILL)
        head.wait()
        shutil.rmtree(ray_tmp, ignore_errors=True)
    start = time.perf_counter()
    local = subprocess.run(grid(local_out, args.seeds, args.max_scans), capture_output=True, text=True)
    report["local_s"] = round(time.perf_counter() - start, 1)
    report["local_exit"] = local.returncode
    ray_rows, local_rows = rows(ray_out), rows(local_out)
    key = ("world", "strategy", "seed")
    report["ray_rows"], report["local_rows"] = len(ray_rows), len(local_rows)
    ordered = [sorted(r, key=lambda row: tuple(str(row.get(k)) for k in key)) for r in (ray_rows, local_rows)]
    report["results_identical"] = ordered[0] == ordered[1]
    report["summary_identical"] = summary_without_timing(ray_out) == summary_without_timing(local_out)
    print(json.dumps(report, indent=1))
    return 0 if report["results_identical"] and report["summary_identical"] and len(ray_rows) == total else 1


if __name__ == "__main__":
    raise SystemExit(main())
