"""Decorators the tree format needs beyond py_trees' own."""

from __future__ import annotations

import py_trees
from py_trees.common import Status


class RepeatUntil(py_trees.decorators.Decorator):
    """Tick the child again after each success until a blackboard flag is true.

    A failing child fails the loop (with the child's reason). After ``max_iterations``
    successful iterations the loop ends with ``on_max`` ("success" or "failure").
    """

    def __init__(
        self, name: str, child: py_trees.behaviour.Behaviour, until_key: str, max_iterations: int, on_max: str
    ) -> None:
        super().__init__(name=name, child=child)
        self.until_key = until_key
        self.max_iterations = max_iterations
        self.on_max = on_max
        self.iterations = 0
        self.blackboard = self.attach_blackboard_client(name=f"{name} (until)")
        self.blackboard.register_key(until_key, access=py_trees.common.Access.READ)

    def initialise(self) -> None:
        self.iterations = 0

    def _done(self) -> bool:
        try:
            return bool(self.blackboard.get(self.until_key))
        except KeyError:
            return False

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.FAILURE:
            self.feedback_message = self.decorated.feedback_message
            return Status.FAILURE
        if status != Status.SUCCESS:
            return Status.RUNNING
        self.iterations += 1
        if self._done():
            self.feedback_message = f"done after {self.iterations} iterations"
            return Status.SUCCESS
        if self.iterations >= self.max_iterations:
            self.feedback_message = f"stopped at max_iterations={self.max_iterations}"
            return Status.SUCCESS if self.on_max == "success" else Status.FAILURE
        self.decorated.stop(Status.INVALID)  # run the body again on the next tick
        return Status.RUNNING
