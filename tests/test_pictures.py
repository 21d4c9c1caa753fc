"""Pictures a person reads at a glance: whole-number scan axes, a legend on every plot, real planner names."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def figures(monkeypatch) -> list:
    """Every matplotlib figure saved during the test (still written to its file)."""
    from matplotlib.figure import Figure

    saved, save = [], Figure.savefig

    def record(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        saved.append(self)
        return save(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return saved


def _whole_ticks(axis) -> bool:  # noqa: ANN001
    ticks = [t for t in axis.get_majorticklocs() if axis.get_view_interval()[0] <= t <= axis.get_view_interval()[1]]
    return bool(ticks) and all(float(t).is_integer() for t in ticks)


def test_coverage_curve_has_whole_scans_and_a_legend(figures, tmp_path) -> None:
    from explore.core import save_curves_png

    save_curves_png({"c_a (ground truth)": (np.arange(1, 4), np.array([0.4, 0.7, 0.8]))}, tmp_path / "c.png",
                    "scans", "coverage")
    (ax,) = figures[0].axes
    assert _whole_ticks(ax.xaxis) and ax.get_legend() is not None


def test_report_plots_have_whole_scans_legends_and_the_planner_used(figures, tmp_path) -> None:
    from explore.runtime.report_plots import plot_coverage, plot_planners, plot_scans
    from explore.runtime.report_tables import planner_table

    rows = [
        {"run_id": f"r{s}{seed}", "world": "bunny_pedestal", "strategy": s, "planner": "default",
         "planner_used": "rrt_connect", "robot": "default", "seed": seed, "status": "success", "scans": 2 + seed,
         "coverage_per_scan": [0.3, 0.6, 0.8][: 2 + seed], "planning_success": 1.0, "planning_time_s": 0.1,
         "path_length_m": 1.0}
        for s in ("ig_quality/bs_hr", "random/random") for seed in (0, 1)
    ]
    plot_coverage(rows, 3, tmp_path / "coverage.png")
    plot_scans(rows, tmp_path / "scans.png")
    table = planner_table(rows)
    assert [v["planner"] for v in table.values] == ["rrt_connect (default)"]
    plot_planners(table, tmp_path / "planners.png")
    coverage, scans, planners = figures
    assert _whole_ticks(coverage.axes[0].xaxis) and coverage.axes[0].get_legend() is not None
    assert _whole_ticks(scans.axes[0].yaxis)
    for ax in planners.axes:
        assert ax.get_legend() is not None
        assert "rrt_connect (default)" in ax.get_xticklabels()[0].get_text()


def test_nbvs_trajectories_have_a_legend(figures, open_world, registry, tmp_path) -> None:
    from explore.nbv import NBVSSession

    with open_world("cluttered") as sim:
        session = NBVSSession(sim, registry, expected=False, n_samples=2000, seed=0, max_views=1, top=4, noise=False)
        session.run()
        session.save_trajectories_png(tmp_path / "trajectories.png")
    labels = [t.get_text() for t in figures[-1].axes[0].get_legend().get_texts()]
    assert {"known environment", "object", "region", "executed motion", "scan (number)", "collision"} <= set(labels)


def test_point_cloud_picture_has_a_colour_key(figures, tmp_path) -> None:
    from explore.core import save_points_png

    save_points_png(np.random.default_rng(0).random((500, 3)), tmp_path / "scan.png")
    assert [ax.get_ylabel() for ax in figures[0].axes][1:] == ["height z [m]"]
