"""Executing a planned motion with positioning noise, open loop or re-localising at its waypoints.

Open loop (Vasquez-Gomez Sec. A6) the per-``dt`` velocity errors add up over the whole
motion: with sigma_omega = 0.28 rad/s and ``dt`` = 50 ms the heading spreads by
0.28 sqrt(dt T) rad after T seconds of base motion (0.2 rad after 10 s), and a 3 m drive ends
decimetres off its path. A mobile robot instead localises while it moves and steers back onto
its plan. :func:`follow_plan` models that: the plan's controls are cut into pieces of constant
control (the turn, drive and turn of each base segment, every arm motion) and, with
``feedback``, each piece is commanded from the configuration actually reached towards the
piece's nominal end:

* a turn in place turns to the nominal heading at the piece's end;
* a drive first turns in place to face its end point (as fast as the base turns; a step of
  zero command costs nothing) and then drives the distance to it in the nominal time; with
  ``leg_length`` > 0 a drive is cut into legs of at most that length, each re-aimed;
* joints move to their nominal values at the piece's end;
* after a turn or a drive the robot re-localises once more and turns back to the nominal
  heading while it is more than ``tolerance`` off (at most three corrections).

Each commanded step errs by the robot's truncated Gaussian noise (a part commanded to stand
still does not err), so errors no longer add up over the motion but only over a piece. Pieces
that turn and translate at once (kinodynamic arcs) are executed open loop. The same function
draws k rollouts at once (Algorithm 1's samples) and the one motion a robot executes; the
samples stay aligned in time (a sample that needs a shorter re-aiming turn waits), so every
sample shares the nominal run's arm configuration at every step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Array, wrap_angle
from explore.motion.noise import STILL, truncated_normal, truncated_normal_logpdf
from explore.motion.records import Execution, MotionPlan


@dataclass
class Rollouts:
    """k executions of one plan by :func:`follow_plan`, aligned in time (M steps)."""

    configs: np.ndarray  # (k, M + 1, dof)
    nominal: np.ndarray  # (M + 1, dof): the same controller without noise
    log_prob: Array  # (k,) log P_i = sum of log p(eps) over the sampled errors (Eq. 2-3)
    applied: np.ndarray | None = None  # (k, M, nc) command + error of every step (``keep_controls``)
    commands: np.ndarray | None = None  # (k, M, nc) the commands alone


def control_pieces(controls: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) step ranges over which the plan's control vector stays the same."""
    controls = np.asarray(controls, dtype=float)
    if len(controls) == 0:
        return []
    change = np.any(np.abs(np.diff(controls, axis=0)) > 1e-6 * (1.0 + np.abs(controls[1:])), axis=1)
    cuts = [0, *(np.flatnonzero(change) + 1).tolist(), len(controls)]
    return list(zip(cuts[:-1], cuts[1:], strict=True))


