"""Scan candidates, the candidate stack, the planning context and occlusion/collision repair.

A candidate is a single view (a 4x4 world_T_sensor pose, for area sensors) or a linear
scan path (:class:`~explore.sim.scan.ScanPath`, for line sensors), together with the surface
part it was made for (``focus`` points and the boundary / hole direction). Sensor frames
follow OpenCV: z looks forward; a line sensor's fan lies in its x-z plane and a scan path
moves along its y axis (the thesis frame has x left, y up; only the names differ).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Array, Points3, Pose
from explore.mapping import first_blocked
from explore.sim import ScanPath

if TYPE_CHECKING:
    from explore.mapping import VoxelGrid
    from explore.sim import RaySensor

CONTINUE, SWITCH, STOP, FALLBACK = "continue", "switch", "stop", "fallback"


@dataclass(frozen=True)
class Decision:
    """What a termination rule decided: ``continue``, ``switch`` (mode), ``fallback`` (scan the best of the
    fallback generator's candidates next) or ``stop``, and why."""

    action: str = CONTINUE
    reason: str = ""
    outcome: str = ""  # for a stop: SUCCESS (the goal is met), BUDGET or NO_CANDIDATES (explore.core.outcomes)
    margin: float = float("nan")  # how far the measure was from the rule's threshold (> 0: beyond it)

    @property
    def stop(self) -> bool:
        return self.action == STOP


@dataclass
class Candidate:
    """One next-best-scan candidate.

    Attributes
    ----------
    target : (4, 4) pose or ScanPath
    source : name of the generator that made it ("boundary", "hole", "sphere", ...)
    info : what it is for: ``kind``, boundary type / hole id, direction, ...
    focus : (k, 3) surface points the candidate must see (boundary or hole vertices), or None
    created : iteration in which it was generated
    score : last utility value (NaN before scoring)
    diagnostics : the utility's intermediate numbers (entropy, counts, ...)
    """

    target: Pose | ScanPath
    source: str
    info: dict[str, Any] = field(default_factory=dict)
    focus: Points3 | None = None
    created: int = 0
    score: float = float("nan")
    diagnostics: dict[str, float] = field(default_factory=dict)
    beams_cache: Any = field(default=None, repr=False, compare=False)  # the utilities' simulated beams

    @property
    def pose(self) -> Pose:
        """The view pose (the middle of a scan path)."""
        return self.target.mid if isinstance(self.target, ScanPath) else self.target

    @property
    def start(self) -> Pose:
        return self.target.start if isinstance(self.target, ScanPath) else self.target

    @property
    def length(self) -> float:
        return self.target.length if isinstance(self.target, ScanPath) else 0.0


class CandidateStack:
    """Unselected candidates kept across iterations (IROS 2012 Sec. III-B).

    Candidates older than ``max_age`` iterations and candidates whose view is close to an
    executed one are stale and dropped.
    """

    def __init__(self, max_age: int = 10, position_tol: float = 0.02, angle_tol_deg: float = 15.0) -> None:
        self.items: list[Candidate] = []
        self.max_age = max_age
        self.position_tol = position_tol
        self.angle_tol = np.deg2rad(angle_tol_deg)

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self):  # noqa: ANN204
        return iter(self.items)

    def push(self, candidates: list[Candidate]) -> None:
        self.items.extend(candidates)

    def clear(self, source: str | None = None) -> int:
        """Remove every candidate (of one source); returns how many were removed."""
        before = len(self.items)
        self.items = [c for c in self.items if source is not None and c.source != source]
        return before - len(self.items)

    def pop(self, index: int) -> Candidate:
        return self.items.pop(index)

    def drop_stale(self, iteration: int, executed: list[Pose] | None = None, keep_sources: tuple = ()) -> int:
        """Drop old candidates and those that repeat an executed view; returns the count."""
        before = len(self.items)
        kept = []
        for cand in self.items:
            if cand.source in keep_sources:
                kept.append(cand)
                continue
            if self.max_age and iteration - cand.created > self.max_age:
                continue
            if executed and any(self._similar(cand.pose, pose) for pose in executed):
                continue
            kept.append(cand)
        self.items = kept
        return before - len(kept)

    def _similar(self, a: Pose, b: Pose) -> bool:
        if np.linalg.norm(a[:3, 3] - b[:3, 3]) > self.position_tol:
            return False
        return float(np.dot(a[:3, 2], b[:3, 2])) > np.cos(self.angle_tol)


