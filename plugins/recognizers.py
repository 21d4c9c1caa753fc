"""Built-in recognizer plugins: PPF voting, FPFH + RANSAC, VFH "mean distance"."""

from __future__ import annotations

from explore.core import Param
from explore.perception import Q_H_MIN, FPFHRansacRecognizer, PPFRecognizer, VFHRecognizer

_VERIFY = (
    Param("match_threshold", float, 0.005, "m", "render-and-compare depth tolerance (Eq. 3.10; also 3 sigma)",
          low=1e-4),
    Param("icp", bool, True, "", "refine each hypothesis with point-to-plane ICP"),
    Param("max_hypotheses", int, 3, "", "hypotheses returned per model", low=1),
    Param("normal_radius", float, 0.01, "m", "normal estimation radius of the model views", low=1e-4),
    Param("min_q_h", float, Q_H_MIN, "", "accept a hypothesis only if its q_h reaches this (Eq. 3.10)", low=0.0,
          high=1.0),
)


class PPF(PPFRecognizer):
    """Drost point-pair features, voting over (model point, alpha), ICP, q_h = (Nm/Nr)(Nm/Nc)^2 (Eq. 3.10)."""

    params = (
        Param("relative_sampling", float, 0.05, "", "sampling distance / model diameter (Drost tau_d)", low=0.005,
              high=0.5),
        Param("min_sampling", float, 0.004, "m", "smallest sampling distance", low=1e-4),
        Param("angle_bins", int, 30, "", "bins of each PPF angle over [0, pi]", low=4),
        Param("alpha_bins", int, 30, "", "bins of the rotation alpha over 2 pi", low=4),
        Param("reference_fraction", float, 0.25, "", "share of scene points used as references", low=0.01,
              high=1.0),
        Param("peaks", int, 5, "", "pose clusters kept after voting", low=1),
        Param("cluster_translation", float, 0.1, "", "pose clustering: translation / model diameter", low=0.0),
        Param("cluster_rotation_deg", float, 24.0, "deg", "pose clustering: rotation", low=0.0, high=180.0),
        Param("max_bin", int, 40, "", "model pairs kept per hash bin (planar faces)", low=1),
        Param("seed", int, 0, "", "reference point sampling seed", low=0),
        *_VERIFY,
    )


class FPFHRansac(FPFHRansacRecognizer):
    """Open3D FPFH features + RANSAC + point-to-plane ICP, verified by q_h (Eq. 3.10)."""

    params = (
        Param("voxel", float, 0.005, "m", "down-sampling voxel of model and cluster", low=1e-4),
        Param("feature_radius_factor", float, 5.0, "", "FPFH radius in voxels", low=1.0),
        Param("max_iterations", int, 50000, "", "RANSAC iterations", low=1),
        Param("confidence", float, 0.999, "", "RANSAC confidence", low=0.5, high=1.0),
        Param("trials", int, 1, "", "RANSAC runs with different seeds", low=1),
        Param("seed", int, 0, "", "RANSAC seed", low=0),
        *_VERIFY,
    )


class VFHMeanDistance(VFHRecognizer):
    """Görner: VFH (308 bins) per view, k = 1 priming, mean distance of the closest 66 % of views < gamma."""

    params = (
        Param("gamma", float, 15.0, "", "mean-distance threshold (our binning; Görner 16.4 with PCL's)", low=0.0),
        Param("keep_fraction", float, 0.66, "", "share of the closest view distances averaged", low=0.01,
              high=1.0),
        Param("training_views", int, 120, "", "rendered training views per model (upper view sphere)", low=1),
        Param("view_distance", float, 1.1, "m", "camera distance of the training views", low=0.05),
        Param("pixel_angle_deg", float, 58.0 / 320.0, "deg", "angular pixel pitch of the training camera",
              low=1e-3),
        Param("noise", float, 1.425e-3 * 1.1**2, "m", "range noise added to training views", low=0.0),
        Param("training_draws", int, 4, "", "noise draws averaged per training view through the scene's sensor",
              low=1, high=64),
        Param("min_height", float, 0.01, "m", "cut of the model bottom (as the segmenter)", low=0.0),
        Param("normal_radius", float, 0.01, "m", "normal estimation radius (Görner 0.01 m)", low=1e-4),
        Param("refine", bool, True, "", "ICP-refine the pose from the best training view"),
        Param("match_threshold", float, 0.005, "m", "render-and-compare depth tolerance", low=1e-4),
        Param("max_hypotheses", int, 3, "", "hypotheses returned", low=1),
        Param("min_q_h", float, Q_H_MIN, "", "accept a hypothesis only if its q_h reaches this (Eq. 3.10)",
              low=0.0, high=1.0),
    )


PLUGINS = [PPF, FPFHRansac, VFHMeanDistance]