class _Stepper:
    """Vectorised Euler steps of k + 1 copies of the robot (the last one without noise)."""

    def __init__(self, robot: Any, start: Array, k: int, rng: np.random.Generator | None, keep: bool) -> None:
        self.robot, self.k, self.rng, self.keep = robot, k, rng, keep
        self.sigma = np.asarray(robot.control_sigma(), dtype=float)
        self.beta = float(robot.truncation)
        self.dt = float(robot.dt)
        self.base = list(robot.base_dofs)
        self.joints = list(robot.joint_dofs)
        self.nb = int(robot.n_base_controls)
        self.lower = np.asarray(robot.lower, dtype=float)[self.joints]
        self.upper = np.asarray(robot.upper, dtype=float)[self.joints]
        self.q = np.repeat(np.asarray(start, dtype=float)[None], k + 1, axis=0)
        self.history = [self.q.copy()]
        self.log_prob = np.zeros(k + 1)
        self.applied: list[np.ndarray] = []
        self.commands: list[np.ndarray] = []
        self.rate = float(np.asarray(robot.base_control_limits(), dtype=float)[-1]) if self.base else 1.0

    def _errors(self, u: np.ndarray) -> np.ndarray:
        """Truncated errors of the k noisy copies where their part is commanded to move."""
        eps = np.zeros_like(u)
        if self.rng is None or not np.any(self.sigma > 0):
            return eps
        moving = np.asarray(self.robot.noise_mask(u), dtype=bool) & (self.sigma > 0)[None]
        moving[self.k] = False
        eps[: self.k] = truncated_normal(self.rng, self.sigma, self.k, self.beta)
        eps *= moving
        self.log_prob += truncated_normal_logpdf(eps, self.sigma, self.beta, moving, per_row=True)
        return eps

    def integrate(self, q: np.ndarray, applied: np.ndarray) -> np.ndarray:
        """One Euler step (Vasquez-Gomez Sec. A6) of configurations (n, dof) under controls (n, nc)."""
        q = q.copy()
        if self.base:
            ix, iy, ith = self.base
            c, s = np.cos(q[:, ith]), np.sin(q[:, ith])
            if self.robot.drive == "differential":
                q[:, ix] += applied[:, 0] * c * self.dt
                q[:, iy] += applied[:, 0] * s * self.dt
                q[:, ith] += applied[:, 1] * self.dt
            else:
                q[:, ix] += (c * applied[:, 0] - s * applied[:, 1]) * self.dt
                q[:, iy] += (s * applied[:, 0] + c * applied[:, 1]) * self.dt
                q[:, ith] += applied[:, 2] * self.dt
        if self.joints:
            q[:, self.joints] = np.clip(q[:, self.joints] + applied[:, self.nb:] * self.dt, self.lower, self.upper)
        return q

    def step(self, u: np.ndarray) -> None:
        """Apply commands ``u`` (k + 1, nc) for one ``dt`` with the noise model."""
        applied = u + self._errors(u)
        q = self.integrate(self.q, applied)
        self.q = q
        self.history.append(q)
        if self.keep:
            self.applied.append(applied)
            self.commands.append(u)

    def joint_commands(self, target: Array, steps: int) -> np.ndarray:
        """(k + 1, n_joints) joint velocities reaching ``target``'s joints in ``steps`` steps."""
        return (np.asarray(target)[self.joints][None] - self.q[:, self.joints]) / (steps * self.dt)

    def turn_to(self, heading: np.ndarray, tolerance: float = 0.0) -> None:
        """Turn each copy in place to ``heading`` (k + 1,) at most at the base's turn rate (those
        within ``tolerance`` stay); the copies that finish first wait."""
        delta = wrap_angle(heading - self.q[:, self.base[2]])
        delta[np.abs(delta) <= tolerance] = 0.0
        need = np.ceil(np.abs(delta) / (self.rate * self.dt) - 1e-9).astype(int)
        for t in range(int(need.max(initial=0))):
            u = np.zeros((self.k + 1, len(self.sigma)))
            turning = need > t
            u[turning, self.nb - 1] = delta[turning] / (need[turning] * self.dt)
            self.step(u)

    def settle_heading(self, heading: float, tolerance: float, tries: int = 3) -> None:
        """Re-localise and correct the heading until every copy is within ``tolerance``."""
        target = np.full(self.k + 1, heading)
        for _ in range(tries):
            if np.all(np.abs(wrap_angle(target - self.q[:, self.base[2]])) <= tolerance):
                return
            self.turn_to(target, tolerance)


def follow_plan(robot: Any, start: Array, controls: np.ndarray, rng: np.random.Generator | None, k: int = 1,
                feedback: bool = True, leg_length: float = 0.0, keep_controls: bool = False,
                tolerance: float = 0.02) -> Rollouts:
    """k noisy executions of ``controls`` from ``start`` (open loop or re-localising, see the module).

    ``rng`` None: no noise. The nominal run (no noise, same controller) comes with the samples.
    ``tolerance`` (rad): with ``feedback``, after a turn or a drive a copy further than this
    from the nominal heading turns to it (a few tries, each with its own noise).
    """
    controls = np.asarray(controls, dtype=float)
    stepper = _Stepper(robot, start, int(k), rng, keep_controls)
    nominal = [np.asarray(start, dtype=float)[None]]
    for t in range(len(controls)):  # the plan's own nominal states, the targets of its pieces
        nominal.append(stepper.integrate(nominal[-1], controls[t][None]))
    targets = [q[0] for q in nominal]
    for begin, end in control_pieces(controls):
        _follow_piece(stepper, controls[begin:end], targets[begin:end + 1], feedback, leg_length, tolerance)
    configs = np.stack(stepper.history, axis=1)  # (k + 1, M + 1, dof)
    applied = commands = None
    if keep_controls:
        applied = np.stack(stepper.applied, axis=1)[: stepper.k]
        commands = np.stack(stepper.commands, axis=1)[: stepper.k]
    return Rollouts(configs[: stepper.k], configs[stepper.k], stepper.log_prob[: stepper.k], applied, commands)


def plan_controls(robot: Any, plan: MotionPlan | np.ndarray) -> tuple[Array, np.ndarray]:
    """Start state and per-``dt`` nominal controls of a plan (as ``robot.execute`` runs it)."""
    if isinstance(plan, MotionPlan) and plan.controls is not None:
        return np.asarray(plan.path[0], dtype=float), np.asarray(plan.controls, dtype=float)
    path = plan.path if isinstance(plan, MotionPlan) else np.asarray(plan, dtype=float)
    controls, _ = robot.controls_from_path(path)
    return np.asarray(path[0], dtype=float), controls


