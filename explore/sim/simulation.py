"""A world loaded into pybullet (DIRECT) with its ground truth for the simulated sensors.

The :class:`Simulation` owns the pybullet client, the bodies and the ground-truth meshes.
Sensors cast rays against the ground truth through :class:`RayCaster` (Open3D
``RaycastingScene``); metrics read :attr:`Simulation.ground_truth`. Planners get only
:meth:`Simulation.environment_ids` (the known static environment), never the objects.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Array, BadInput, Points3, captured_output, pose_from, rpy_deg_to_matrix
from explore.sim.bullet import body_visual_meshes, p
from explore.sim.meshes import TriMesh, box_mesh, cylinder_mesh, read_mesh, sphere_mesh
from explore.sim.world import BodySpec, WorldSpec, load_world_spec, pybullet_data_path

CONTACT_GAP = 5e-4  # m between a body and the body it rests on
MIN_OBJECT_EXTENT = 1e-3  # m: the finest sensor here (the striper) samples about 0.6 mm apart
# bodies whose surfaces cross over less than OVERLAP_TOLERANCE, or with no point deeper than
# PENETRATION_TOLERANCE in the other, touch (a ball resting in a bowl set by hand); else they intersect
OVERLAP_TOLERANCE = 0.005  # m
PENETRATION_TOLERANCE = 0.002  # m
# pybullet's createCollisionShape / createVisualShape take at most 131 072 vertices and 524 288 indices
# (B3_MAX_NUM_VERTICES / B3_MAX_NUM_INDICES of the wheel, measured); a larger mesh is reduced for pybullet
PYBULLET_MAX_VERTICES, PYBULLET_MAX_TRIANGLES = 131_072, 524_288 // 3


@dataclass(frozen=True)
class GroundTruthBody:
    name: str
    body_id: int
    mesh: TriMesh  # world frame
    is_object: bool
    known: bool
    specular: float = 0.0  # share of the light reflected as by a mirror (BodySpec.specular)


class RayCaster:
    """Casts many rays at once against triangle meshes (Open3D ``RaycastingScene``)."""

    def __init__(self, meshes: list[TriMesh], nthreads: int = 0) -> None:
        import open3d as o3d

        self._scene = o3d.t.geometry.RaycastingScene(nthreads=nthreads)
        self._geometry_to_index: dict[int, int] = {}
        for index, mesh in enumerate(meshes):
            tmesh = o3d.t.geometry.TriangleMesh()
            tmesh.vertex.positions = o3d.core.Tensor(mesh.vertices.astype(np.float32))
            tmesh.triangle.indices = o3d.core.Tensor(mesh.triangles.astype(np.int32))
            self._geometry_to_index[int(self._scene.add_triangles(tmesh))] = index
        self._lookup = np.full(max(self._geometry_to_index, default=0) + 2, -1, dtype=np.int64)
        for geometry_id, index in self._geometry_to_index.items():
            self._lookup[geometry_id] = index

    def cast(self, origins: Points3, directions: Points3) -> tuple[Array, np.ndarray, Points3]:
        """Distance to the first hit (inf if none), index of the mesh hit (-1), hit normals."""
        import open3d as o3d

        rays = np.hstack([origins, directions]).astype(np.float32)
        result = self._scene.cast_rays(o3d.core.Tensor(rays))
        t_hit = result["t_hit"].numpy().astype(np.float64)
        ids = result["geometry_ids"].numpy().astype(np.int64)
        invalid = ids >= len(self._lookup)  # INVALID_ID for misses
        index = np.where(invalid, -1, self._lookup[np.minimum(ids, len(self._lookup) - 1)])
        normals = result["primitive_normals"].numpy().astype(np.float64)
        return t_hit, index, normals

    def closest(self, points: Points3) -> tuple[Points3, Points3]:
        """The nearest surface point of every query point and the normal of its triangle (inf and 0
        with no mesh: Open3D would return uninitialised memory)."""
        import open3d as o3d

        if not self._geometry_to_index:
            return np.full((len(points), 3), np.inf), np.zeros((len(points), 3))

        result = self._scene.compute_closest_points(o3d.core.Tensor(np.asarray(points, dtype=np.float32)))
        return result["points"].numpy().astype(np.float64), result["primitive_normals"].numpy().astype(np.float64)


def over_top(mesh: TriMesh, xy: Array, tolerance: float = 1e-3) -> bool:
    """``xy`` lies over the top of ``mesh``: inside the outline of its vertices within 2 mm of its
    highest (the whole footprint when those are fewer than a face, e.g. a sphere's pole)."""
    from scipy.spatial import ConvexHull, QhullError

    vertices = mesh.vertices
    top = vertices[vertices[:, 2] >= vertices[:, 2].max() - 2e-3, :2]
    try:
        equations = ConvexHull(top).equations
    except (QhullError, ValueError):
        equations = ConvexHull(vertices[:, :2]).equations
    return bool(np.all(equations[:, :2] @ np.asarray(xy, dtype=float) + equations[:, 2] <= tolerance))


def surface_crossings(mesh: TriMesh, other: TriMesh) -> Points3:
    """Where the edges of ``mesh``'s triangles pass through ``other``'s surface (world points):
    two surfaces intersect exactly where an edge of one crosses a triangle of the other."""
    edges = np.unique(np.sort(mesh.triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    start = mesh.vertices[edges[:, 0]]
    vector = mesh.vertices[edges[:, 1]] - start
    length = np.linalg.norm(vector, axis=1)
    keep = length > 1e-9
    start, vector, length = start[keep], vector[keep], length[keep]
    direction = vector / length[:, None]
    distance, hit, _ = RayCaster([other]).cast(start, direction)
    crossed = (hit >= 0) & (distance < length)
    return start[crossed] + direction[crossed] * distance[crossed, None]


def depth_behind(mesh: TriMesh, other: TriMesh) -> float:
    """How far (m) the deepest vertex or triangle centre of ``mesh`` lies behind ``other``'s surface: its
    distance to the nearest point of that surface when it is on the side the face's normal points
    away from (inside a closed body, below an open sheet); 0 if none is."""
    points = np.vstack([mesh.vertices, mesh.vertices[mesh.triangles].mean(axis=1)])
    nearest, normals = RayCaster([other]).closest(points)
    offset = points - nearest
    behind = np.einsum("ij,ij->i", offset, normals) < 0.0
    return float(np.linalg.norm(offset[behind], axis=1).max(initial=0.0))


class Simulation:
    """A world in pybullet plus its ground truth. Create one per run; ``close()`` it."""

    def __init__(self, spec: WorldSpec | str, registry: Any | None = None, seed: int = 0) -> None:
        self.spec = spec if isinstance(spec, WorldSpec) else load_world_spec(spec)
        self.seed = seed
        self.client = p.connect(p.DIRECT)
        p.setAdditionalSearchPath(str(pybullet_data_path()), physicsClientId=self.client)
        self.bodies: list[GroundTruthBody] = []
        try:
            with captured_output(stdout=True):  # pybullet's b3Error / b3Warning and Open3D's warnings
                for body in self.spec.environment:
                    self._add(body, is_object=False)
                for body in self.spec.objects:
                    self._add(body, is_object=True)
            self._check_region()
            self._check_overlaps()
        except BaseException:
            self.close()
            raise
        self.raycaster = RayCaster([b.mesh for b in self.bodies])
        #: per body, in the ray caster's order: the mirror share of the light its surface reflects
        self.specular = np.array([b.specular for b in self.bodies], dtype=float)
        self._environment_caster: RayCaster | None = None
        self.sensor = None
        self.robot = None
        if registry is not None:
            try:
                self.attach_plugins(registry)
            except BaseException:
                self.close()
                raise

    # -- plugins -------------------------------------------------------------------------
    def attach_plugins(
        self,
        registry: Any,
        sensor: tuple[str, dict] | None = None,
        robot: tuple[str, dict] | None = None,
    ) -> None:
        """Build the world's sensor and robot plugins (optionally overridden)."""
        file = str(self.spec.path)
        name, params = sensor or (self.spec.sensor.plugin, self.spec.sensor.params)
        self.sensor = registry.create("sensor", name, params, file, "sensor")
        name, params = robot or (self.spec.robot.plugin, self.spec.robot.params)
        self.robot = registry.create("robot", name or registry.default("robot", "world")[0], params, file, "robot")
        if hasattr(self.robot, "attach"):
            self.robot.attach(self)
        placed = self.spec.robot.base is not None
        if (placed or getattr(self.robot, "base_dofs", ())) and hasattr(self.robot, "collisions"):
            inside = sorted({name for name in self.robot.collisions(self.robot.q, "true", 0.0) if name != "self"})
            if inside:  # a base the world does not place starts at the origin
                raise BadInput(file, "robot.base", f"the robot starts inside {', '.join(map(repr, inside))}"
                               + ("" if placed else " at the origin: give its pose, base: [x, y, z, yaw_deg]"))

    # -- bodies --------------------------------------------------------------------------
    def _support(self, name: str) -> GroundTruthBody:
        """The body ``name`` that another rests on (listed before it)."""
        support = next((b for b in self.bodies if b.name == name), None)
        if support is None:
            raise BadInput(str(self.spec.path), "on", f"{name!r} must be listed before the bodies on it")
        return support

    def _support_top(self, name: str, xy: Array, where: str) -> float:
        """The height of the top of the body ``name`` that a body centred at ``xy`` rests on."""
        support = self._support(name)
        if not over_top(support.mesh, xy):
            lo, hi = support.mesh.bounds
            raise BadInput(str(self.spec.path), f"{where}.position",
                           f"[{xy[0]:g}, {xy[1]:g}] is not over the top of {name!r} (it spans x "
                           f"{lo[0]:.3g}..{hi[0]:.3g}, y {lo[1]:.3g}..{hi[1]:.3g}): the body would float")
        return float(support.mesh.vertices[:, 2].max())

    def _drop_onto(self, name: str, vertices: Points3, where: str) -> float:
        """The height of the bounding-box centre at which a body whose vertices (world frame, at the
        position it is dropped from) come to rest on ``name``, falling straight down: the shortest
        fall of any vertex onto that body's surface. Picks one bin of a shelf with several, or a
        sloped floor, where the top of the whole body (:meth:`_support_top`) would be the roof."""
        support = self._support(name)
        down = np.tile([0.0, 0.0, -1.0], (len(vertices), 1))
        fall, _, normal = RayCaster([support.mesh], nthreads=1).cast(vertices, down)
        hit = np.isfinite(fall)
        lo, hi = vertices[:, 2].min(), vertices[:, 2].max()
        if not hit.any():
            raise BadInput(str(self.spec.path), f"{where}.position",
                           f"nothing of {name!r} lies below the body dropped from z = {lo:.3g} (its lowest "
                           "point): lower z or move x, y over it")
        if np.any(normal[hit, 2] < 0.0):  # a ray from inside meets a face from behind
            raise BadInput(str(self.spec.path), f"{where}.position",
                           f"the body dropped from z = {lo:.3g} (its lowest point) starts inside {name!r}: raise z")
        return float(0.5 * (lo + hi) - fall[hit].min())

    def _add(self, body: BodySpec, is_object: bool) -> None:
        kind = "objects" if is_object else "environment"
        index = (self.spec.objects if is_object else self.spec.environment).index(body)
        where = f"{kind}[{index}]"
        rotation = rpy_deg_to_matrix(body.rpy_deg)
        quat = p.getQuaternionFromEuler(np.deg2rad(body.rpy_deg).tolist())
        is_file_body = body.shape == "file" and body.source.suffix.lower() in (".urdf", ".sdf")
        if is_file_body:
            body_id, mesh = self._add_urdf(body, quat, where)  # mesh at the origin, rotated
        else:
            mesh = self._primitive_or_mesh(body, where).transformed(pose_from(np.zeros(3), rotation))
        lo, hi = mesh.bounds
        extent = float(np.max(hi - lo))
        if is_object and extent < MIN_OBJECT_EXTENT:
            raise BadInput(str(self.spec.path), f"{where}.size" if body.size is not None else where,
                           f"the object is {extent:.3g} m across: below {MIN_OBJECT_EXTENT * 1000:g} mm, "
                           "no range sensor here resolves it")
        center = 0.5 * (lo + hi)
        position = body.position.copy()  # the centre of the body's bounding box
        if body.on is not None and body.drop:
            position[2] = self._drop_onto(body.on, mesh.vertices - center + position, where) + CONTACT_GAP
        elif body.on is not None:
            position[2] = self._support_top(body.on, position[:2], where) + CONTACT_GAP + (center[2] - lo[2])
        if is_file_body:
            p.resetBasePositionAndOrientation(
                body_id, (position - center).tolist(), quat, physicsClientId=self.client
            )
            world_mesh = TriMesh.concatenate(body_visual_meshes(body_id, self.client))
        else:
            mesh = TriMesh(mesh.vertices - center, mesh.triangles)
            body_id = self._create_mesh_body(mesh, body.color)
            p.resetBasePositionAndOrientation(
                body_id, position.tolist(), [0, 0, 0, 1], physicsClientId=self.client
            )
            world_mesh = TriMesh(mesh.vertices + position, mesh.triangles)
        if not np.all(np.isfinite(world_mesh.vertices)):
            raise BadInput(str(self.spec.path), where, "pose gives non-finite coordinates")
        if body.specular > 0:  # the colour render shows the highlight too
            for link in range(-1, p.getNumJoints(body_id, physicsClientId=self.client)):
                p.changeVisualShape(body_id, link, specularColor=[body.specular] * 3, physicsClientId=self.client)
        self.bodies.append(GroundTruthBody(body.name, body_id, world_mesh, is_object, body.known, body.specular))

    def _primitive_or_mesh(self, body: BodySpec, where: str) -> TriMesh:
        if body.shape == "box":
            mesh = box_mesh(body.dims)
        elif body.shape == "cylinder":
            mesh = cylinder_mesh(body.dims[0], body.dims[1])
        elif body.shape == "sphere":
            mesh = sphere_mesh(body.dims[0])
        else:
            try:
                mesh = read_mesh(body.source)
            except (OSError, ValueError) as error:
                raise BadInput(str(self.spec.path), f"{where}.source", f"cannot read mesh: {error}") from None
        scale = body.scale
        if body.size is not None:
            lo, hi = mesh.bounds
            scale = np.full(3, body.size / float(np.max(hi - lo)))
        return TriMesh(mesh.vertices * scale, mesh.triangles)

    def _create_mesh_body(self, mesh: TriMesh, color: tuple[float, ...]) -> int:
        """A static pybullet body of ``mesh`` (its collisions and colour render). A mesh beyond pybullet's size
        limits is reduced for it (:meth:`TriMesh.within`); the ground truth and the sensors' ray casting keep
        the full mesh."""
        mesh = mesh.within(PYBULLET_MAX_VERTICES, PYBULLET_MAX_TRIANGLES)
        vertices = mesh.vertices.tolist()
        indices = mesh.triangles.reshape(-1).tolist()
        collision = p.createCollisionShape(
            p.GEOM_MESH, vertices=vertices, indices=indices,
            flags=p.GEOM_FORCE_CONCAVE_TRIMESH, physicsClientId=self.client,
        )
        visual = p.createVisualShape(
            p.GEOM_MESH, vertices=vertices, indices=indices, rgbaColor=list(color),
            physicsClientId=self.client,
        )
        return p.createMultiBody(0.0, collision, visual, physicsClientId=self.client)

    def _add_urdf(self, body: BodySpec, quat: tuple, where: str) -> tuple[int, TriMesh]:
        file = str(self.spec.path)
        scale = float(body.scale[0])
        if body.size is not None or not np.allclose(body.scale, body.scale[0]):
            if body.size is None:
                raise BadInput(file, f"{where}.scale", "URDF/SDF bodies take one uniform scale")
        body_id = self._load_file(body, scale, where)
        p.resetBasePositionAndOrientation(body_id, [0, 0, 0], [0, 0, 0, 1], physicsClientId=self.client)
        mesh = TriMesh.concatenate(body_visual_meshes(body_id, self.client))
        if len(mesh.triangles) == 0:
            raise BadInput(file, f"{where}.source", "the file has no visual geometry")
        if body.size is not None:  # the largest extent in its own frame, as for a mesh: a turned body stays the same
            lo, hi = mesh.bounds
            p.removeBody(body_id, physicsClientId=self.client)
            body_id = self._load_file(body, body.size / float(np.max(hi - lo)), where)
        p.resetBasePositionAndOrientation(body_id, [0, 0, 0], quat, physicsClientId=self.client)
        return body_id, TriMesh.concatenate(body_visual_meshes(body_id, self.client))

    def _load_file(self, body: BodySpec, scale: float, where: str) -> int:
        try:
            if body.source.suffix.lower() == ".urdf":
                return p.loadURDF(str(body.source), useFixedBase=True, globalScaling=scale, physicsClientId=self.client)
            ids = p.loadSDF(str(body.source), globalScaling=scale, physicsClientId=self.client)
        except p.error as error:
            raise BadInput(str(self.spec.path), f"{where}.source", f"pybullet cannot load it: {error}") from None
        if len(ids) != 1:  # e.g. pybullet_data's stadium.sdf: the others would stand in the world unseen
            for extra in ids:
                p.removeBody(extra, physicsClientId=self.client)
            raise BadInput(str(self.spec.path), f"{where}.source", f"{body.source.name} holds {len(ids)} models; "
                           "a body takes one (give each model a file of its own)")
        return ids[0]

    def _check_region(self) -> None:
        tol = 1e-3
        for index, body in enumerate(b for b in self.bodies if b.is_object):
            lo, hi = body.mesh.bounds
            if np.any(lo < self.spec.region_min - tol) or np.any(hi > self.spec.region_max + tol):
                spec = self.spec.objects[index]
                oversized = np.max(hi - lo) > 10.0 * np.max(self.spec.region_max - self.spec.region_min)
                hint = ("; is its mesh in millimetres? give the object a size (its largest extent in m)"
                        if oversized and spec.size is None and np.allclose(spec.scale, 1.0) else "")
                raise BadInput(
                    str(self.spec.path),
                    f"objects[{index}] ({body.name})",
                    f"extends outside the region: object box {np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()}, "
                    f"region {self.spec.region_min.tolist()}..{self.spec.region_max.tolist()}{hint}",
                )

    def _check_overlaps(self) -> None:
        """No object may intersect another body: a world whose objects pass through each other or
        through the table is no scene a robot could meet (the segmentation would see one object).
        Surfaces that cross over more than ``OVERLAP_TOLERANCE`` with a point more than
        ``PENETRATION_TOLERANCE`` behind the other's surface intersect; a slight press of one body
        into another, as hand-placed positions give, is touching."""
        environment = [("environment", j, b) for j, b in enumerate(b for b in self.bodies if not b.is_object)]
        objects = [b for b in self.bodies if b.is_object]
        for index, body in enumerate(objects):
            lo, hi = body.mesh.bounds
            for kind, position, other in environment + [("objects", j, b) for j, b in enumerate(objects[:index])]:
                olo, ohi = other.mesh.bounds
                if np.any(lo > ohi + OVERLAP_TOLERANCE) or np.any(olo > hi + OVERLAP_TOLERANCE):
                    continue
                crossings = np.vstack([surface_crossings(body.mesh, other.mesh),
                                       surface_crossings(other.mesh, body.mesh)])
                extent = float(np.ptp(crossings, axis=0).max()) if len(crossings) else 0.0
                if extent <= OVERLAP_TOLERANCE:
                    continue
                depth = max(depth_behind(body.mesh, other.mesh), depth_behind(other.mesh, body.mesh))
                if depth > PENETRATION_TOLERANCE:
                    raise BadInput(str(self.spec.path), f"objects[{index}] ({body.name})",
                                   f"intersects {kind}[{position}] ({other.name}): their surfaces cross over "
                                   f"{1000.0 * extent:.0f} mm, {1000.0 * depth:.0f} mm deep; move one of them")

    # -- queries -------------------------------------------------------------------------
    @property
    def ground_truth(self) -> list[GroundTruthBody]:
        """Ground-truth bodies; for metrics and simulated sensors only, never for planners."""
        return self.bodies

    def objects(self) -> list[GroundTruthBody]:
        return [b for b in self.bodies if b.is_object]

    def body_colour(self, body: GroundTruthBody) -> np.ndarray | None:
        """The one RGB colour (3,) in [0, 1] of a body's untextured visual shapes, as a given model's material
        tells it; None when its shapes carry textures or differ in colour."""
        shapes = p.getVisualShapeData(body.body_id, flags=p.VISUAL_SHAPE_DATA_TEXTURE_UNIQUE_IDS,
                                      physicsClientId=self.client)
        if not shapes or any(shape[8] >= 0 for shape in shapes):
            return None
        colours = np.array([shape[7][:3] for shape in shapes], dtype=float)
        return colours[0] if np.ptp(colours, axis=0).max() < 1e-3 else None

    def environment_ids(self) -> list[int]:
        """pybullet ids of the known static environment (what a planner may know)."""
        return [b.body_id for b in self.bodies if not b.is_object]

    def environment_caster(self) -> RayCaster:
        """A ray caster over the known static environment (what a planner may know), built once."""
        if self._environment_caster is None:
            self._environment_caster = RayCaster([b.mesh for b in self.bodies if not b.is_object], nthreads=1)
        return self._environment_caster

    def object_ids(self) -> list[int]:
        return [b.body_id for b in self.bodies if b.is_object]

    def object_mesh(self, name: str | None = None) -> TriMesh:
        """Ground-truth mesh of one object (or of all objects)."""
        chosen = [b.mesh for b in self.objects() if name is None or b.name == name]
        return TriMesh.concatenate(chosen)

    def close(self) -> None:
        if getattr(self, "client", None) is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> dict[str, Any]:
        """A summary for ``explore worlds show``."""
        rows = []
        for body in self.bodies:
            lo, hi = body.mesh.bounds
            role = ("object, known" if body.known else "object, unknown") if body.is_object else "environment"
            rows.append(
                {
                    "name": body.name,
                    "role": role + (f", glossy {body.specular:g}" if body.specular > 0 else ""),
                    "size_m": np.round(hi - lo, 3).tolist(),
                    "center_m": np.round(0.5 * (lo + hi), 3).tolist(),
                    "triangles": int(len(body.mesh.triangles)),
                }
            )
        return {
            "name": self.spec.name,
            "file": str(self.spec.path),
            "description": self.spec.description,
            "bodies": rows,
            "robot": {"plugin": self.spec.robot.plugin or getattr(self.robot, "name", ""),
                      "params": self.spec.robot.params},
            "sensor": {"plugin": self.spec.sensor.plugin, "params": self.spec.sensor.params},
            "region": {"min": self.spec.region_min.tolist(), "max": self.spec.region_max.tolist()},
        }
