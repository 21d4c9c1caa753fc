"""One exploration run: a tree, a world and the overrides, executed tick by tick.

:class:`RunContext` is the value every behaviour receives in ``setup(context=...)``: the
simulation, the registry, the run's blackboard namespace, a worker thread for long steps,
the trace, the optional Rerun log and a place (``state``) where behaviours keep library
objects (the modelling session, the scene, the database). :func:`execute` checks every
name and setting, ticks the tree until it finishes and writes the run directory
(``metrics.json``, ``trace.jsonl``, meshes, ``pvs.npz``, pictures, the tree as dot/PNG).
The schema of ``metrics.json`` is documented in ``docs/metrics.md``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from explore.core import (
    BUDGET,
    FAILURE,
    INTERRUPTED,
    SUCCESS,
    BadInput,
    Terminated,
    set_threads,
)
from explore.motion import work_clock
from explore.runtime.context import RunContext
from explore.runtime.outputs import write_outputs
from explore.runtime.run_inputs import (
    RunConfig,
    check_inputs,
    default_out_dir,
    highest_missing,
    prepare_out_dir,
    remove_run_files,
)
from explore.runtime.trees import build


@dataclass
class RunResult:
    status: str  # one of explore.core.outcomes.STATUSES
    reason: str
    metrics: dict[str, Any]
    out_dir: Path


def execute(
    config: RunConfig,
    registry: Any,
    on_tick: Callable[[Any, RunContext], None] | None = None,
) -> RunResult:
    """Check the inputs, build and tick the tree, write the run directory.

    Every name and setting is checked before the run directory is created. Bad input found
    later (e.g. a behaviour raising :class:`BadInput`) removes what this run wrote and
    re-raises; any other ending writes ``metrics.json`` with the status and reason.
    """
    tree_file, overrides = check_inputs(config, registry)
    path = config.out or default_out_dir(config)
    created = highest_missing(path)  # the folder this run creates (with runs/ if that is new too)
    out_dir = prepare_out_dir(path)
    set_threads(config.threads)
    try:
        context = RunContext(config, registry, out_dir)
    except BadInput:
        remove_run_files(out_dir, created)
        raise
    try:
        with work_clock() if config.planning_clock == "work" else contextlib.nullcontext():
            status, reason, root = _tick(config, registry, context, tree_file, overrides, on_tick)
        metrics = write_outputs(context, tree_file, root, status, reason)
        context.trace("end", status=status, reason=reason)
        return RunResult(status, reason, metrics, out_dir)
    except BadInput:
        context.close()
        remove_run_files(out_dir, created)
        raise
    except BaseException as error:  # an interrupt (SIGINT, SIGTERM) or a crash: still leave the results behind
        if isinstance(error, KeyboardInterrupt):
            status, reason = INTERRUPTED, "terminated (SIGTERM)" if isinstance(error, Terminated) else "interrupted"
        else:
            status, reason = FAILURE, f"crashed: {type(error).__name__}: {error}"
        context.settle()  # the step running in the worker ends before its results are read
        write_outputs(context, tree_file, context.root, status, reason)
        context.trace("end", status=status, reason=reason)
        raise
    finally:
        context.close()


def _tick(config: RunConfig, registry: Any, context: RunContext, tree_file: Any,
          overrides: dict[str, dict[str, Any]], on_tick: Callable[[Any, RunContext], None] | None,
          ) -> tuple[str, str, Any]:
    """Tick until the root finishes (or ``max_ticks``); trace every status change."""
    import py_trees
    from py_trees.common import Status

    root = build(tree_file.root, registry, overrides, context.namespace)
    context.root = root
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup(context=context)
    context.trace("start", tree=tree_file.name, world=context.sim.spec.name, seed=config.seed)
    previous: dict[int, str] = {}
    ticks = 0
    while ticks < config.max_ticks:
        tree.tick()
        ticks += 1
        for node in root.iterate():
            status = node.status.value
            if previous.get(id(node)) != status:
                previous[id(node)] = status
                if node is not root or status != "RUNNING":
                    context.trace("status", tick=ticks, node=node.name, status=status, message=node.feedback_message)
        if on_tick is not None:
            on_tick(root, context)
        if root.status in (Status.SUCCESS, Status.FAILURE):
            break
        context.wait_for_work(0.1)
    providers = [p for p in context.state.values() if getattr(p, "end_outcome", "")]
    short = next((p for p in providers if p.end_outcome != SUCCESS), None)
    if root.status == Status.SUCCESS:  # the tree succeeded: did the mission reach its goal?
        if short is not None:
            status, reason = short.end_outcome, short.end_reason
        else:
            ends = [getattr(p, "end_reason", "") for p in context.state.values()]
            status, reason = SUCCESS, root.feedback_message or next((e for e in ends if e), "tree succeeded")
    elif root.status == Status.FAILURE:
        status, reason = FAILURE, _failure_reason(root)
        if short is not None and not _failed_steps(root):  # only a goal check failed: the run's state says why
            status, reason = short.end_outcome, f"{short.end_reason} ({reason})"
    else:
        status, reason = BUDGET, f"tree still running after max_ticks={config.max_ticks}"
    tree.shutdown()
    return status, reason, root


def _failure_reason(root: Any) -> str:
    """The deepest failed node's reason (the step that actually failed)."""
    from py_trees.common import Status

    reason = root.feedback_message or "tree failed"
    failed = [n for n in root.iterate() if n.status == Status.FAILURE and n.feedback_message and not n.children]
    for node in _failed_steps(root) or failed:
        reason = f"{node.name}: {node.feedback_message}"
    return reason


def _failed_steps(root: Any) -> list[Any]:
    """The failed leaves that are steps, not conditions (a condition's failure is an answer)."""
    from py_trees.common import Status

    return [n for n in root.iterate() if n.status == Status.FAILURE and n.feedback_message and not n.children
            and not getattr(n, "is_condition", False)]
