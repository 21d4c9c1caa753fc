"""Behaviour plugins: one per step of the seeds' loops, thin adapters over the library.

Each declares the blackboard keys it reads and writes (in the run's namespace) and calls
one step of :class:`explore.nbv.modelling.ModellingSession`, which keeps the records, so a tree
and ``ModellingSession.step()`` produce the same metrics. Steps that take long (scanning,
integrating, registering, planning, moving) are ``blocking``: they run in the run's worker
thread while the tree keeps ticking.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import NO_CANDIDATES, Param
from explore.motion import Capability
from explore.nbv import STOP, Decision, ModellingSession
from explore.runtime import ExploreBehaviour, ModellingOutputs, Outcome, failure, success


class StartModelling(ExploreBehaviour):
    """Start single-object modelling: PVS, surface model, strategy and motion planner over the world's region."""

    name = "start_modelling"
    writes = ("modelling", "done", "reason")
    blocking = True
    params = (
        Param("strategy", str, "ig_quality/bs_hr_calibrated", "", "NBV strategy (overridden by --strategy; the "
              "thesis IG/Quality + BS/HR with the stop calibrated on the broad object set)"),
        Param("resolution", float, 0.005, "m", "PVS voxel edge length", low=1e-4),
        Param("max_scans", int, 30, "", "scan budget (overridden by --max-scans)", low=1),
        Param("noise", bool, True, "", "execute motions with the robot's positioning noise model"),
        Param("relocalise", bool, True, "", "a mobile base re-localises while it executes a motion and steers back "
              "onto it; false: open loop, as Vasquez-Gomez et al. execute (errors add up over a whole approach)"),
        Param("max_plan_attempts", int, 10, "", "candidates tried per scan when planning the best fails", low=1),
        Param("fallback", str, "auto", "", "view generator tried when no candidate of the strategy is left or "
              "can be reached; auto = reachable (views of the robot's own configurations) for an arm on a fixed "
              "base, the sphere for other robots; none = no fallback"),
        Param("continue_after_stop", bool, False, "", "scan on to the budget after the termination said stop "
              "(thesis Table 4.5: n_s is where it first did, c_a(30) after the budget)"),
    )

    def _fallback(self, robot: Any, registry: Any) -> str | None:
        """The fallback view generator's name (see the ``fallback`` parameter); an unknown one is bad input."""
        name = self.p["fallback"]
        if name == "auto":
            fixed_arm = robot.has(Capability.ARM) and not robot.has(Capability.MOBILE_BASE)
            return "reachable" if fixed_arm else "sphere"
        if name in ("", "none"):
            return None
        registry.get("view_generator", name, self.name, "fallback")
        return name

    def work(self) -> Outcome:
        ctx = self.context
        config = ctx.config
        strategy_name = config.strategy or self.p["strategy"]
        strategy = ctx.registry.create("strategy", strategy_name, config.scoped("strategy"), "--strategy", "strategy")
        session = ModellingSession(
            ctx.sim,
            strategy,
            ctx.registry,
            seed=config.seed,
            resolution=float(config.setting("resolution", self.p["resolution"])),
            max_scans=config.max_scans or self.p["max_scans"],
            planner=(config.planner, config.scoped("planner")),
            noise=self.p["noise"],
            relocalise=self.p["relocalise"],
            max_plan_attempts=self.p["max_plan_attempts"],
            fallback_generator=self._fallback(ctx.sim.robot, ctx.registry),
            continue_after_stop=self.p["continue_after_stop"],
        )
        ctx.state["modelling"] = ModellingOutputs(session, strategy_name, ctx)
        self.write("modelling", session)
        self.write("done", False)
        self.write("reason", "")
        ctx.trace("decision", what="strategy", strategy=strategy_name, planner=session.motion.planner_name)
        return success(f"strategy {strategy_name}, planner {session.motion.planner_name}")


class PlanMotion(ExploreBehaviour):
    """Plan the scan: scan-path IK in 10 mm portions, the PVS along it (NBS rule), the approach motion.

    With ``initial`` the random initial scan along a side or edge of the region (thesis
    Sec. 4.7; the next side or edge if the robot cannot reach it). Otherwise the selected
    candidate, and the next best ones if planning it fails; when none can be planned the
    flag ``done`` is set with the reason and the behaviour fails.
    """

    name = "plan_motion"
    reads = ("modelling", "candidate")
    writes = ("plan", "done", "reason")
    blocking = True
    params = (Param("initial", bool, False, "", "plan the initial scan instead of the selected candidate"),)

    def work(self) -> Outcome:
        session = self.need("modelling")
        before = len(session.motion.plans)
        plan = session.plan_initial() if self.p["initial"] else session.plan_best(self.need("candidate"))
        for record in session.motion.plans[before:]:
            self.context.trace("decision", what="plan", source=record.source, verdict=record.verdict,
                               seconds=record.seconds, planner=record.planner)
        self.write("plan", plan)
        if plan is None:
            what = "initial scan" if self.p["initial"] else "candidate"
            reason = f"no reachable {what} ({session.plan_failure})"
            if self.p["initial"]:
                session.finish("failed", reason)
            else:
                session.note_stop(Decision(STOP, reason, NO_CANDIDATES))
                session.finish("stopped", reason, NO_CANDIDATES)
                self.write("done", True)
                self.write("reason", reason)
            return failure(reason)
        return success(plan.reason)


