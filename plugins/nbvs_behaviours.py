"""Behaviours of the Vasquez-Gomez view/state loop (``trees/nbvs_mobile.yaml``).

One behaviour per step of Sec. A2/A8 of the digest: start the session, take the first
state, sample states, run the filter pipeline, plan, score with the deterministic or the
expected utility (Algorithm 1), select, execute the controls with positioning noise,
acquire, integrate, check termination. Each is a thin adapter over
:class:`explore.nbv.nbvs.NBVSSession`, kept in ``context.state["nbvs"]`` inside a
:class:`TreeNBVS`, which also records what the metrics need (``live_stats``,
``run_outputs``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import Param, save_curves_png, save_points_png
from explore.nbv import AreaFactor, NBVSSession, ViewRecord
from explore.runtime import ExploreBehaviour, Outcome, failure, object_result, success


class TreeNBVS:
    """An :class:`~explore.nbv.nbvs.NBVSSession` driven step by step by a tree (records as ``step()``)."""

    def __init__(self, session: Any, strategy: str) -> None:
        self.session = session
        self.strategy = strategy
        self.stage_s: dict[str, float] = {}
        self.selection_s: list[float] = []
        self._since = 0
        self._pending: Any = None  # the record of the move whose scan is not integrated yet
        self._states: list[Any] = []

    @property
    def end_reason(self) -> str:
        """Why the run ended (the run's reason when the tree succeeds)."""
        return str(self.session.reason)

    @property
    def end_outcome(self) -> str:
        """How the run ended (:mod:`explore.core.outcomes`; the run's status when the tree succeeds)."""
        return self.session.outcome

    # -- steps -------------------------------------------------------------------------------
    def _timed(self, stage: str, fn: Any, *args: Any) -> Any:
        t0 = time.perf_counter()
        out = fn(*args)
        self.stage_s[stage] = self.stage_s.get(stage, 0.0) + time.perf_counter() - t0
        return out

    def first_view(self) -> np.ndarray:
        return self.session.first_view()

    def sample(self) -> list[Any]:
        self._since = len(self.session.plan_log)
        self.stage_s = {}
        self._states = []
        return self._timed("sample", self.session.sample)

    def filter(self, states: list[Any]) -> list[Any]:
        return self._timed("filter", self.session.filter, states)

    def plan(self, states: list[Any]) -> list[Any]:
        return self._timed("plan", self.session.plan, states)

    def score(self, states: list[Any]) -> list[Any]:
        scored = self._timed("score", self.session.score, states)
        self._states += scored
        return scored

    def select(self) -> tuple[Any, list[Any]]:
        """The best candidate scored this iteration, else (None, the next round's candidates);
        (None, []) stops the run (no view/state left)."""
        best = self.session.select(self._states)
        if best is not None:
            self.selection_s.append(sum(self.stage_s.values()))
            return best, []
        more = self.session.next_round()
        if not more:
            self.selection_s.append(sum(self.stage_s.values()))
            self.session.no_candidate()
        return None, more

    def execute(self, best: Any) -> Any:
        """Run the controls with noise; the record waits for its scan (unless the run collided)."""
        t0 = time.perf_counter()
        run, record = self.session.move(best, self._states, self._since)
        self.stage_s["execute"] = time.perf_counter() - t0
        record.seconds = dict(self.stage_s)
        if self.session.status == "running":
            self._pending = record
        else:
            self.session.records.append(record)
        return run

    def acquire(self, pose: np.ndarray) -> Any:
        return self.session.acquire(pose)

    def integrate(self, scan: Any) -> Any:
        record = self._pending or ViewRecord(0, {}, 0.0, 0.0, float("nan"), None, 1.0, 0.0, 0, False, [])
        self._pending = None
        self.session.integrate(scan, record)
        self.session.records.append(record)
        return record

    def finished(self) -> bool:
        return self.session.finished()

    # -- metrics -----------------------------------------------------------------------------
    def live_stats(self) -> dict[str, Any]:
        s = self.session
        stats: dict[str, Any] = {"strategy": self.strategy, "scans": len(s.records)}
        if s.records:
            stats["coverage"] = float(s.records[-1].coverage)
        stats["collisions"] = sum(1 for r in s.records[1:] if r.collided)
        return stats

    def run_outputs(self, out_dir: Any) -> dict[str, Any]:
        """PVS, measured points, coverage and trajectory pictures; the NBVS metrics."""
        out_dir = Path(out_dir)
        s = self.session
        summary = s.summary()
        s.pvs.save(out_dir / "pvs.npz")
        s.pvs.save_octomap(out_dir / "pvs.bt")
        points = np.vstack(s.points) if s.points else np.zeros((0, 3))
        if len(points):
            import open3d as o3d

            o3d.io.write_point_cloud(str(out_dir / "points.ply"),
                                     o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)))
            save_points_png(points, out_dir / "points.png", f"{s.sim.spec.name}: {len(s.records)} scans")
        coverage = [float(c) for c in summary["coverage"]]
        if coverage:
            x = np.arange(1, len(coverage) + 1)
            save_curves_png({"c_a (ground truth)": (x, np.asarray(coverage))}, out_dir / "coverage.png", "scans",
                            "coverage", self.strategy)
        s.save_trajectories_png(out_dir / "trajectories.png", f"{self.strategy}, seed {s.seed}")
        moves = s.records[1:]
        lengths = [float(r.path_length) for r in moves]
        times = [t for t, _ in s.plan_log]
        return {
            "strategy": self.strategy,
            "expected_utility": s.expected,
            "k": s.k if s.expected else None,
            "weighting": s.weighting if s.expected else None,
            "planner_used": s.planner_name,
            "scans": len(s.records),
            "coverage": coverage[-1] if coverage else None,
            "coverage_per_scan": coverage,
            "trajectories": len(moves),
            "collisions": summary["collisions"],
            "collision_rate": summary["collision_rate"],
            "collided_with": [list(r.collisions[0]) for r in moves if r.collided],
            "path_length": float(sum(lengths)),
            "path_length_per_move": lengths,
            "path_length_unit": "Vasquez-Gomez Eq. 8 (weighted configuration distance)",
            "path_length_m": s.travelled_m(),
            "planning": {
                "queries": len(times),
                "success_rate": summary["plan_success_rate"],
                "median_s": float(np.median(times)) if times else None,
                "total_s": float(sum(times)),
            },
            "ess_per_move": summary["ess"],
            "stages_per_move": summary["stages"],
            "relocalise": s.relocalise,
            "leg_length": s.leg_length if s.relocalise else None,
            "selection_s_mean": float(np.mean(self.selection_s)) if self.selection_s else None,
            "selection_s_median": float(np.median(self.selection_s)) if self.selection_s else None,
            "selection_s_per_scan": self.selection_s,
            "stage_s_per_move": [{k: round(float(v), 3) for k, v in r.seconds.items()} for r in moves],
            "stop_reason": s.reason or s.status,
            "objects": [{"name": b.name, "coverage": coverage[-1] if coverage else None,
                         "result": object_result(coverage[-1] if coverage else None)}
                        for b in s.sim.objects()],
        }


