"""Recognition hypotheses and what makes one acceptable: the models of the database, a hypothesis (model,
world_T_model, quality q_h), the q_h threshold (Kriegel: the best hypothesis is accepted if q_h > threshold;
the value is unpublished, we use 0.5: on the tabletop overview right matches score 0.84-0.98 and the best
wrong ones 0.02-0.25, see benchmarks/scene.py), and the rivals that make a recognition ambiguous (a second
model or a second pose that explains the data almost as well), which the scene exploration resolves with more
views.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, pose_error, reaches
from explore.mapping import sample_surface
from explore.perception.colour import COLOUR_KIND, ColourSignature
from explore.sim import Scan, TriMesh

ScanSource = Scan | Sequence[Scan] | Mapping[int, Scan]

#: q_h acceptance threshold (Kriegel Eq. 3.10; value [UNSPEC] in the thesis, chosen from the
#: measured gap between right (>= 0.84) and wrong (<= 0.25) matches on the tabletop)
Q_H_MIN = 0.5

#: N_m/N_r from which the model's rendering counts as confirmed although the cluster holds more
#: (another object touching it): right matches 0.92-0.98, wrong ones <= 0.71 on the tabletop
RENDER_FIT_MIN = 0.9


@dataclass
class Model:
    """A database object: its mesh in the object frame and stored descriptors (kind -> (array, params))."""

    name: str
    mesh: TriMesh
    descriptors: dict[str, tuple[np.ndarray, dict[str, Any]]] = field(default_factory=dict)

    @property
    def diameter(self) -> float:
        lo, hi = self.mesh.bounds
        return float(np.linalg.norm(hi - lo))

    @property
    def colour(self) -> ColourSignature | None:
        """The colours stored with the model (None: stored without colour, e.g. learned by a depth-only sensor)."""
        stored = self.descriptors.get(COLOUR_KIND)
        return None if stored is None else ColourSignature.from_array(stored[0])

    def key(self) -> tuple[str, int, float]:
        """Identity for caches: name, vertex count and a checksum of the vertices."""
        return self.name, len(self.mesh.vertices), float(np.round(np.abs(self.mesh.vertices).sum(), 6))


@dataclass(frozen=True)
class Hypothesis:
    """A recognised object: model name, world_T_model, quality in [0, 1] (higher is better)."""

    model: str
    pose: Pose
    quality: float
    method: str
    diagnostics: dict[str, Any] = field(default_factory=dict)

    @property
    def q_h(self) -> float:
        """The render-and-compare score (Eq. 3.10), NaN if it was not computed (no scans)."""
        return float(self.diagnostics.get("q_h", math.nan))

    @property
    def render_fit(self) -> float:
        """N_m / N_r: the share of the model's rendered pixels the data confirms (NaN without scans)."""
        rendered = self.diagnostics.get("N_r")
        return float(self.diagnostics["N_m"]) / rendered if rendered else math.nan


def accepted(
    hypotheses: Sequence[Hypothesis], min_q_h: float = Q_H_MIN, min_render_fit: float = RENDER_FIT_MIN,
    min_matched: int = 100,
) -> list[Hypothesis]:
    """The hypotheses whose q_h reaches ``min_q_h`` (Kriegel Eq. 3.10), in their order.

    Extension for touching objects (Görner's assumption 3 broken): a hypothesis whose rendering
    the data confirms (N_m/N_r >= ``min_render_fit``, at least ``min_matched`` pixels) is
    accepted as a *partial* match even with a low q_h -- the model is there, the rest of the
    cluster is something else (the scene session splits it off). A hypothesis without q_h
    (recognised without scans to render into) is never accepted.
    """
    out = []
    for h in hypotheses:
        if not math.isfinite(h.q_h):
            continue
        partial = h.render_fit >= min_render_fit and h.diagnostics.get("N_m", 0) >= min_matched
        if reaches(h.q_h, min_q_h) or partial:
            out.append(h)
    return out