class ExecuteMotion(ExploreBehaviour):
    """Execute the approach motion with the robot's positioning noise, checked against the true world."""

    name = "execute_motion"
    reads = ("modelling", "plan")
    blocking = True

    def work(self) -> Outcome:
        session = self.need("modelling")
        run = session.execute(self.need("plan"))
        if run is None:
            return success("placed at the scan start")
        _trace_motion(self, session, run)
        if session.status == "collided":
            return failure(session.reason)
        return success(f"{len(run.controls)} steps" + (", collided (continued)" if run.collided else ""))


class AcquireScan(ExploreBehaviour):
    """Run the scan motion (a linear scan path, or none for a single view) and take the scan."""

    name = "acquire_scan"
    reads = ("modelling", "plan")
    writes = ("scan",)
    blocking = True

    def work(self) -> Outcome:
        session = self.need("modelling")
        motions = len(session.motion.motions)
        scan, scan_length, _ = session.acquire(self.need("plan"))
        if len(session.motion.motions) > motions:
            _trace_motion(self, session, None)
        if session.status == "collided":
            return failure(session.reason)
        self.write("scan", scan)
        hits = int(scan.hits.sum())
        self.context.trace("scan", index=session.n_scans + 1, beams=len(scan), returns=hits, length_m=scan_length)
        if self.context.rerun is not None:
            self.context.rerun.step(session.n_scans + 1)
            self.context.rerun.scan(scan)
        return success(f"{hits} returns")


class RegisterScan(ExploreBehaviour):
    """Local ICP of the new scan to the model before integration (Kriegel thesis Sec. 3.2.3).

    Thesis values: correspondences within 3 mm, 2-3 iterations (running to convergence
    shrank a model by ~4 mm), pairs with normals more than 60 deg apart rejected. A weak
    or implausibly large correction is not applied.
    """

    name = "register_scan"
    reads = ("modelling", "scan")
    writes = ("scan",)
    blocking = True
    params = (
        Param("enabled", bool, True, "", "register (false: pass the scan through unchanged)"),
        Param("radius", float, 0.003, "m", "correspondence radius", low=1e-5),
        Param("iterations", int, 3, "", "ICP iterations (thesis 2-3)", low=1),
        Param("normal_gate_deg", float, 60.0, "deg", "reject pairs whose normals differ more", low=0.0, high=180.0),
        Param("method", str, "point_to_point", "", "least-squares step (thesis: point to point)",
              choices=("point_to_point", "point_to_plane")),
        Param("min_fitness", float, 0.3, "", "apply only if this share of scan points found a partner", low=0.0,
              high=1.0),
        Param("max_shift", float, 0.01, "m", "apply only corrections that move the scan's centroid less", low=0.0),
        Param("max_angle_deg", float, 3.0, "deg", "apply only corrections up to this rotation", low=0.0),
    )

    def work(self) -> Outcome:
        if not self.p["enabled"]:
            return success("disabled")
        session = self.need("modelling")
        registrar = self.context.registry.create(
            "registrar", "icp",
            {"radius": self.p["radius"], "iterations": self.p["iterations"],
             "normal_gate_deg": self.p["normal_gate_deg"], "method": self.p["method"]},
            "register_scan", "params",
        )
        scan = self.need("scan")
        corrected, result = session.register(scan, registrar, self.p["min_fitness"], self.p["max_shift"],
                                             self.p["max_angle_deg"])
        if result is None:
            return success("no model yet")
        applied = corrected is not scan
        points = scan.points()
        centre = points.mean(axis=0)
        transform = result.transformation
        shift = float(np.linalg.norm(transform[:3, :3] @ centre + transform[:3, 3] - centre))
        self.context.trace("registration", index=session.n_scans + 1, fitness=result.fitness, rmse=result.rmse,
                           shift_m=shift, applied=applied)
        self.write("scan", corrected)
        return success(f"{'applied' if applied else 'rejected'}: shift {1000 * shift:.2f} mm, fitness "
                       f"{result.fitness:.2f}")


