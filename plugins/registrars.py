"""Built-in registrar plugins: local ICP, Goerner's Plane ICP and the gtsam pose graph."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from explore.api import PlaneRegistrar, ScansRegistrar, ScanToModelRegistrar
from explore.core import Param, Points3, Pose
from explore.perception import (
    IcpResult,
    IncrementalPoseGraph,
    PoseGraphResult,
    icp_local,
    plane_icp,
    pose_graph_from_scans,
    sigmas6,
)
from explore.sim import Scan


class Icp(ScanToModelRegistrar):
    """Local ICP of a scan to the model: 3 mm radius, 3 iterations, 60 deg normal gate (Kriegel 3.2.3)."""

    name = "icp"
    params = (
        Param("radius", float, 0.003, "m", "correspondence radius (bottom scans: 20 mm)", low=1e-6),
        Param("iterations", int, 3, "", "ICP iterations (thesis 2-3; bottom scans: 40)", low=0),
        Param("normal_gate_deg", float, 60.0, "deg", "reject pairs with normals further apart", low=0.0, high=180.0),
        Param("method", str, "point_to_point", "", "least-squares step", choices=("point_to_point", "point_to_plane")),
    )

    def register(
        self, source_points: Points3, source_normals: Points3 | None, target_points: Points3,
        target_normals: Points3 | None, init: Pose | None = None,
    ) -> IcpResult:
        """Transform of the source into the target frame (starting from ``init``)."""
        return icp_local(
            source_points, source_normals, target_points, target_normals, init,
            radius=self.radius, iterations=self.iterations, normal_gate_deg=self.normal_gate_deg, method=self.method,
        )


class PlaneIcp(PlaneRegistrar):
    """Goerner's Plane ICP: snap to the table plane, then 2-D (x, y, yaw) ICP with 3-D correspondences."""

    name = "plane_icp"
    params = (
        Param("radius", float, 0.05, "m", "maximum correspondence distance (Goerner: 5 cm)", low=1e-6),
        Param("fine_radius", float, 0.01, "m", "second, fine stage (0 = single stage)", low=0.0),
        Param("iterations", int, 30, "", "maximum ICP iterations per stage", low=0),
    )

    def register(
        self, source: Points3, target: Points3, plane: Any, source_plane: Any | None = None, init: Pose | None = None,
    ) -> IcpResult:
        """Transform of the source into the target frame; ``plane`` is the table in the target frame."""
        radii = (self.radius, self.fine_radius) if self.fine_radius > 0 else (self.radius,)
        return plane_icp(source, target, plane, source_plane, init, radius=radii, iterations=self.iterations)


class PoseGraphRegistrar(ScansRegistrar):
    """gtsam pose graph over a run's scans: odometry + pairwise ICP + loop closures, robust LM."""

    name = "pose_graph"
    params = (
        Param("voxel", float, 0.01, "m", "finest ICP voxel (coarse-to-fine x4, x2, x1)", low=1e-4),
        Param("priors", str, "odometry", "", "relative odometry factors (mobile base) or absolute kinematic priors",
              choices=("odometry", "kinematics")),
        Param("odometry_sigma_t", float, 0.02, "m", "translation sigma per odometry step / of a kinematic prior",
              low=1e-9),
        Param("odometry_sigma_r", float, 2.0, "deg", "rotation sigma per odometry step / of a kinematic prior",
              low=1e-9),
        Param("edge_sigma", float, 0.005, "m", "ICP edge sigma along well-constrained directions", low=1e-9),
        Param("min_overlap", float, 0.3, "", "least ICP fitness / predicted overlap of an edge", low=0.0, high=1.0),
        Param("loop_closures", bool, True, "", "register non-consecutive scans that overlap"),
        Param("max_loop_closures", int, 50, "", "at most this many loop-closure edges", low=0),
        Param("robust", str, "huber", "", "robust kernel of the ICP edges", choices=("huber", "cauchy", "none")),
        Param("robust_k", float, 1.345, "", "kernel threshold in whitened units", low=1e-6),
        Param("max_iterations", int, 100, "", "Levenberg-Marquardt iterations", low=1),
    )

    def register(self, scans: Sequence[Scan], poses: Sequence[Pose] | None = None) -> PoseGraphResult:
        """Corrected world_T_sensor poses of ``scans`` (believed poses: ``poses`` or the scans' own)."""
        sigmas = sigmas6(math.radians(self.odometry_sigma_r), self.odometry_sigma_t)
        return pose_graph_from_scans(
            scans, poses, odometry_sigmas=sigmas, prior_sigmas=sigmas if self.priors == "kinematics" else None,
            voxel=self.voxel, edge_sigma=self.edge_sigma, min_overlap=self.min_overlap,
            loop_closures=self.loop_closures, max_loop_closures=self.max_loop_closures,
            robust=self.robust, robust_k=self.robust_k, max_iterations=self.max_iterations,
        )

    def incremental(self, plane: Any | None = None, reference: Points3 | None = None) -> IncrementalPoseGraph:
        """An empty pose graph with these parameters that grows one scan at a time; with ``plane``
        (the floor of a mobile base) its edges come from Plane ICP in x, y, yaw, with
        ``reference`` (points of the known environment) every scan is also localised in that map."""
        sigmas = sigmas6(math.radians(self.odometry_sigma_r), self.odometry_sigma_t)
        return IncrementalPoseGraph(
            sigmas, sigmas if self.priors == "kinematics" else None, voxel=self.voxel, edge_sigma=self.edge_sigma,
            min_overlap=self.min_overlap, max_links=min(self.max_loop_closures, 3), robust=self.robust,
            robust_k=self.robust_k, max_iterations=self.max_iterations, plane=plane, reference=reference,
        )


PLUGINS = [Icp, PlaneIcp, PoseGraphRegistrar]