@dataclass
class PlanningContext:
    """Everything a view generator, utility or termination may read (no ground truth).

    Attributes
    ----------
    pvs, surface : the probabilistic voxel space and the surface model
    grid : dense snapshot of the PVS with surface features (:class:`VoxelGrid`), refreshed
        after every integration
    sensor, robot : the sensor and robot plugins
    region_min, region_max : the region of interest (the unknown box)
    environment_boxes : axis-aligned boxes (lo, hi) of the known environment
    iteration : scans taken so far (n_s)
    last_scan : the latest Scan
    executed : world_T_sensor poses of the scans taken (middle of the path)
    sensor_pose : current sensor pose
    coverage_history : ĉ_m after each scan
    off_support_history : ĉ_m after each scan without the opening at the support (the region floor)
    density_history : d̄_m after each scan
    unknown_history : unknown voxels in the region after each scan
    mode : the generator mode ("boundary" or "hole" for boundary_hole)
    best_score_diagnostics : diagnostics of the last selected candidate
    rng : the session's random generator
    support_margin : how far below the support plane (the region floor) a sensor may go
    standoff : the sensor distance of the views (:func:`modelling_standoff`); 0: the sensor's
        optimal distance
    registry : the plugin registry (for plugins that build the plugins they wrap)
    """

    pvs: Any
    surface: Any
    grid: VoxelGrid
    sensor: RaySensor
    robot: Any
    region_min: Array
    region_max: Array
    environment_boxes: list[tuple[Array, Array]] = field(default_factory=list)
    iteration: int = 0
    last_scan: Any = None
    executed: list[Pose] = field(default_factory=list)
    sensor_pose: Pose | None = None
    coverage_history: list[float] = field(default_factory=list)
    off_support_history: list[float] = field(default_factory=list)
    fallback_scans: int = 0  # scans of candidates from the session's fallback generator
    fallback_available: bool = False  # the session has a fallback generator (a FALLBACK decision offers it)
    density_history: list[float] = field(default_factory=list)
    unknown_history: list[int] = field(default_factory=list)
    mode: str = "boundary"
    stack: CandidateStack | None = None
    best_diagnostics: dict[str, float] = field(default_factory=dict)
    available: int = 0  # candidates on the stack before the last selection
    exhausted: bool = False  # the strategy's own generator left no candidate (a fallback's may be on the stack)
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    support_margin: float = 0.02
    standoff: float = 0.0
    registry: Any = None

    @property
    def region_centre(self) -> Array:
        return 0.5 * (np.asarray(self.region_min) + np.asarray(self.region_max))

    @property
    def lowest_sensor_z(self) -> float:
        """Lowest admissible sensor height: the support plane (region floor) less ``support_margin``.

        Objects cannot be viewed from below (thesis Sec. 4.1); a sensor under the support
        would only look through it.
        """
        return float(self.region_min[2]) - self.support_margin


def standoff_for(ctx: PlanningContext, value: float = 0.0) -> float:
    """``value`` (m), or the context's standoff (else the sensor's optimal distance) when ``value`` <= 0."""
    if value > 0:
        return value
    return float(ctx.standoff) if ctx.standoff > 0 else float(ctx.sensor.optimal_distance)


def beam_spacing_distance(sensor: RaySensor, spacing: float) -> float:
    """Distance at which the sensor's central beams fall ``spacing`` apart on a surface facing it
    (inf if it has a single beam)."""
    dirs = np.asarray(sensor.local_directions(), dtype=float)
    centre = int(np.argmax(dirs[:, 2]))
    cos = dirs @ dirs[centre]
    cos[centre] = -1.0
    cos = cos[cos < 1.0 - 1e-12]  # repeated beams are no finer sampling
    if len(cos) == 0:
        return float("inf")
    return float(spacing / np.tan(np.arccos(np.clip(cos.max(), -1.0, 1.0))))


