"""Runtime: the plugin registry and hooks, behaviour trees, runs and their outputs, comparisons and
reports.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.runtime.behaviour import ExploreBehaviour, Outcome, failure, success
from explore.runtime.compare import compare
from explore.runtime.compare_grid import RESULTS_FILE, Grid, OnDone, RunSpec
from explore.runtime.compare_results import complete_metrics, read_results
from explore.runtime.executor import Executor
from explore.runtime.hookspecs import ENTRY_POINT_GROUP, hookimpl
from explore.runtime.isolated_runs import make_registry, run_isolated, run_local
from explore.runtime.outputs import ModellingOutputs, object_result, tree_dot, write_tree_diagram
from explore.runtime.registry import KINDS, Registry
from explore.runtime.report import write_report
from explore.runtime.report_tables import step_times
from explore.runtime.run import execute
from explore.runtime.run_inputs import RunConfig, attach_plugins, check_inputs, default_out_dir
from explore.runtime.rundiff import comparable, differences, load_run, run_differences
from explore.runtime.trees import build, find_tree, list_trees, load_tree

__all__ = [
    "ENTRY_POINT_GROUP",
    "Executor",
    "ExploreBehaviour",
    "Grid",
    "KINDS",
    "ModellingOutputs",
    "OnDone",
    "Outcome",
    "RESULTS_FILE",
    "Registry",
    "RunConfig",
    "RunSpec",
    "attach_plugins",
    "build",
    "check_inputs",
    "comparable",
    "compare",
    "complete_metrics",
    "default_out_dir",
    "differences",
    "execute",
    "failure",
    "find_tree",
    "hookimpl",
    "list_trees",
    "load_run",
    "load_tree",
    "make_registry",
    "object_result",
    "read_results",
    "run_differences",
    "run_isolated",
    "run_local",
    "step_times",
    "success",
    "tree_dot",
    "write_report",
    "write_tree_diagram",
]
