"""The database step of a scene exploration (Kriegel thesis Sec. 3.1, 5.6.3): a modelled object is added with a
short, stable name (<world>-<n>) and its provenance, and every recognised object's location is remembered."""

from __future__ import annotations

import re
import time
from typing import TYPE_CHECKING

import numpy as np

from explore.perception import (
    COLOUR_KIND,
    Model,
    NameTaken,
    PPFRecognizer,
    VFHRecognizer,
    colour_signature,
    model_descriptors,
    object_frame,
)
from explore.scene.scene_objects import (
    RECOGNISED,
    SceneObject,
)
from explore.sim import TriMesh

if TYPE_CHECKING:
    from explore.scene.session import SceneSession


class DatabaseUpdate:
    """The database step: add modelled objects, remember where recognised ones were."""

    def __init__(self, scene: SceneSession) -> None:
        self.scene = scene
        self._remembered: dict[int, tuple[str, bytes]] = {}  # object id -> (model, pose) last recorded

    # -- the object database -------------------------------------------------------------------
    def add_to_database(self, obj: SceneObject, world_mesh: TriMesh, scans: int) -> str:
        """Add a modelled mesh (world frame) with descriptors, provenance and location."""
        scene = self.scene
        start = time.perf_counter()
        world_T_model, mesh = object_frame(world_mesh)
        name = self._new_name()
        chosen = [scene.recognizer] if hasattr(scene.recognizer, "describe") else []  # the configured one's own
        kinds = {r.descriptor_kind for r in chosen}
        chosen += [r for r in (PPFRecognizer(), VFHRecognizer()) if r.descriptor_kind not in kinds]
        descriptors = model_descriptors(Model(name, mesh), chosen)
        colours = scene.recognition.cluster_colours(obj.cluster)
        if colours is not None and (signature := colour_signature(colours)) is not None:
            descriptors[COLOUR_KIND] = signature.as_array()
        coverage = float(np.clip(obj.coverage_estimate, 0.0, 1.0))
        while True:
            try:
                scene.db.add(name, mesh, provenance="modelled", world=scene.sim.spec.name, run=scene.settings.run_name,
                             scans=int(scans), coverage=coverage, descriptors=descriptors)
                break
            except NameTaken:
                name = self._new_name()  # another run writing the database took this name meanwhile
        scene.db.set_location(name, scene.sim.spec.name, world_T_model, np.vstack(world_mesh.bounds))
        obj.pose = world_T_model
        scene.added.append(name)
        scene.model_cache = None
        scene.timed("database_s", start)
        scene.say(f"object {obj.id}: added to the database as {name}")
        return name

    def _new_name(self) -> str:
        """A short, stable name for a modelled object: ``<world>-<n>``, the first n free in the database
        (the run that made it is recorded beside it, not in its name)."""
        scene = self.scene
        # an object name is ASCII letters, digits, _ . - (up to 100), not starting with a dot
        stem = re.sub(r"[^A-Za-z0-9_.\-]", "_", scene.sim.spec.name)[:80].lstrip(".") or "world"
        k = 1
        while f"{stem}-{k}" in scene.db:
            k += 1
        return f"{stem}-{k}"

    def remember_locations(self) -> None:
        """Record where each recognised object was seen (the database's last known location), once per
        recognition: a call that finds the same model at the same pose adds no row."""
        scene = self.scene
        for obj in scene.by_status(RECOGNISED):
            if obj.model is not None and obj.pose is not None and obj.model in scene.db:
                seen = (obj.model, np.asarray(obj.pose, dtype=float).tobytes())
                if self._remembered.get(obj.id) == seen:
                    continue
                scene.db.set_location(obj.model, scene.sim.spec.name, obj.pose, np.vstack(obj.cluster.aabb))
                self._remembered[obj.id] = seen
