"""Behaviour plugins: one per step of the seeds' loops, thin adapters over the library.

Each declares the blackboard keys it reads and writes (in the run's namespace). Steps that
take long (scanning, integrating, planning, moving) are ``blocking``: they run in the run's
worker thread while the tree keeps ticking.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.bt_behaviour import ExploreBehaviour, Outcome, failure, success
from explore.params import Param


class StartModelling(ExploreBehaviour):
    """Start single-object modelling: PVS, surface model and strategy over the world's region."""

    name = "start_modelling"
    writes = ("modelling", "target", "done", "reason")
    params = (
        Param("strategy", str, "ig_quality/bs_hr", "", "NBV strategy (overridden by --strategy)"),
        Param("resolution", float, 0.005, "m", "PVS voxel edge length", low=1e-4),
        Param("max_scans", int, 30, "", "scan budget (overridden by --max-scans)", low=1),
    )

    def work(self) -> Outcome:
        from explore.modelling import ModellingSession

        ctx = self.context
        config = ctx.config
        strategy_name = config.strategy or self.p["strategy"]
        strategy = ctx.registry.create(
            "strategy", strategy_name, config.scoped("strategy"), "--strategy", "strategy"
        )
        session = ModellingSession(
            ctx.sim,
            strategy,
            ctx.registry,
            seed=config.seed,
            resolution=float(config.setting("resolution", self.p["resolution"])),
            max_scans=config.max_scans or self.p["max_scans"],
            planner=config.planner,
        )
        adapter = TreeModelling(session, strategy_name)
        ctx.state["modelling"] = adapter
        session = adapter
        self.write("modelling", adapter)
        self.write("target", session.initial_target())
        self.write("done", False)
        self.write("reason", "")
        ctx.trace("decision", what="strategy", strategy=strategy_name)
        return success(f"strategy {strategy_name}")


class AcquireScan(ExploreBehaviour):
    """Take a scan at the current target (a view or a scan path) with the world's sensor."""

    name = "acquire_scan"
    reads = ("modelling", "target")
    writes = ("scan",)
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        scan = session.acquire(self.read("target"))
        self.write("scan", scan)
        hits = int(scan.hits.sum())
        self.context.trace("scan", index=session.n_scans + 1, beams=len(scan), returns=hits)
        return success(f"{hits} returns")


class IntegrateScan(ExploreBehaviour):
    """Integrate the last scan into the PVS and the surface model (and its features)."""

    name = "integrate_scan"
    reads = ("modelling", "scan")
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        stats = session.integrate(self.read("scan"))
        record = session.session.records[-1] if session.session.records else None
        line = session_status_line(session)
        self.context.status_line = line
        self.context.trace("integrated", **({} if record is None else _record_fields(record)), stats=stats)
        return success(line)


class GenerateCandidates(ExploreBehaviour):
    """Generate NBV/NBS candidates with the strategy's view generator onto the candidate stack."""

    name = "generate_candidates"
    reads = ("modelling",)
    blocking = True

    def work(self) -> Outcome:
        count = self.read("modelling").generate()
        return success(f"{count} candidates")


class SelectNBV(ExploreBehaviour):
    """Score the candidates with the strategy's utility and pick the best one."""

    name = "select_nbv"
    reads = ("modelling",)
    writes = ("candidate", "done", "reason")
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        candidate = session.select()
        self.write("candidate", candidate)
        if candidate is None:
            self.write("done", True)
            self.write("reason", "no candidate left")
            self.context.trace("decision", what="select", result="none left")
            return success("no candidate left")
        self.context.trace("decision", what="select", score=float(candidate.score), source=candidate.source)
        return success(f"score {candidate.score:.4g}")


