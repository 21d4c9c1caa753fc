"""How a run ended, in the words its ``status`` uses (``metrics.json``, ``results.csv``, the CLI).

``success`` only when the mission's goal was met; a run that used up its budget or ran out of
things to try says so. Exit codes: 0 success, 1 any other end of the mission, 2 bad input,
130 interrupted (SIGINT), 143 terminated (SIGTERM).
"""

from __future__ import annotations

SUCCESS = "success"  # the goal was met (coverage target, every cluster explained, ...)
BUDGET = "budget_exhausted"  # the scan / view / iteration budget was used up first
NO_CANDIDATES = "no_candidates"  # nothing left to try: no candidate, none reachable, no progress left
FAILURE = "failure"  # a step failed: a collision, no first view, a branch of the tree, a crash
INTERRUPTED = "interrupted"  # SIGINT or SIGTERM; the results so far are written

FINISHED = (SUCCESS, BUDGET, NO_CANDIDATES, FAILURE)  # the run reached an end of its own
STATUSES = (*FINISHED, INTERRUPTED)
STYLE = {SUCCESS: "green", BUDGET: "yellow", NO_CANDIDATES: "yellow", FAILURE: "red", INTERRUPTED: "magenta"}