def _session(behaviour: ExploreBehaviour) -> TreeNBVS:
    return behaviour.need("nbvs")


class StartNBVS(ExploreBehaviour):
    """Start Vasquez-Gomez view/state planning: PVS over the region, DU or EU from the strategy."""

    name = "start_nbvs"
    writes = ("nbvs", "done", "reason")
    params = (
        Param("strategy", str, "vasquez/eu", "", "vasquez/eu (expected utility) or vasquez/du; any strategy's "
              "utility is the view part (overridden by --strategy)"),
        Param("n_samples", int, 10000, "", "sampled states whose director ray hits the region", low=1),
        Param("top", int, 25, "", "candidates kept for motion planning", low=1),
        Param("overlap", float, 0.5, "", "registration threshold h (Eq. 5)", low=0.0, high=1.0),
        Param("min_unknown", int, 30, "", "unknown voxels a candidate must see", low=0),
        Param("resolution", float, 0.01, "m", "PVS voxel edge length", low=1e-4),
        Param("max_views", int, 12, "", "planned views after the first scan (--max-scans N: N - 1)", low=1),
        Param("noise", bool, True, "", "execute with the robot's positioning noise"),
        Param("stop_on_collision", bool, True, "", "a collision ends the run (the paper's runs do)"),
        Param("planner_time_limit", float, 3.0, "s", "time limit of each planning query", low=0.01),
        Param("beam_stride", int, 8, "", "every n-th camera beam is simulated for visibility", low=1),
        Param("weighting", str, "mean", "", "EU weights: the sample mean, or Algorithm 1's probability weights "
              "(which count each sample's probability twice)", choices=("mean", "probability")),
        Param("relocalise", bool, True, "", "execute and roll out each motion re-localising at its waypoints and "
              "steering back onto it (false: open loop, as in the paper)"),
        Param("leg_length", float, 0.25, "m", "with relocalise, a drive is also re-aimed every this many metres "
              "(0: only at the waypoints)", low=0.0),
    )

    def work(self) -> Outcome:
        ctx = self.context
        config = ctx.config
        name = config.strategy or self.p["strategy"]
        strategy = ctx.registry.create("strategy", name, config.scoped("strategy"), "--strategy", "strategy").strategy
        expected = strategy.utility == "expected_utility"
        params = dict(strategy.utility_params)
        utility = str(params.pop("base", AreaFactor.name)) if expected else strategy.utility
        k = int(params.pop("k", 100)) if expected else 1
        session = NBVSSession(
            ctx.sim, ctx.registry, utility=utility, expected=expected, k=k, seed=config.seed,
            n_samples=self.p["n_samples"], top=self.p["top"], overlap=self.p["overlap"],
            min_unknown=self.p["min_unknown"], resolution=float(config.setting("resolution", self.p["resolution"])),
            max_views=max(0, config.max_scans - 1) if config.max_scans else self.p["max_views"],
            noise=self.p["noise"],
            stop_on_collision=self.p["stop_on_collision"], beam_stride=self.p["beam_stride"],
            planner=config.planner,
            planner_params={"time_limit": self.p["planner_time_limit"], **config.scoped("planner")},
            utility_params={} if expected or utility == AreaFactor.name else params,
            weighting=self.p["weighting"], relocalise=self.p["relocalise"], leg_length=self.p["leg_length"],
        )
        session.progress = ctx.progress
        adapter = TreeNBVS(session, name)
        ctx.state["nbvs"] = adapter
        self.write("nbvs", adapter)
        self.write("done", False)
        self.write("reason", "")
        ctx.trace("decision", what="strategy", strategy=name, expected=expected, k=k, utility=utility,
                  planner=session.planner_name)
        return success(f"{name}: {'EU k=' + str(k) if expected else 'DU'}, planner {session.planner_name}")