class CheckTermination(ExploreBehaviour):
    """Ask the strategy's termination rule: continue, switch mode, or stop (with the reason)."""

    name = "check_termination"
    reads = ("modelling", "done", "reason")
    writes = ("done", "reason")

    def work(self) -> Outcome:
        if self.read("done"):
            return success(self.read("reason") or "done")
        decision = self.read("modelling").terminate()
        action = getattr(decision, "action", "continue")
        reason = getattr(decision, "reason", "")
        self.context.trace("decision", what="termination", action=action, reason=reason)
        if action == "stop":
            self.write("done", True)
            self.write("reason", reason)
        return success(f"{action}: {reason}" if reason else action)


class CheckFlag(ExploreBehaviour):
    """Condition: succeed when a blackboard flag has the expected value, fail otherwise."""

    name = "check_flag"
    is_condition = True
    params = (
        Param("key", str, "done", "", "blackboard key (in the run's namespace)"),
        Param("expect", bool, True, "", "value that makes the condition succeed"),
    )

    def setup(self, **kwargs: Any) -> None:
        self.reads = (self.p["key"],)
        super().setup(**kwargs)

    def work(self) -> Outcome:
        value = bool(self.read(self.p["key"], False))
        if value == self.p["expect"]:
            return success(f"{self.p['key']} is {value}")
        return failure(f"{self.p['key']} is {value}")


class PlanMotion(ExploreBehaviour):
    """Plan a collision-free motion to the selected candidate (known environment + PVS)."""

    name = "plan_motion"
    reads = ("modelling", "candidate")
    writes = ("plan",)
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        plan = session.plan(self.read("candidate"))
        self.write("plan", plan)
        if plan is None:
            return failure("no collision-free motion to the candidate")
        return success(f"{getattr(plan, 'length', 0.0):.3f} m")


class ExecuteMotion(ExploreBehaviour):
    """Execute the planned motion (with the robot's positioning noise); the next target results."""

    name = "execute_motion"
    reads = ("modelling", "plan", "candidate")
    writes = ("target",)
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        target = session.execute(self.read("plan"), self.read("candidate"))
        if target is None:
            return failure("the motion ended in a collision")
        self.write("target", target)
        return success()


def session_status_line(session: Any) -> str:
    stats = session.live_stats() if hasattr(session, "live_stats") else {}
    return "  ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in stats.items())


def _record_fields(record: Any) -> dict[str, Any]:
    fields = getattr(record, "__dict__", {})
    return {k: v for k, v in fields.items() if isinstance(v, int | float | str | bool | np.floating | np.integer)}


