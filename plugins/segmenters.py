"""Built-in segmenter plugins."""

from __future__ import annotations

from explore.core import Param
from explore.perception import PlaneClusterSegmenter

#: (cluster tolerance [m], minimum cluster size) per scale preset (Görner: 0.05 m / 20 points)
SCALE_PRESETS = {"room": (0.05, 20), "table": (0.02, 30)}


class PlaneClusters(PlaneClusterSegmenter):
    """Support plane by RANSAC, table hull prism 0-0.5 m, Euclidean clusters (Görner Ch. 3)."""

    name = "plane_clusters"
    params = (
        Param("distance_threshold", float, 0.02, "m", "RANSAC inlier distance (Görner 0.02 m)", low=1e-4),
        Param("success_probability", float, 0.99, "", "p in N = log(1-p)/log(1-w^3)", low=0.5, high=0.999999),
        Param("inlier_fraction", float, 1.0 / 3.0, "", "w in N = log(1-p)/log(1-w^3)", low=0.01, high=1.0),
        Param("min_plane_height", float, 0.2, "m", "floor cut: the support plane is searched above this world z "
              "(below it only when there is none)", low=-100.0),
        Param("max_tilt_deg", float, 20.0, "deg", "largest tilt of a support plane from +z", low=0.0, high=90.0),
        Param("table_tolerance", float, 0.03, "m", "connectivity of the table inliers", low=1e-4),
        Param("min_table_points", int, 200, "", "smallest table (points)", low=3),
        Param("min_height", float, 0.01, "m", "object points start this high above the plane", low=0.0),
        Param("max_height", float, 0.5, "m", "top of the object prism above the plane", low=0.0),
        Param("scale", str, "room", "", "preset for tolerance / min size: room 0.05 m / 20, table 0.02 m / 30",
              choices=tuple(SCALE_PRESETS)),
        Param("cluster_tolerance", float, 0.0, "m", "Euclidean clustering tolerance (0: from the preset)", low=0.0),
        Param("min_cluster_size", int, 0, "", "smallest cluster in points (0: from the preset)", low=0),
        Param("normal_radius", float, 0.01, "m", "radius of the normal estimation (Görner 0.01 m)", low=1e-4),
        Param("seed", int, 0, "", "RANSAC seed", low=0),
    )

    def __init__(self, scale: str = "room", cluster_tolerance: float = 0.0, min_cluster_size: int = 0,
                 **values: float) -> None:
        tolerance, size = SCALE_PRESETS[scale]
        super().__init__(cluster_tolerance=cluster_tolerance or tolerance, min_cluster_size=min_cluster_size or size,
                         **values)
        self.scale = scale


PLUGINS = [PlaneClusters]
