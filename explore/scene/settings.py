"""The settings of a scene exploration: every choice of :class:`~explore.scene.session.SceneSession` in one value."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from explore.perception import DepthProcessing


@dataclass(frozen=True)
class SceneSettings:
    """What a scene exploration uses and how much it may do.

    Attributes
    ----------
    segmenter, recognizer, validator, registrar : plugin names or (name, params)
    strategy : NBV strategy for modelling unknown objects (name, (name, params) or Strategy)
    seed : seeds the sensor noise, the execution noise and random choices
    resolution : scene PVS voxel edge (None: 5 mm)
    pvs_layout : the scene PVS's storage, "dense", "sparse" (hashed blocks, memory that follows the
        observed space) or "auto" (:func:`~explore.mapping.make_pvs`: dense up to 32 M voxels)
    max_views : view budget of the whole exploration
    recognition_views : recognise an object from the points of at most this many of its views
        (those with the most points; render-and-compare costs one ray cast per view)
    model_scans : scan budget per modelled object; ``model_coverage`` stops earlier at ĉ_m
    retry_scans : re-try recognition after each of the first ``retry_scans`` modelling scans
    multi_view_views : view budget per ambiguous object; ``multi_view_agree`` per-view
        hypotheses must agree (fused cluster) before an object counts as recognised
    view_render_fit : share of the model's rendered beams the view must confirm (N_m / N_r of
        Eq. 3.10) before one view's hypothesis confirms a pose in multi-view recognition. A right
        model, also one learned with holes, is confirmed where it has surface (0.76-0.99 per view
        on the tables, most above 0.85); a model learned from another, similar object puts
        surface where the view saw none (a jenga block taken for a random part modelled earlier:
        0.63-0.77 in every view, while its q_h of 0.52-0.64 passed and enough such views agreed)
    noise : execute motions with the robot's positioning noise
    planner : motion planner plugin name (robots other than the free flyer)
    run_name : recorded as the provenance of modelled objects
    associate_tolerance : a new view's cluster joins an object when its points come this close
    box_margin : the modelling box around an object's points (and ``box_top`` above them)
    min_points : clusters with fewer points (over all views) are noise, not objects
    reach_tries : NBS candidates tried for reachability (IK) per modelling step before the most
        novel reachable view of the object is taken instead
    split_distance, split_share : points of a recognised object farther from the model than four
        spreads of its residuals (at most ``split_distance``, at least 5 mm:
        :func:`explore.scene.recognition.explained_distance`), if at least ``split_share`` of them,
        are another object touching it
    register : grow a pose graph with every view when the robot has a noisy base that cannot
        localise itself (and correct the views, the clusters and the PVS with it); a base with a
        planar laser localises every view in the known room as it drives (``Mover.localise``)
    flying_pixel_filter : drop the beams of every view that fewer than 3 of their 8 neighbours lie
        within this share of their depth of (flying pixels between two surfaces), 0: keep every beam
    median_px : median-filter every view's depth image over 3 or 5 pixels first (0: off)
    organised_normals : give the points of an organised view the normals of its depth image
        (:func:`~explore.perception.organised_normals`) instead of a neighbour search's
    """

    segmenter: Any = None
    recognizer: Any = None
    validator: Any = None
    registrar: Any = None
    strategy: Any = None
    seed: int = 0
    resolution: float | None = None
    pvs_layout: str = "auto"
    max_views: int = 80
    recognition_views: int = 6
    model_scans: int = 12
    model_coverage: float = 0.75
    retry_scans: int = 3
    multi_view_views: int = 10
    multi_view_agree: int = 2
    view_render_fit: float = 0.8
    noise: bool = True
    planner: str | None = None
    run_name: str = "run"
    associate_tolerance: float = 0.01
    box_margin: float = 0.03
    box_top: float = 0.04
    min_points: int = 60
    reach_tries: int = 4
    split_distance: float = 0.015
    split_share: float = 0.1
    register: bool = True
    flying_pixel_filter: float = DepthProcessing.flying_pixel_filter
    median_px: int = DepthProcessing.median_px
    organised_normals: bool = DepthProcessing.organised_normals

    @property
    def depth_processing(self) -> DepthProcessing:
        """What every view goes through before it is used (``flying_pixel_filter``, ``median_px``,
        ``organised_normals``)."""
        return DepthProcessing(self.flying_pixel_filter, self.median_px, self.organised_normals)
