"""Progress lines of a run: what changed, and a heartbeat while a long step works.

A run prints a line when its status line changes (a scan integrated, a view taken, an object
recognised), when the running step reports what it is doing (:meth:`RunContext.progress`:
"expected utility: 12 of 40 candidates", "pose graph: 9 views"), and otherwise every
``heartbeat_s`` seconds while a step runs, naming the step and how long it has been at it. The
tree is ticked every 0.1 s while a step works in the run's worker thread, so no run stays
silent for long; a step that blocks the tick itself is what the silence test catches.
"""

from __future__ import annotations

from typing import Any

HEARTBEAT_S = 2.0


class ProgressLines:
    """Called on every tick with (root, context); returns the line to show, or None."""

    def __init__(self, heartbeat_s: float = HEARTBEAT_S) -> None:
        self.heartbeat_s = heartbeat_s
        self.status = ""
        self.activity = ""
        self.printed_at = 0.0
        self.step = ""
        self.step_since = 0.0
        self.times: list[float] = []  # when each line was shown (seconds since the run started)

    def __call__(self, root: Any, context: Any) -> str | None:
        now = context.elapsed()
        tip = root.tip() if root is not None else None
        step = tip.name if tip is not None and tip.status.value == "RUNNING" else ""
        if step != self.step:
            self.step, self.step_since = step, now
        text = None
        if context.status_line and context.status_line != self.status:
            self.status = text = context.status_line
        elif context.activity and context.activity != self.activity:
            self.activity = context.activity
            text = f"{step}: {context.activity}" if step else context.activity
        elif step and now - self.printed_at >= self.heartbeat_s:
            text = f"{step}: {context.activity or 'working'} ({now - self.step_since:.0f} s in this step)"
        if text is None:
            return None
        self.printed_at = now
        self.times.append(now)
        return f"[{now:6.1f} s] {text}"

    def longest_silence(self, end: float) -> float:
        """The longest time without a line, up to ``end`` (seconds since the run started)."""
        marks = [0.0, *self.times, end]
        return max(b - a for a, b in zip(marks, marks[1:], strict=False))