def modelling_standoff(sensor: RaySensor, spacing: float) -> float:
    """The sensor distance of modelling views: the sensor's optimal distance, or nearer where
    its beams would sample the surface more sparsely than ``spacing`` (the model's point
    spacing R_r, Kriegel thesis Sec. 4.3.1), but no nearer than 1.25 x its minimum range.

    A 160 x 120 camera over 58 degrees is 5.9 mm per pixel at the middle of a 0.2-1.5 m range:
    a model sampled that sparsely stays full of holes, so its views come to 0.29 m. The
    thesis' striper and a 640 x 480 camera are dense enough at their optimal distance.
    """
    optimal = float(sensor.optimal_distance)
    nearest = min(optimal, 1.25 * float(sensor.min_range))
    return float(max(nearest, min(optimal, beam_spacing_distance(sensor, spacing))))


def footprint_width(ctx: PlanningContext, standoff: float) -> float:
    """Width (m) that one stripe (line sensor) or the image (area sensor) covers at ``standoff``."""
    dirs = ctx.sensor.local_directions()
    half = float(np.max(np.abs(dirs[:, 0] / np.maximum(dirs[:, 2], 1e-6))))
    return 2.0 * standoff * half


def in_environment_boxes(ctx: PlanningContext, positions: Points3, clearance: float = 0.02) -> np.ndarray:
    """(n,) bool: which ``positions`` lie within ``clearance`` of a box of the known environment."""
    blocked = np.zeros(len(positions), dtype=bool)
    for lo, hi in ctx.environment_boxes:
        blocked |= np.all((positions > np.asarray(lo) - clearance) & (positions < np.asarray(hi) + clearance), axis=1)
    return blocked


# ---------------------------------------------------------------------------------------
# frames and paths
# ---------------------------------------------------------------------------------------
def frame_from(view: Array, sweep: Array, position: Array) -> Pose | None:
    """world_T_sensor with z = ``view`` and y along ``sweep`` (orthogonalised); None if parallel.

    Thesis Eq. 4.16-4.17 in OpenCV naming: the scan moves along y, the fan spans x.
    """
    z = np.asarray(view, dtype=float)
    z = z / np.linalg.norm(z)
    y = np.asarray(sweep, dtype=float) - np.dot(sweep, z) * z
    norm = np.linalg.norm(y)
    if norm < 1e-6:
        return None
    y /= norm
    x = np.cross(y, z)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, y, z])
    pose[:3, 3] = position
    return pose


def any_sweep(view: Array) -> Array:
    """A sweep direction perpendicular to ``view``: the world z axis projected, else x."""
    view = np.asarray(view, dtype=float)
    for axis in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        y = axis - np.dot(axis, view) * view
        if np.linalg.norm(y) > 0.2:
            return y / np.linalg.norm(y)
    return np.array([0.0, 1.0, 0.0])


def path_over(pose: Pose, extent_points: Points3 | None, standoff: float, speed: float,
              margin: float = 0.01, min_length: float = 0.03, max_length: float = 0.5) -> ScanPath:
    """Scan path through ``pose`` along its y axis across the extent of ``extent_points``.

    Thesis Sec. 4.3.2: the planes through the viewpoint with normal d_b (= sensor y) at the
    minimum and maximum signed distance of the mesh vertices give the two ends.
    """
    y = pose[:3, 1]
    if extent_points is None or len(extent_points) == 0:
        lo, hi = -0.5 * min_length, 0.5 * min_length
    else:
        # points in front of the sensor only, along the sweep axis
        focus = pose[:3, 3] + standoff * pose[:3, 2]
        s = (extent_points - focus) @ y
        lo, hi = float(s.min()) - margin, float(s.max()) + margin
    if hi - lo < min_length:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_length, mid + 0.5 * min_length
    if hi - lo > max_length:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * max_length, mid + 0.5 * max_length
    start, end = pose.copy(), pose.copy()
    start[:3, 3] = pose[:3, 3] + lo * y
    end[:3, 3] = pose[:3, 3] + hi * y
    return ScanPath(start, end, speed)