class TreeModelling:
    """The modelling session driven step by step by a tree (records what ``step()`` records)."""

    def __init__(self, session: Any, strategy: str) -> None:
        self.session = session
        self.strategy = strategy
        self._pending: dict[str, Any] = {"source": "initial", "info": {}, "score": float("nan")}
        self._selection_s = 0.0
        self._candidates = 0
        self._decision = ("continue", "")
        self._path_length = 0.0

    @property
    def n_scans(self) -> int:
        return self.session.n_scans

    def initial_target(self) -> Any:
        return self.session.initial_target()

    def acquire(self, target: Any) -> Any:
        import time

        self._t0 = time.perf_counter()
        scan, scan_length, travel = self.session.acquire(target)
        self._scan_length, self._travel = scan_length, travel
        return scan

    def integrate(self, scan: Any) -> dict[str, Any]:
        import time

        from explore.modelling import ScanRecord

        out = self.session.integrate(scan)
        s = self.session
        s.records.append(
            ScanRecord(
                index=s.n_scans, source=self._pending["source"], info=dict(self._pending["info"]),
                scan_length_m=self._scan_length, travel_m=self._travel, selection_s=self._selection_s,
                candidates=self._candidates, coverage_estimate=s.ctx.coverage_history[-1],
                coverage_border=float(s.surface.coverage_border()), density=s.ctx.density_history[-1],
                unknown_voxels=s.ctx.unknown_history[-1], decision=self._decision[0], reason=self._decision[1],
                score=self._pending["score"], step_s=time.perf_counter() - getattr(self, "_t0", time.perf_counter()),
            )
        )
        return {"integrate_s": out.get("integrate_s", 0.0)}

    def generate(self) -> int:
        count = self.session.generate()
        self._candidates = len(self.session.stack)
        return count

    def select(self) -> Any:
        candidate = self.session.select()
        self._selection_s = self.session.selection_times[-1] if candidate is not None else 0.0
        if candidate is not None:
            self._pending = {"source": candidate.source, "info": candidate.info, "score": candidate.score}
        return candidate

    def terminate(self) -> Any:
        decision = self.session.terminate()
        self._decision = (decision.action, decision.reason)
        if decision.stop:
            self.session.status, self.session.reason = "stopped", decision.reason
        return decision

    def plan(self, candidate: Any) -> Any:
        """Free flyer: a straight line to the candidate's start (others: reachability by IK)."""
        from explore.scan import ScanPath

        start = candidate.target.start if isinstance(candidate.target, ScanPath) else candidate.target
        robot = self.session.robot
        if robot is not None and robot.name != "free_flyer" and robot.ik(start) is None:
            return None
        here = self.session.ctx.sensor_pose
        length = 0.0 if here is None else float(np.linalg.norm(start[:3, 3] - here[:3, 3]))
        return _Plan(length)

    def execute(self, plan: Any, candidate: Any) -> Any:
        return candidate.target

    def live_stats(self) -> dict[str, Any]:
        s = self.session
        stats: dict[str, Any] = {"strategy": self.strategy, "scans": s.n_scans}
        if s.records:
            stats["ĉ_m"] = float(s.records[-1].coverage_estimate)
            stats["candidates"] = int(self._candidates)
        return stats

    def run_outputs(self, out_dir: Any) -> dict[str, Any]:
        """Meshes, PVS, pictures and the modelling metrics for metrics.json."""
        from pathlib import Path

        from explore.pictures import save_curves_png

        out_dir = Path(out_dir)
        s = self.session
        metrics = s.metrics()
        s.surface.save_ply(out_dir / "model.ply")
        s.surface.save_png(out_dir / "model.png", f"{s.sim.spec.name}: {s.n_scans} scans")
        s.pvs.save(out_dir / "pvs.npz")
        coverage = list(metrics.get("coverage") or [])
        estimate = list(metrics.get("coverage_estimate") or [])
        x = np.arange(1, len(estimate) + 1)
        curves = {"ĉ_m (estimate)": (x, np.asarray(estimate))}
        if coverage:
            curves["c_a (ground truth)"] = (x[: len(coverage)], np.asarray(coverage))
        save_curves_png(curves, out_dir / "coverage.png", "scans", "coverage", self.strategy)
        selection = list(metrics.get("selection_s") or [])
        return {
            "strategy": self.strategy,
            "scans": s.n_scans,
            "coverage": coverage[-1] if coverage else None,
            "coverage_per_scan": coverage,
            "coverage_estimate": estimate[-1] if estimate else None,
            "coverage_estimate_per_scan": estimate,
            "density_per_scan": metrics.get("density"),
            "path_length_m": metrics.get("travel_m"),
            "scan_path_m": metrics.get("scan_path_m"),
            "selection_s_mean": float(np.mean(selection)) if selection else None,
            "selection_s_per_scan": selection,
            "n_s": metrics.get("n_s"),
            "stop_reason": metrics.get("stop_reason"),
            "objects": [{"name": b.name, "result": "modelled", "coverage": coverage[-1] if coverage else None}
                        for b in s.sim.objects()],
        }


class _Plan:
    def __init__(self, length: float) -> None:
        self.length = length


PLUGINS = [
    StartModelling,
    AcquireScan,
    IntegrateScan,
    GenerateCandidates,
    SelectNBV,
    CheckTermination,
    CheckFlag,
    PlanMotion,
    ExecuteMotion,
]
