"""Next-best-view: candidates, scan planning, Kriegel's next-best-scan modelling session and
Vasquez-Gomez view/state planning.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.nbv.candidates import (
    BETAS_DEG,
    CONTINUE,
    STOP,
    SWITCH,
    Candidate,
    CandidateStack,
    Decision,
    PlanningContext,
    RepairSettings,
    above_support,
    any_sweep,
    clip_above,
    collision_free_share,
    frame_from,
    make_target,
    path_over,
    repair,
    rotation,
    segments_hit_boxes,
)
from explore.nbv.expected_utility import ObstacleField, StateSamples, expected_utility, rollout_batch, samples_needed
from explore.nbv.modelling import ModellingSession
from explore.nbv.modelling_records import resolve_strategy
from explore.nbv.nbvs import NBVSSession
from explore.nbv.scan_planning import DEFAULT_PLANNER
from explore.nbv.view_states import STAGES, ViewRecord, default_planner

__all__ = [
    "BETAS_DEG",
    "CONTINUE",
    "Candidate",
    "CandidateStack",
    "DEFAULT_PLANNER",
    "Decision",
    "ModellingSession",
    "NBVSSession",
    "ObstacleField",
    "PlanningContext",
    "RepairSettings",
    "STAGES",
    "STOP",
    "SWITCH",
    "StateSamples",
    "ViewRecord",
    "above_support",
    "any_sweep",
    "clip_above",
    "collision_free_share",
    "default_planner",
    "expected_utility",
    "frame_from",
    "make_target",
    "path_over",
    "repair",
    "resolve_strategy",
    "rollout_batch",
    "rotation",
    "samples_needed",
    "segments_hit_boxes",
]
