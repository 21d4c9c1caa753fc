"""Foundations every layer uses: errors, typed arrays, parameters, user files and output paths,
outcomes, decisions with margins, determinism, SE(3) geometry, pictures.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.core.decisions import TIE, pick_best, reaches
from explore.core.determinism import THREAD_VARIABLES, open3d_serial, set_threads
from explore.core.errors import (
    MAX_LINE,
    BadInput,
    MissionFailed,
    PluginCheckFailed,
    RegistryError,
    Terminated,
    brief,
    valid_names,
)
from explore.core.geometry import (
    fibonacci_sphere,
    invert,
    kabsch,
    look_at,
    mean_pose,
    mean_rotation,
    parse_vector,
    pose_error,
    pose_from,
    project_rotation,
    quaternion_xyzw,
    rotation_angle,
    rpy_deg_to_matrix,
    transform_points,
    wrap_angle,
)
from explore.core.native_output import captured_output
from explore.core.outcomes import BUDGET, FAILURE, FINISHED, INTERRUPTED, NO_CANDIDATES, STYLE, SUCCESS
from explore.core.output_paths import check_output
from explore.core.params import Param, parse_assignment, validate_params
from explore.core.pictures import equal_axes, plt, save_curves_png, save_mesh_png, save_points_png
from explore.core.plugin import Plugin
from explore.core.typed import Array, Points3, Pose
from explore.core.user_files import OBJECT_NAME, OBJECT_NAME_RULE, check_path_name, load_yaml, read_text

__all__ = [
    "Array",
    "BUDGET",
    "BadInput",
    "FAILURE",
    "FINISHED",
    "INTERRUPTED",
    "MAX_LINE",
    "MissionFailed",
    "PluginCheckFailed",
    "NO_CANDIDATES",
    "OBJECT_NAME",
    "OBJECT_NAME_RULE",
    "Param",
    "Plugin",
    "Points3",
    "Pose",
    "RegistryError",
    "STYLE",
    "SUCCESS",
    "THREAD_VARIABLES",
    "TIE",
    "Terminated",
    "brief",
    "captured_output",
    "check_output",
    "check_path_name",
    "equal_axes",
    "fibonacci_sphere",
    "invert",
    "kabsch",
    "load_yaml",
    "look_at",
    "mean_pose",
    "mean_rotation",
    "open3d_serial",
    "parse_assignment",
    "parse_vector",
    "pick_best",
    "plt",
    "pose_error",
    "pose_from",
    "project_rotation",
    "quaternion_xyzw",
    "reaches",
    "read_text",
    "rotation_angle",
    "rpy_deg_to_matrix",
    "save_curves_png",
    "save_mesh_png",
    "save_points_png",
    "set_threads",
    "transform_points",
    "valid_names",
    "validate_params",
    "wrap_angle",
]
