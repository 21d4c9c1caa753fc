"""Next-best-view: candidates, scan planning, Kriegel's next-best-scan modelling session and
Vasquez-Gomez view/state planning.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.nbv.area_factor import AreaFactor
from explore.nbv.candidates import (
    BETAS_DEG,
    CONTINUE,
    FALLBACK,
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
    footprint_width,
    frame_from,
    in_environment_boxes,
    make_target,
    modelling_standoff,
    path_over,
    repair,
    rotation,
    segments_hit_boxes,
    standoff_for,
)
from explore.nbv.expected_utility import (
    ObstacleField,
    StateSamples,
    colliding_rollouts,
    expected_utility,
    samples_needed,
)
from explore.nbv.modelling import ModellingSession
from explore.nbv.modelling_records import resolve_strategy
from explore.nbv.nbvs import NBVSSession
from explore.nbv.strategy import OVERRIDES, Strategy, StrategyPlugin, make_strategy
from explore.nbv.termination import Termination
from explore.nbv.utility import RAY_PARAMS, RayUtility, Utility, beams_of, candidate_beams, non_free_count
from explore.nbv.view_generator import ViewGenerator
from explore.nbv.view_states import STAGES, ViewRecord

__all__ = [
    "AreaFactor",
    "BETAS_DEG",
    "CONTINUE",
    "Candidate",
    "CandidateStack",
    "Decision",
    "ModellingSession",
    "NBVSSession",
    "OVERRIDES",
    "ObstacleField",
    "PlanningContext",
    "RAY_PARAMS",
    "RayUtility",
    "RepairSettings",
    "STAGES",
    "STOP",
    "FALLBACK",
    "SWITCH",
    "StateSamples",
    "Strategy",
    "StrategyPlugin",
    "Termination",
    "Utility",
    "ViewGenerator",
    "ViewRecord",
    "above_support",
    "any_sweep",
    "beams_of",
    "candidate_beams",
    "clip_above",
    "colliding_rollouts",
    "expected_utility",
    "footprint_width",
    "frame_from",
    "in_environment_boxes",
    "make_strategy",
    "make_target",
    "non_free_count",
    "path_over",
    "repair",
    "resolve_strategy",
    "rotation",
    "samples_needed",
    "segments_hit_boxes",
    "modelling_standoff",
    "standoff_for",
]
