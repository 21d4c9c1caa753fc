"""Vasquez-Gomez Fig. 11 from NBVS runs (benchmarks/collision_vs_k.py): the collision rate per executed
move of each (executor, approach, k), a PNG, and one line with exit 2 for a bad runs file."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from collision_vs_k import main, read_runs, rows_of  # noqa: E402

pytestmark = pytest.mark.timeout(120)


def _run(approach: str, k: int, seed: int, collisions: int, moves: int, coverage: float, relocalise: bool) -> dict:
    return {"world": "cluttered", "approach": approach, "k": k, "seed": seed, "collisions": collisions,
            "trajectories": moves, "final_coverage": coverage, "views": moves + 1, "relocalise": relocalise}


def test_collision_rate_is_collisions_over_executed_moves_per_executor_approach_and_k(tmp_path: Path) -> None:
    runs = [_run("DU-MU", 1, 0, 1, 4, 0.4, False), _run("DU-MU", 1, 1, 1, 2, 0.5, False),
            _run("EU-MU", 1, 0, 1, 5, 0.3, False), _run("EU-MU", 1, 1, 0, 3, 0.5, False),
            _run("EU-MU", 500, 0, 0, 3, 0.35, False), _run("EU-MU", 500, 0, 0, 12, 0.8, True)]
    path = tmp_path / "runs.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in runs) + "\n", encoding="utf-8")
    rows = {(r["executor"], r["approach"], r["k"]): r for r in rows_of(read_runs([str(path)]))}
    assert set(rows) == {("open loop", "DU-MU", None), ("open loop", "EU-MU", 1), ("open loop", "EU-MU", 500),
                         ("re-localising", "EU-MU", 500)}
    du = rows[("open loop", "DU-MU", None)]
    assert du["collision_rate"] == pytest.approx(2 / 6) and du["runs_with_collision"] == 1.0
    eu1 = rows[("open loop", "EU-MU", 1)]
    assert eu1["collision_rate"] == pytest.approx(1 / 8) and eu1["mean_coverage"] == pytest.approx(0.4)
    assert rows[("re-localising", "EU-MU", 500)]["mean_views"] == 13
    png = tmp_path / "fig11.png"
    assert main([str(path), "--plot", str(png)]) == 0 and png.stat().st_size > 10_000


@pytest.mark.parametrize("content, says", [("{not json\n", "runs.jsonl:1: not a JSON line"),
                                           ('{"approach": "DU"}\n', "runs.jsonl:1: no k, collisions"),
                                           ("\n", "no runs")])
def test_a_bad_runs_file_gets_one_line_and_exit_2(tmp_path: Path, capsys, content: str, says: str) -> None:
    path = tmp_path / "runs.jsonl"
    path.write_text(content, encoding="utf-8")
    assert main([str(path)]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
    assert main([str(tmp_path / "missing.jsonl")]) == 2
    assert "missing.jsonl: cannot read" in capsys.readouterr().err


def test_runs_of_different_settings_are_not_mixed_in_one_figure(tmp_path: Path, capsys) -> None:
    budget_only = {**_run("EU-MU", 500, 0, 0, 12, 0.9, True), "min_unknown": 0}
    with_stop = _run("EU-MU", 500, 1, 0, 8, 0.8, True)  # an older record: the session's 30
    path = tmp_path / "runs.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in (budget_only, with_stop)) + "\n", encoding="utf-8")
    assert main([str(path)]) == 2
    err = capsys.readouterr().err
    assert "different min_unknown (0, 30)" in err and len(err.strip().splitlines()) == 1