def surface_distances(mesh: TriMesh, pose_a: Pose, pose_b: Pose, samples: int = 600,
                      onto: TriMesh | None = None) -> Array:
    """Distances (m) from ``samples`` points of the model surface at ``pose_a`` to the surface at ``pose_b``
    (or to ``onto`` at ``pose_b``: another object's surface).

    Their mean is the symmetric-object pose error (ADD-S): zero for two poses that put the
    surface in the same place, such as a plain cube turned by 90 degrees. Point-to-mesh
    distances (Open3D ``RaycastingScene.compute_distance``), so sampling adds no error.
    """
    points, _ = sample_surface(mesh, max(mesh.area(), 1e-12) / samples, seed=1)
    return distance_to_model(mesh if onto is None else onto, pose_b, points @ pose_a[:3, :3].T + pose_a[:3, 3])


def surfaces_coincide(mesh: TriMesh, pose_a: Pose, pose_b: Pose, within: float = 0.003) -> bool:
    """Whether two poses of a model put its surface in the same place: 95 % of it within ``within`` m.

    A symmetric object's turned poses coincide (a capsule turned half a turn about its axis), so
    they are one explanation of what was seen. A hidden mug handle moves only 5 % of the surface,
    so the 95th percentile (6 mm there) and not the mean (3 mm) decides.
    """
    return bool(np.percentile(surface_distances(mesh, pose_a, pose_b), 95) < within)


def distance_to_model(mesh: TriMesh, pose: Pose, points: Points3) -> Array:
    """Distance (m, (n,)) of world ``points`` to a model's surface (``mesh``, object frame) placed at ``pose``."""
    import open3d as o3d

    query = o3d.core.Tensor(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    return raycasting_scene(mesh, pose).compute_distance(query).numpy().astype(np.float64)


def rivals(
    hypotheses: Sequence[Hypothesis],
    ratio: float = 0.8,
    translation: float = 0.01,
    rotation_deg: float = 5.0,
    meshes: Mapping[str, TriMesh] | None = None,
    same_surface: float = 0.003,
) -> list[Hypothesis]:
    """Hypotheses that compete with the one of highest q_h (the recognition is then ambiguous).

    A rival has q_h >= ``ratio`` x the best q_h and either names another model or puts the same
    model at a pose more than ``translation`` m or ``rotation_deg`` away (the fusion radius of
    :func:`explore.perception.fuse_poses`): e.g. a mug whose handle is hidden, which fits the
    cylinder at any rotation about its axis. With ``meshes`` a second pose that puts the
    model's surface where the first does (:func:`surfaces_coincide` within ``same_surface``: a
    symmetric object) is the same explanation, not a rival.
    """
    ordered = sorted(hypotheses, key=lambda h: -h.q_h)
    if not ordered:
        return []
    best = ordered[0]
    out = []
    for h in ordered[1:]:
        if not h.q_h >= ratio * best.q_h:
            continue
        if h.model != best.model:
            out.append(h)
            continue
        t_err, r_err = pose_error(h.pose, best.pose)
        r_err = math.degrees(r_err)
        if t_err <= translation and r_err <= rotation_deg:
            continue
        if meshes is not None and h.model in meshes and surfaces_coincide(
                meshes[h.model], h.pose, best.pose, same_surface):
            continue
        out.append(h)
    return out


# -- rendering and verification -----------------------------------------------------------
def raycasting_scene(mesh: TriMesh, pose: Pose | None = None):  # -> o3d.t.geometry.RaycastingScene
    import open3d as o3d

    vertices = mesh.vertices if pose is None else mesh.vertices @ pose[:3, :3].T + pose[:3, 3]
    tmesh = o3d.t.geometry.TriangleMesh()
    tmesh.vertex.positions = o3d.core.Tensor(vertices.astype(np.float32))
    tmesh.triangle.indices = o3d.core.Tensor(mesh.triangles.astype(np.int32))
    scene = o3d.t.geometry.RaycastingScene(nthreads=1)
    scene.add_triangles(tmesh)
    return scene
