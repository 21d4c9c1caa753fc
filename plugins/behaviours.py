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
        ctx.state["modelling"] = ModellingOutputs(session, strategy_name)
        self.write("modelling", session)
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
        self.context.trace("scan", index=len(session.history), beams=len(scan), returns=hits)
        return success(f"{hits} returns")


class IntegrateScan(ExploreBehaviour):
    """Integrate the last scan into the PVS and the surface model (and its features)."""

    name = "integrate_scan"
    reads = ("modelling", "scan")
    blocking = True

    def work(self) -> Outcome:
        session = self.read("modelling")
        stats = session.integrate(self.read("scan"))
        record = session.history[-1] if session.history else None
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


class ModellingOutputs:
    """Adapter that gives the run directory what a modelling session produced."""

    def __init__(self, session: Any, strategy: str) -> None:
        self.session = session
        self.strategy = strategy

    def live_stats(self) -> dict[str, Any]:
        return self.session.live_stats() if hasattr(self.session, "live_stats") else {}

    def run_outputs(self, out_dir: Any) -> dict[str, Any]:
        return self.session.write_outputs(out_dir)


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
