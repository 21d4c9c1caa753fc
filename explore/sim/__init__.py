"""Simulation and sensing: world files, the pybullet world with its ground truth, meshes, scans and
the simulated range sensors.
"""

# The names other packages use (they import from the package, never from its modules).
from explore.sim.acquire import MeshWorld, target_for
from explore.sim.artefacts import (
    correlated_field,
    dark_return_probability,
    depth_level_spacing,
    discontinuity_mask,
    flying_pixels,
    grazing_return_probability,
    highlight_return_probability,
    mirror_deviation,
    quantise_disparity,
    smooth_field,
)
from explore.sim.bullet import body_aabb, frame_pose, p
from explore.sim.meshes import TriMesh, box_mesh, cylinder_mesh, read_mesh, sphere_mesh
from explore.sim.scan import Scan, ScanPath
from explore.sim.sensing import NOISE_MODELS, RaySensor, noise_sigma, sigma_kinect, sigma_laser_poly, sigma_tof
from explore.sim.simulation import GroundTruthBody, RayCaster, Simulation
from explore.sim.world import WorldSpec, find_world, list_worlds, load_world_spec, repo_root

__all__ = [
    "GroundTruthBody",
    "MeshWorld",
    "NOISE_MODELS",
    "RayCaster",
    "RaySensor",
    "Scan",
    "ScanPath",
    "Simulation",
    "TriMesh",
    "WorldSpec",
    "body_aabb",
    "box_mesh",
    "correlated_field",
    "dark_return_probability",
    "depth_level_spacing",
    "discontinuity_mask",
    "flying_pixels",
    "grazing_return_probability",
    "highlight_return_probability",
    "mirror_deviation",
    "noise_sigma",
    "quantise_disparity",
    "smooth_field",
    "sigma_tof",
    "cylinder_mesh",
    "find_world",
    "frame_pose",
    "list_worlds",
    "load_world_spec",
    "p",
    "read_mesh",
    "repo_root",
    "sigma_kinect",
    "sigma_laser_poly",
    "sphere_mesh",
    "target_for",
]
