"""Scene exploration: the scene session (segment, recognise, validate, model, store), its motion,
views, patrol and metrics.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.scene.metrics import model_truth, pose_graph_errors
from explore.scene.motion import Mover
from explore.scene.patrol import known_tables, surround
from explore.scene.scene_objects import FLOOR, close_holes, environment_reference
from explore.scene.session import SceneSession
from explore.scene.settings import SceneSettings

__all__ = [
    "FLOOR",
    "Mover",
    "SceneSession",
    "SceneSettings",
    "close_holes",
    "environment_reference",
    "known_tables",
    "model_truth",
    "pose_graph_errors",
    "surround",
]
