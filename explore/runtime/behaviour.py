"""Base class of the behaviour plugins: declared blackboard keys, non-blocking work, reasons.

A behaviour is a thin adapter over the library. It declares the blackboard keys it reads
and writes (py_trees clients with access rights, in the run's namespace), does its work in
:meth:`work` and reports failures with a reason that ends up in the trace. Work that takes
long (motion, scanning, planning) sets ``blocking = True``: it then runs in the run's
worker thread and :meth:`update` returns RUNNING until the result is there.
"""

from __future__ import annotations

import traceback
from abc import abstractmethod
from concurrent.futures import Future
from typing import Any

import py_trees
from py_trees.common import Access, Status

from explore.core import BadInput


class Outcome:
    """What :meth:`ExploreBehaviour.work` returns: a status and a reason."""

    __slots__ = ("status", "reason")

    def __init__(self, status: Status, reason: str = "") -> None:
        self.status = status
        self.reason = reason


def success(reason: str = "") -> Outcome:
    return Outcome(Status.SUCCESS, reason)


def failure(reason: str) -> Outcome:
    return Outcome(Status.FAILURE, reason)


class MissingInput(Exception):
    """A blackboard key a behaviour needs that no step before it has written."""


class ExploreBehaviour(py_trees.behaviour.Behaviour):
    """Base of explore's behaviour plugins (kind ``behaviour``).

    A subclass declares the blackboard keys it ``reads`` and ``writes`` and, in ``key_params``, the
    parameters whose value names a key it reads (``check_flag``'s ``key``): a tree file whose loops
    or such parameters read a key no behaviour of it writes is refused when it loads."""

    kind = "behaviour"
    name = "behaviour"  # registered name (instances get their display name from the tree)
    params: tuple = ()
    reads: tuple[str, ...] = ()
    writes: tuple[str, ...] = ()
    #: parameters whose value names a blackboard key the behaviour reads (a tree file is refused
    #: when no behaviour of it writes that key: a misspelt flag would never be set)
    key_params: tuple[str, ...] = ()
    blocking = False
    is_condition = False  # a condition's FAILURE is an answer, not an error: not traced as failure

    def __init__(self, name: str, **params: Any) -> None:
        super().__init__(name=name)
        self.p = params
        self.context: Any = None
        self.bb: py_trees.blackboard.Client | None = None
        self._future: Future | None = None
        self.tree_path = ""

    # -- lifecycle -------------------------------------------------------------------------
    def setup(self, **kwargs: Any) -> None:
        """Receive the run context and register the declared blackboard keys (``reads``, the keys
        named by ``key_params``, ``writes``)."""
        self.context = kwargs["context"]
        self.bb = self.attach_blackboard_client(name=self.name, namespace=self.context.namespace)
        for key in (*self.reads, *(self.p[name] for name in self.key_params)):
            self.bb.register_key(key, access=Access.READ)
        for key in self.writes:
            self.bb.register_key(key, access=Access.WRITE)

    def initialise(self) -> None:
        self.feedback_message = ""
        self.context.progress("")
        if self.blocking:
            self._future = self.context.submit(self._held_step)

    def _held_step(self) -> tuple[Outcome, list[dict[str, Any]]]:
        """The step in the worker thread, its trace events held until the tick takes its result."""
        with self.context.held_trace() as held:
            return self._guarded(), held

    def update(self) -> Status:
        if self.blocking:
            if self._future is None or not self._future.done():
                return Status.RUNNING
            outcome, held = self._future.result()
            self._future = None
            self.context.release(held)
        else:
            outcome = self._guarded()
        self.feedback_message = outcome.reason
        if outcome.status == Status.FAILURE and not self.is_condition:
            self.context.trace("failure", node=self.name, behaviour=type(self).name, reason=outcome.reason)
        return outcome.status

    def terminate(self, new_status: Status) -> None:
        """Interrupted while its step runs (a timeout, or the tree left the branch): drop the step.

        A step not yet started is cancelled; a running one finishes in the background and
        the run's later steps do not wait for it (:class:`explore.runtime.run.Worker`).
        """
        if new_status == Status.INVALID and self._future is not None:
            self.context.abandon(self._future, self.name)
            self._future = None

    # -- work --------------------------------------------------------------------------------
    def _guarded(self) -> Outcome:
        try:
            outcome = self.work()
        except BadInput:
            raise
        except MissingInput as missing:
            return failure(self._missing(str(missing)))
        except Exception as error:  # noqa: BLE001 - a failing step fails the node with its reason
            self.context.trace(
                "exception", node=self.name, error=f"{type(error).__name__}: {error}", traceback=traceback.format_exc()
            )
            return failure(f"{type(error).__name__}: {error}")
        if outcome is None:
            return success()
        if isinstance(outcome, Outcome):
            return outcome
        if isinstance(outcome, Status):
            return Outcome(outcome)
        raise TypeError(f"{type(self).__name__}.work returned {outcome!r}")

    @abstractmethod
    def work(self) -> Outcome | Status | None:
        """Do the step; return an Outcome (None means success)."""

    # -- blackboard helpers ----------------------------------------------------------------------
    def read(self, key: str, default: Any = None) -> Any:
        """The value of a declared blackboard key, ``default`` when none has been written."""
        try:
            return self.bb.get(key)
        except KeyError:
            return default

    def need(self, key: str) -> Any:
        """A key this behaviour reads that an earlier step must have written: when none has, the step
        fails naming the behaviours that write it (a tree that runs them later or not at all)."""
        value = self.read(key)
        if value is None:
            raise MissingInput(key)
        return value

    def _missing(self, key: str) -> str:
        registry = getattr(self.context, "registry", None)
        writers = [info.name for info in (registry.of_kind("behaviour") if registry is not None else [])
                   if key in getattr(info.factory, "writes", ())]
        return (f"needs '{key}', which no step before it has written"
                + (f" (written by {', '.join(writers)})" if writers else ""))

    def write(self, key: str, value: Any) -> None:
        """Set a declared blackboard key."""
        self.bb.set(key, value, overwrite=True)