class IntegrateScan(ExploreBehaviour):
    """Integrate the last scan into the PVS and the surface model (and its features)."""

    name = "integrate_scan"
    reads = ("modelling", "scan")
    blocking = True

    def work(self) -> Outcome:
        session = self.need("modelling")
        stats = session.integrate(self.need("scan"))
        outputs = self.context.state.get("modelling")
        if outputs is not None:
            outputs.after_integration()
        record = session.records[-1]
        fields = {k: v for k, v in vars(record).items() if isinstance(v, int | float | str | np.floating)}
        line = outputs.status_line() if outputs is not None else f"scans {session.n_scans}"
        self.context.status_line = line
        self.context.trace("integrated", **fields, stats=stats)
        if self.context.rerun is not None:
            mesh = session.surface.mesh
            self.context.rerun.mesh(mesh.vertices, mesh.triangles)
            self.context.rerun.voxels(session.pvs.occupied_points(), session.pvs.resolution)
        return success(line)


class GenerateCandidates(ExploreBehaviour):
    """Generate NBV/NBS candidates with the strategy's view generator onto the candidate stack."""

    name = "generate_candidates"
    reads = ("modelling",)
    blocking = True

    def work(self) -> Outcome:
        count = self.need("modelling").generate()
        return success(f"{count} candidates")


class SelectNBV(ExploreBehaviour):
    """Score the candidates with the strategy's utility and pick the best one."""

    name = "select_nbv"
    reads = ("modelling",)
    writes = ("candidate", "done", "reason")
    blocking = True

    def work(self) -> Outcome:
        session = self.need("modelling")
        scored = list(session.stack)
        candidate = session.select()  # scores every candidate of the stack in place
        self.write("candidate", candidate)
        if candidate is None:  # nothing left: the termination rule says whether the goal (or budget) came first
            decision = session.terminate()
            if not decision.stop:
                decision = Decision(STOP, "no candidate left", NO_CANDIDATES)
            session.note_stop(decision)
            session.finish("stopped", decision.reason, decision.outcome)
            self.write("done", True)
            self.write("reason", decision.reason)
            self.context.trace("decision", what="select", result="none left")
            return success("no candidate left")
        if self.context.rerun is not None:
            poses = np.array([c.pose for c in scored])
            self.context.rerun.candidates(poses[:, :3, 3], poses[:, :3, 2], np.array([c.score for c in scored]))
        self.context.trace("decision", what="select", score=float(candidate.score), source=candidate.source,
                           margin=session.pending_margin)
        return success(f"score {candidate.score:.4g}")


class CheckTermination(ExploreBehaviour):
    """Ask the strategy's termination rule: continue, switch mode, or stop (with the reason)."""

    name = "check_termination"
    reads = ("modelling", "done", "reason")
    writes = ("done", "reason")

    def work(self) -> Outcome:
        if self.read("done"):
            return success(self.read("reason") or "done")
        session = self.need("modelling")
        decision = session.terminate()
        self.context.trace("decision", what="termination", action=decision.action, reason=decision.reason,
                           margin=decision.margin)
        if decision.stop:
            session.note_stop(decision)
        if decision.stop and session.continue_after_stop and session.n_scans < session.max_scans:
            return success(f"n_s = {session.first_stop} ({session.first_stop_reason}); scanning on")
        if decision.stop:
            session.finish("stopped", decision.reason, decision.outcome)
            self.write("done", True)
            self.write("reason", decision.reason)
        return success(f"{decision.action}: {decision.reason}" if decision.reason else decision.action)


class CheckFlag(ExploreBehaviour):
    """Condition: succeed when a blackboard flag has the expected value, fail otherwise."""

    name = "check_flag"
    is_condition = True
    params = (
        Param("key", str, "done", "", "blackboard key (in the run's namespace)"),
        Param("expect", bool, True, "", "value that makes the condition succeed"),
    )
    key_params = ("key",)

    def work(self) -> Outcome:
        value = bool(self.read(self.p["key"], False))
        if value == self.p["expect"]:
            return success(f"{self.p['key']} is {value}")
        return failure(f"{self.p['key']} is {value}")


def _trace_motion(behaviour: ExploreBehaviour, session: Any, run: Any) -> None:
    """Trace the last executed motion (and log the sensor path to Rerun)."""
    record = session.motion.motions[-1]
    behaviour.context.trace("motion", index=session.n_scans + 1, kind=record.kind, steps=record.steps,
                            duration_s=record.duration_s, sensor_path_m=record.sensor_path_m,
                            collided=record.collided, bodies=list(record.bodies))
    if behaviour.context.rerun is not None and run is not None:
        robot = session.robot
        behaviour.context.rerun.trajectory(np.array([robot.fk(q)[:3, 3] for q in run.configs[::5]]))
        behaviour.context.rerun.sensor_pose(run.sensor_pose)


PLUGINS = [
    StartModelling,
    PlanMotion,
    ExecuteMotion,
    AcquireScan,
    RegisterScan,
    IntegrateScan,
    GenerateCandidates,
    SelectNBV,
    CheckTermination,
    CheckFlag,
]