class NBVSFirstState(ExploreBehaviour):
    """Take the first, exactly known state (no motion; Vasquez-Gomez Sec. A2 step 1)."""

    name = "nbvs_first_state"
    reads = ("nbvs",)
    writes = ("pose",)
    blocking = True

    def work(self) -> Outcome:
        nbvs = _session(self)
        pose = nbvs.first_view()
        if nbvs.session.status == "failed":
            return failure(nbvs.session.reason)
        self.write("pose", pose)
        return success(f"sensor at {np.round(pose[:3, 3], 3).tolist()}")


class NBVSSampleStates(ExploreBehaviour):
    """Sample states uniformly until enough aim the director ray at the region (Sec. A8.1)."""

    name = "nbvs_sample_states"
    reads = ("nbvs",)
    writes = ("states",)
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        states = session.sample()
        self.write("states", states)
        stages = session.session.stages
        return success(f"{stages['ray_hits']} of {stages['sampled']} draws aim at the region")


class NBVSFilter(ExploreBehaviour):
    """Filter pipeline: collision, visibility, registration overlap h, surface, top n (Sec. A8.2-7)."""

    name = "nbvs_filter"
    reads = ("nbvs", "states")
    writes = ("states", "chosen")
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        states = session.filter(self.need("states"))
        self.write("states", states)
        self.write("chosen", False)
        stages = session.session.stages
        self.context.trace("decision", what="filter", **{k: int(v) for k, v in stages.items()})
        return success(" -> ".join(f"{k} {v}" for k, v in stages.items()))


class NBVSPlan(ExploreBehaviour):
    """Plan a motion from the current state to each candidate (pos of Eq. 4, dist of Eq. 7)."""

    name = "nbvs_plan"
    reads = ("nbvs", "states")
    writes = ("states",)
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        states = self.need("states")
        planned = session.plan(states)
        self.write("states", planned)
        return success(f"{len(planned)} of {len(states)} planned")  # the time is in the metrics (stage times)


