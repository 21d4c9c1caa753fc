"""The public plugin API: everything a plugin package imports, and nothing else.

One base class per plugin kind states the kind's whole contract (abstract methods, typed
attributes, array shapes, frames and units in the docstrings); the built-in plugins subclass
the same classes. A package registers its plugins through the ``explore.plugins`` entry point
with a ``@hookimpl`` function ``explore_register_plugins(register)`` (and optionally
``explore_register_commands(app)`` for CLI sub-commands); see ``docs/writing-plugins.md``.

=================  =====================  ==================================================
kind               base class             the contract
=================  =====================  ==================================================
sensor             :class:`Sensor`        beams, noise (``sigma``, ``measure``), acquisition
robot              :class:`Robot`         FK/IK, collision, execution, :class:`Capability`
motion_planner     :class:`MotionPlanner` ``plan(problem, start, goal, seed)``
view_generator     :class:`ViewGenerator` ``generate(ctx) -> list[Candidate]``
utility            :class:`Utility`       ``score(candidates, ctx) -> (n,)``
termination        :class:`Termination`   ``decide(ctx) -> Decision``
strategy           :class:`StrategyPlugin` a generator + utility + termination recipe
segmenter          :class:`Segmenter`     ``segment(scans) -> Segmentation``
recognizer         :class:`Recognizer`    ``recognize(cluster, models) -> hypotheses``
pose_validator     :class:`PoseValidator` ``validate(pvs, vertices, pose) -> Validation``
registrar          :class:`Registrar`     ``register(...)``, fixed by the role's subclass
behaviour          :class:`Behaviour`     a py_trees behaviour: ``work() -> Outcome``
executor           :class:`Executor`      ``run(specs, on_done)``
=================  =====================  ==================================================
"""

from explore.core import (
    BUDGET,
    FAILURE,
    INTERRUPTED,
    NO_CANDIDATES,
    SUCCESS,
    Array,
    BadInput,
    Param,
    Points3,
    Pose,
    fibonacci_sphere,
    invert,
    kabsch,
    look_at,
    mean_pose,
    mean_rotation,
    pick_best,
    pose_error,
    pose_from,
    project_rotation,
    quaternion_xyzw,
    reaches,
    rotation_angle,
    transform_points,
    wrap_angle,
)
from explore.core.plugin import Plugin
from explore.mapping import (
    ACC_NAMES,
    ENTROPY,
    HITS,
    OCC_FIRST,
    OCCLUSION,
    PROXIMITY,
    QUAL_LIT,
    QUAL_NEED,
    REAR_ENTROPY,
    REAR_VOXEL,
    TRAVERSED,
    UNK_FIRST,
    UNKNOWN_VOXELS,
    UNOBSERVED,
    TraceSettings,
    VoxelGrid,
)
from explore.motion import (
    BulletCollider,
    BulletRobot,
    Capability,
    CollisionEvent,
    Execution,
    MotionPlan,
    MotionPlanner,
    MotionProblem,
    Part,
    Robot,
)
from explore.nbv import CONTINUE, FALLBACK, STOP, SWITCH, Candidate, Decision, PlanningContext, make_target
from explore.nbv.area_factor import AreaFactor
from explore.nbv.strategy import OVERRIDES, Strategy, StrategyPlugin, make_strategy
from explore.nbv.termination import Termination
from explore.nbv.utility import RAY_PARAMS, RayUtility, Utility, beams_of, candidate_beams, non_free_count
from explore.nbv.view_generator import ViewGenerator
from explore.perception import Cluster, DepthProcessing, Hypothesis, Model, Segmentation, Validation
from explore.perception.contracts import (
    PlaneRegistrar,
    PoseValidator,
    Recognizer,
    Registrar,
    ScansRegistrar,
    ScanToModelRegistrar,
    Segmenter,
)
from explore.runtime import KINDS, ExploreBehaviour, Outcome, failure, hookimpl, success
from explore.runtime.compare_grid import OnDone, RunSpec
from explore.runtime.executor import Executor
from explore.runtime.hookspecs import ENTRY_POINT_GROUP
from explore.sim import NOISE_MODELS, MeshWorld, RaySensor, Scan, ScanPath, Simulation, frame_pose

#: the contract of the ``sensor`` kind (:class:`explore.sim.sensing.RaySensor`)
Sensor = RaySensor
#: the contract of the ``behaviour`` kind (:class:`explore.runtime.behaviour.ExploreBehaviour`)
Behaviour = ExploreBehaviour

#: the base class of each plugin kind
CONTRACTS: dict[str, type] = {
    "sensor": Sensor,
    "robot": Robot,
    "motion_planner": MotionPlanner,
    "view_generator": ViewGenerator,
    "utility": Utility,
    "termination": Termination,
    "strategy": StrategyPlugin,
    "segmenter": Segmenter,
    "recognizer": Recognizer,
    "pose_validator": PoseValidator,
    "registrar": Registrar,
    "behaviour": Behaviour,
    "executor": Executor,
}

__all__ = [
    "ACC_NAMES",
    "BUDGET",
    "CONTINUE",
    "CONTRACTS",
    "ENTROPY",
    "ENTRY_POINT_GROUP",
    "FAILURE",
    "HITS",
    "INTERRUPTED",
    "KINDS",
    "NOISE_MODELS",
    "NO_CANDIDATES",
    "OCCLUSION",
    "OCC_FIRST",
    "OVERRIDES",
    "PROXIMITY",
    "QUAL_LIT",
    "QUAL_NEED",
    "RAY_PARAMS",
    "REAR_ENTROPY",
    "REAR_VOXEL",
    "STOP",
    "SUCCESS",
    "FALLBACK",
    "SWITCH",
    "TRAVERSED",
    "UNKNOWN_VOXELS",
    "UNK_FIRST",
    "UNOBSERVED",
    "AreaFactor",
    "Array",
    "BadInput",
    "Behaviour",
    "BulletCollider",
    "BulletRobot",
    "Candidate",
    "Capability",
    "CollisionEvent",
    "Cluster",
    "Decision",
    "DepthProcessing",
    "Execution",
    "Executor",
    "Hypothesis",
    "MeshWorld",
    "Model",
    "MotionPlan",
    "MotionPlanner",
    "MotionProblem",
    "OnDone",
    "Outcome",
    "Param",
    "Part",
    "PlaneRegistrar",
    "PlanningContext",
    "Plugin",
    "Points3",
    "Pose",
    "PoseValidator",
    "RayUtility",
    "Recognizer",
    "Registrar",
    "Robot",
    "RunSpec",
    "Scan",
    "ScanPath",
    "ScanToModelRegistrar",
    "ScansRegistrar",
    "Segmentation",
    "Segmenter",
    "Sensor",
    "Simulation",
    "Strategy",
    "StrategyPlugin",
    "Termination",
    "TraceSettings",
    "Utility",
    "Validation",
    "ViewGenerator",
    "VoxelGrid",
    "beams_of",
    "candidate_beams",
    "failure",
    "fibonacci_sphere",
    "frame_pose",
    "hookimpl",
    "invert",
    "kabsch",
    "look_at",
    "make_strategy",
    "make_target",
    "non_free_count",
    "mean_pose",
    "mean_rotation",
    "pick_best",
    "pose_error",
    "pose_from",
    "project_rotation",
    "quaternion_xyzw",
    "reaches",
    "rotation_angle",
    "success",
    "transform_points",
    "wrap_angle",
]