def execute_following(robot: Any, plan: MotionPlan | np.ndarray, rng: np.random.Generator | None,
                      feedback: bool = True, leg_length: float = 0.0) -> Execution:
    """Execute ``plan`` as :func:`follow_plan` steers it (``rng`` None: without noise); the
    motion is replayed in the TRUE world, where a collision is an event (``robot.execute``).

    The execution's controls are the commands and its noise the errors added to them.
    """
    start, controls = plan_controls(robot, plan)
    done = follow_plan(robot, start, controls, rng, 1, feedback, leg_length, keep_controls=True)
    assert done.applied is not None and done.commands is not None
    run = robot.execute(MotionPlan(done.configs[0], controls=done.applied[0], dt=float(robot.dt)),
                        None, noise=False, world="true")
    n = len(run.controls)  # fewer when a collision stopped the motion
    run.controls, run.noise = done.commands[0][:n], (done.applied[0] - done.commands[0])[:n]
    run.log_prob = float(done.log_prob[0])
    return run


def _follow_piece(stepper: _Stepper, controls: np.ndarray, nominal: list[Array], feedback: bool,
                  leg_length: float, tolerance: float) -> None:
    """One piece of constant control (see the module for what each kind does)."""
    n, u, nb = len(controls), controls[0], stepper.nb
    base_u = u[:nb]
    translating = nb and np.any(np.abs(base_u[:-1]) > STILL)
    turning = nb and abs(base_u[-1]) > STILL
    if not feedback or (translating and turning):
        for t in range(n):
            stepper.step(np.repeat(controls[t][None], stepper.k + 1, axis=0))
        return
    if not translating:  # the base turns or stands still; the joints go to their targets
        u_all = np.zeros((stepper.k + 1, len(u)))
        ith = stepper.base[2] if nb else -1
        if turning:  # headings are continuous (never wrapped) along a motion
            u_all[:, nb - 1] = (nominal[-1][ith] - stepper.q[:, ith]) / (n * stepper.dt)
        if stepper.joints:
            u_all[:, nb:] = stepper.joint_commands(nominal[-1], n)
        for _ in range(n):
            stepper.step(u_all)
        if turning:
            stepper.settle_heading(float(nominal[-1][ith]), tolerance)
        return
    legs = 1 if leg_length <= 0.0 else max(1, math.ceil(float(np.linalg.norm(base_u[:-1])) * n * stepper.dt
                                                        / leg_length - 1e-9))
    cuts = np.linspace(0, n, legs + 1).round().astype(int)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        if b > a:
            _drive_leg(stepper, u, nominal[b], b - a, tolerance)


def _drive_leg(stepper: _Stepper, u: Array, target: Array, steps: int, tolerance: float) -> None:
    """Re-aim at ``target``'s base position, drive there in ``steps`` steps, correct the heading."""
    ix, iy, ith = stepper.base
    nb = stepper.nb
    xy = np.asarray(target)[[ix, iy]]
    u_all = np.zeros((stepper.k + 1, len(u)))
    if stepper.joints:
        u_all[:, nb:] = stepper.joint_commands(target, steps)
    if stepper.robot.drive == "differential":
        backwards = bool(u[0] < 0.0)
        d = xy[None] - stepper.q[:, [ix, iy]]
        heading = np.arctan2(d[:, 1], d[:, 0]) + (math.pi if backwards else 0.0)
        stepper.turn_to(np.where(np.hypot(d[:, 0], d[:, 1]) > 1e-9, heading, stepper.q[:, ith]))
        d = xy[None] - stepper.q[:, [ix, iy]]
        u_all[:, 0] = (-1.0 if backwards else 1.0) * np.hypot(d[:, 0], d[:, 1]) / (steps * stepper.dt)
        for _ in range(steps):
            stepper.step(u_all)
        stepper.settle_heading(float(target[ith]), tolerance)
        return
    d = xy[None] - stepper.q[:, [ix, iy]]  # omnidirectional: the body-frame velocity towards the target
    c, s = np.cos(stepper.q[:, ith]), np.sin(stepper.q[:, ith])
    u_all[:, 0] = (c * d[:, 0] + s * d[:, 1]) / (steps * stepper.dt)
    u_all[:, 1] = (-s * d[:, 0] + c * d[:, 1]) / (steps * stepper.dt)
    for _ in range(steps):
        stepper.step(u_all)