class NBVSScore(ExploreBehaviour):
    """Deterministic utility g (Eq. 4) or expected utility (Algorithm 1, k noisy rollouts)."""

    name = "nbvs_score"
    reads = ("nbvs", "states")
    writes = ("states",)
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        states = session.score(self.need("states"))
        self.write("states", states)
        feasible = sum(1 for s in states if s.score > 0)
        return success(f"{feasible} of {len(states)} feasible")


class NBVSSelect(ExploreBehaviour):
    """argmax of the (expected) utility; if none is feasible, the next round of candidates;
    when nothing is left the run is done (with the stage that emptied)."""

    name = "nbvs_select"
    reads = ("nbvs",)
    writes = ("candidate", "chosen", "states", "done", "reason")

    def work(self) -> Outcome:
        session = _session(self)
        best, more = session.select()
        self.write("candidate", best)
        if best is None and more:
            self.write("states", more)
            self.write("chosen", False)
            return success(f"none feasible: {len(more)} more candidates")
        self.write("chosen", True)
        if best is None:
            self.write("done", True)
            self.write("reason", session.session.reason)
            self.context.trace("decision", what="select", result="none", reason=session.session.reason)
            return success(session.session.reason)
        info = {"score": float(best.score), "deterministic": float(best.deterministic), "path_length": best.length,
                "margin": best.margin}
        if best.expected is not None:
            info["ess"] = float(best.expected.ess)
        self.context.trace("decision", what="select", **info)
        return success(f"score {best.score:.4g}")


class NBVSExecute(ExploreBehaviour):
    """Execute the controls with positioning noise, checked against the TRUE world."""

    name = "nbvs_execute"
    reads = ("nbvs", "candidate")
    writes = ("pose",)
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        run = session.execute(self.need("candidate"))
        self.context.trace("motion", steps=len(run.controls), collided=run.collided,
                           bodies=[list(e.bodies) for e in run.collisions])
        if run.collided and session.session.status == "collided":  # the mission fails, as the paper counts it
            return failure(session.session.reason)
        self.write("pose", run.sensor_pose)
        return success(f"{len(run.controls)} control steps" + (" (collided, continuing)" if run.collided else ""))


class NBVSAcquire(ExploreBehaviour):
    """Scan at the executed sensor pose."""

    name = "nbvs_acquire"
    reads = ("nbvs", "pose")
    writes = ("scan",)
    blocking = True

    def work(self) -> Outcome:
        scan = _session(self).acquire(self.need("pose"))
        self.write("scan", scan)
        hits = int(scan.hits.sum())
        self.context.trace("scan", index=len(_session(self).session.records) + 1, beams=len(scan), returns=hits)
        return success(f"{hits} returns")


class NBVSIntegrate(ExploreBehaviour):
    """Integrate the scan into the PVS (OctoMap-style Bayes update) and measure coverage."""

    name = "nbvs_integrate"
    reads = ("nbvs", "scan")
    blocking = True

    def work(self) -> Outcome:
        session = _session(self)
        record = session.integrate(self.need("scan"))
        line = "  ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                         for k, v in session.live_stats().items())
        self.context.status_line = line
        self.context.trace("integrated", index=record.index, coverage=float(record.coverage),
                           unknown_voxels=int(record.unknown_voxels))
        return success(line)


class NBVSCheckTermination(ExploreBehaviour):
    """Stop after ``max_views`` planned views (the paper's simulation runs: 12)."""

    name = "nbvs_check_termination"
    reads = ("nbvs", "done")
    writes = ("done", "reason")

    def work(self) -> Outcome:
        if self.read("done"):
            return success(self.read("reason") or "done")
        session = _session(self)
        if session.finished():
            self.write("done", True)
            self.write("reason", session.session.reason)
            self.context.trace("decision", what="termination", action="stop", reason=session.session.reason)
            return success(f"stop: {session.session.reason}")
        return success("continue")


PLUGINS = [
    StartNBVS,
    NBVSFirstState,
    NBVSSampleStates,
    NBVSFilter,
    NBVSPlan,
    NBVSScore,
    NBVSSelect,
    NBVSExecute,
    NBVSAcquire,
    NBVSIntegrate,
    NBVSCheckTermination,
]