def make_target(sensor: RaySensor, pose: Pose, extent_points: Points3 | None, standoff: float,
                path_margin: float = 0.01, min_length: float = 0.03) -> Pose | ScanPath:
    """A single view for area sensors, a scan path over the extent for line sensors."""
    if sensor.geometry != "line":
        return pose
    return path_over(pose, extent_points, standoff, getattr(sensor, "speed", 0.05), path_margin, min_length)


def rotation(axis: Array, angle: float) -> Array:
    """R(a, beta) = a a^T + cos(beta)(I - a a^T) + sin(beta) A (thesis Eq. 4.29, Rodrigues)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    outer = np.outer(a, a)
    return outer + np.cos(angle) * (np.eye(3) - outer) + np.sin(angle) * skew


# ---------------------------------------------------------------------------------------
# occlusion / collision tests and Algorithm 3
# ---------------------------------------------------------------------------------------
def sample_positions(target: Pose | ScanPath, count: int = 5) -> Points3:
    """Sensor positions sampled along a target (one for a single view)."""
    if not isinstance(target, ScanPath):
        return np.asarray(target)[None, :3, 3]
    s = np.linspace(0.0, 1.0, count)[:, None]
    return target.start[:3, 3] + s * (target.end[:3, 3] - target.start[:3, 3])


def segments_hit_boxes(starts: Points3, ends: Points3, boxes: list[tuple[Array, Array]]) -> np.ndarray:
    """Mask of the segments start->end that pass through any axis-aligned box (lo, hi) (slab test)."""
    starts = np.asarray(starts, dtype=float).reshape(-1, 3)
    delta = np.asarray(ends, dtype=float).reshape(-1, 3) - starts
    hit = np.zeros(len(starts), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / delta
        for lo, hi in boxes:
            t1 = (np.asarray(lo) - starts) * inv
            t2 = (np.asarray(hi) - starts) * inv
            t1 = np.where(np.isnan(t1), -np.inf, t1)
            t2 = np.where(np.isnan(t2), np.inf, t2)
            enter = np.max(np.minimum(t1, t2), axis=1)
            leave = np.min(np.maximum(t1, t2), axis=1)
            hit |= (enter <= leave) & (leave >= 0.0) & (enter <= 1.0)
    return hit


def above_support(target: Pose | ScanPath, lowest_z: float) -> bool:
    """True if the sensor stays at or above ``lowest_z`` along the whole target (thesis Sec. 4.1)."""
    return bool(np.all(sample_positions(target, 2)[:, 2] >= lowest_z))


def clip_above(target: Pose | ScanPath, lowest_z: float, min_length: float = 0.03) -> Pose | ScanPath | None:
    """The part of a target above ``lowest_z``: a scan path is shortened, a view kept or dropped.

    Returns None if less than ``min_length`` of a path (or no view) remains.
    """
    if not isinstance(target, ScanPath):
        return target if above_support(target, lowest_z) else None
    a, b = target.start[:3, 3], target.end[:3, 3]
    za, zb = float(a[2]), float(b[2])
    if za >= lowest_z and zb >= lowest_z:
        return target
    if za < lowest_z and zb < lowest_z:
        return None
    s = (lowest_z - za) / (zb - za)  # where the path crosses the limit
    cut = a + s * (b - a)
    start, end = target.start.copy(), target.end.copy()
    if za < lowest_z:
        start[:3, 3] = cut
    else:
        end[:3, 3] = cut
    if np.linalg.norm(end[:3, 3] - start[:3, 3]) < min_length:
        return None
    return ScanPath(start, end, target.speed)


def occlusion_free_share(grid: VoxelGrid, target: Pose | ScanPath, focus: Points3, p_block: float = 0.95,
                         samples: int = 5, margin: float | None = None) -> float:
    """Share of (sensor sample, focus point) lines of sight not blocked in the PVS (Alg. 3).

    A focus point counts as reached from a sample if no voxel with p >= ``p_block`` lies on
    the line before the last ``margin`` (default 1.5 voxels) in front of the point. Each
    focus point is tested from the sample nearest to it along the path.
    """
    if focus is None or len(focus) == 0:
        return 1.0
    margin = 1.5 * grid.resolution if margin is None else margin
    positions = sample_positions(target, samples)
    # nearest sample along the path for each focus point
    nearest = np.argmin(np.linalg.norm(focus[:, None, :] - positions[None, :, :], axis=2), axis=1)
    origins = positions[nearest]
    delta = focus - origins
    dist = np.linalg.norm(delta, axis=1)
    dirs = delta / np.maximum(dist[:, None], 1e-9)
    t = first_blocked(grid, origins, dirs, np.maximum(dist - margin, 0.0), p_block)
    return float(np.mean(~np.isfinite(t)))


def collision_free_share(grid: VoxelGrid, target: Pose | ScanPath, clearance: float = 0.02,
                         p_free: float = 0.25, environment_boxes: list | None = None, portions: int = 10) -> float:
    """Share of path portions whose sensor position keeps ``clearance`` from non-free voxels.

    Voxels at p >= ``p_free`` (unknown or occupied) are obstacles (Vasquez-Gomez: unknown
    space is an obstacle); positions inside an inflated environment box collide.
    """
    positions = sample_positions(target, portions + 1)
    offsets = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=3))) * clearance
    probe = (positions[:, None, :] + offsets[None]).reshape(-1, 3)
    blocked = (grid.lookup(probe, outside=0.0) >= p_free).reshape(len(positions), -1).any(axis=1)
    for lo, hi in environment_boxes or []:
        inside = np.all((positions > np.asarray(lo) - clearance) & (positions < np.asarray(hi) + clearance), axis=1)
        blocked |= inside
    return float(np.mean(~blocked))


BETAS_DEG = (0, 10, -10, 20, -20, 30, -30, 40, -40)


@dataclass
class RepairSettings:
    """Algorithm 3 settings: accept at >= 50 % un-occluded and >= 50 % collision-free."""

    betas_deg: tuple[int, ...] = BETAS_DEG
    min_visible: float = 0.5
    min_free: float = 0.5
    clearance: float = 0.02
    p_block: float = 0.95


def repair(candidate: Candidate, ctx: PlanningContext, anchor: Array, standoff: float,
           extent_points: Points3 | None, settings: RepairSettings = RepairSettings()) -> Candidate | None:
    """Occlusion/collision replanning (thesis Sec. 4.5.2, Algorithm 3).

    Rotates the viewing direction s_z about s_x (outer loop) and s_y (inner loop) by 0, ±10,
    ..., ±40 degrees, recomputes the frame (Eq. 4.16-4.17) and the path ends (Eq. 4.18)
    around ``anchor`` (the surface part of interest), and returns the first candidate that
    is occlusion-free and collision-free (cheap occlusion test first), or None. A target that
    takes the sensor below the support plane counts as colliding (thesis Sec. 4.1).
    """
    base = candidate.pose
    s_x, s_y, s_z = base[:3, 0], base[:3, 1], base[:3, 2]
    focus = candidate.focus
    for bx in settings.betas_deg:
        rx = rotation(s_x, np.deg2rad(bx))
        for by in settings.betas_deg:
            z = rotation(s_y, np.deg2rad(by)) @ rx @ s_z
            if bx == 0 and by == 0:
                target = candidate.target
            else:
                pose = frame_from(z, s_y, np.asarray(anchor) - standoff * z)
                if pose is None:
                    continue
                target = make_target(ctx.sensor, pose, extent_points, standoff)
            if not above_support(target, ctx.lowest_sensor_z):
                continue
            visible = 1.0 if focus is None else occlusion_free_share(ctx.grid, target, focus, settings.p_block)
            if visible < settings.min_visible:
                continue
            if collision_free_share(ctx.grid, target, settings.clearance, environment_boxes=ctx.environment_boxes) \
                    < settings.min_free:
                continue
            if bx == 0 and by == 0:
                return candidate
            info = dict(candidate.info, repaired_deg=(bx, by))
            return Candidate(target, candidate.source, info, focus, candidate.created)
    return None
