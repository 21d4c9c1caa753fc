"""Perception: segmentation, recognition, registration, PVS validation of hypotheses, and the
object database.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.perception.colour import (
    COLOUR_KIND,
    MIN_COLOUR_AGREEMENT,
    ColourSignature,
    chromaticity,
    colour_agreement,
    colour_signature,
    material_signature,
    shows_colours_of,
)
from explore.perception.contracts import (
    PlaneRegistrar,
    PoseValidator,
    Recognizer,
    Registrar,
    ScansRegistrar,
    ScanToModelRegistrar,
    Segmenter,
    require_role,
)
from explore.perception.database import PROVENANCES, NameTaken, ObjectDatabase, default_path, object_frame
from explore.perception.depth_filters import (
    DepthProcessing,
    depth_image,
    filter_depth_scan,
    flying_pixel_mask,
    jump_edges,
    median_depth,
    organised_normals,
    with_organised_normals,
)
from explore.perception.fpfh import FPFHRansacRecognizer
from explore.perception.fusion import FusedPose, fuse_poses
from explore.perception.hypotheses import (
    Q_H_MIN,
    Hypothesis,
    Model,
    accepted,
    distance_to_model,
    rivals,
    surface_distances,
    surfaces_coincide,
)
from explore.perception.icp import IcpResult, icp_local, scan_points_and_normals
from explore.perception.incremental_graph import IncrementalPoseGraph, LikelihoodField
from explore.perception.model_data import ModelCloud, model_cloud
from explore.perception.normals import estimate_normals
from explore.perception.planar_icp import PlanarSurface, refine_planar
from explore.perception.plane_icp import as_2d_transform, plane_frame, plane_icp
from explore.perception.pose_graph import PoseGraph, PoseGraphResult, pose_graph_from_scans, rebase_scan, sigmas6
from explore.perception.ppf import PPFRecognizer
from explore.perception.recognition import model_descriptors
from explore.perception.scene_registration import register_pair
from explore.perception.segmentation import (
    Cloud,
    Cluster,
    PlaneClusterSegmenter,
    Segmentation,
    Table,
    euclidean_clusters,
    grown_to,
    merge_clusters,
    ransac_iterations,
)
from explore.perception.validation import (
    ACCEPT_FROM,
    FREE_BELOW,
    OCCUPIED_FROM,
    Validation,
    pvs_votes,
    vote_points,
)
from explore.perception.verification import icp_refine, inlier_fraction, render_and_compare
from explore.perception.vfh import VFHRecognizer, vfh_signature

__all__ = [
    "COLOUR_KIND",
    "MIN_COLOUR_AGREEMENT",
    "ColourSignature",
    "chromaticity",
    "colour_agreement",
    "colour_signature",
    "material_signature",
    "shows_colours_of",
    "PlanarSurface",
    "icp_refine",
    "inlier_fraction",
    "ModelCloud",
    "model_cloud",
    "ACCEPT_FROM",
    "Cloud",
    "Cluster",
    "FPFHRansacRecognizer",
    "FREE_BELOW",
    "FusedPose",
    "Hypothesis",
    "IcpResult",
    "IncrementalPoseGraph",
    "LikelihoodField",
    "Model",
    "OCCUPIED_FROM",
    "NameTaken",
    "ObjectDatabase",
    "PROVENANCES",
    "PPFRecognizer",
    "PlaneClusterSegmenter",
    "PlaneRegistrar",
    "PoseGraph",
    "PoseGraphResult",
    "PoseValidator",
    "Q_H_MIN",
    "Recognizer",
    "Registrar",
    "ScanToModelRegistrar",
    "ScansRegistrar",
    "Segmentation",
    "Segmenter",
    "Table",
    "VFHRecognizer",
    "Validation",
    "accepted",
    "as_2d_transform",
    "default_path",
    "estimate_normals",
    "euclidean_clusters",
    "grown_to",
    "depth_image",
    "DepthProcessing",
    "filter_depth_scan",
    "flying_pixel_mask",
    "fuse_poses",
    "icp_local",
    "jump_edges",
    "median_depth",
    "organised_normals",
    "with_organised_normals",
    "merge_clusters",
    "model_descriptors",
    "object_frame",
    "plane_frame",
    "plane_icp",
    "refine_planar",
    "pose_graph_from_scans",
    "pvs_votes",
    "vote_points",
    "ransac_iterations",
    "rebase_scan",
    "register_pair",
    "render_and_compare",
    "require_role",
    "rivals",
    "scan_points_and_normals",
    "sigmas6",
    "surface_distances",
    "surfaces_coincide",
    "distance_to_model",
    "vfh_signature",
]
