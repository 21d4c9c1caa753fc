"""Open3D FPFH features + RANSAC + ICP, with the same verification as PPF (RANSAC on one thread: its per-thread
generators do not repeat)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from explore.core import Points3, open3d_serial
from explore.perception.hypotheses import Q_H_MIN, Hypothesis, Model
from explore.perception.model_data import ModelCloud, model_cloud
from explore.perception.recognizer_base import RecognizerBase
from explore.perception.segmentation import Cluster
from explore.perception.verification import (
    o3d_cloud,
)
from explore.sim import Scan


# -- FPFH + RANSAC ----------------------------------------------------------------------------
class FPFHRansacRecognizer(RecognizerBase):
    """Open3D FPFH features + RANSAC + point-to-plane ICP, verified by q_h (Eq. 3.10)."""

    name = "fpfh_ransac"
    descriptor_kind = "fpfh"

    def __init__(
        self,
        voxel: float = 0.005,
        feature_radius_factor: float = 5.0,
        max_iterations: int = 50000,
        confidence: float = 0.999,
        trials: int = 1,
        match_threshold: float = 0.005,
        icp: bool = True,
        max_hypotheses: int = 3,
        normal_radius: float = 0.01,
        seed: int = 0,
        min_q_h: float = Q_H_MIN,
    ) -> None:
        super().__init__()
        self.min_q_h = min_q_h
        self.voxel = voxel
        self.feature_radius_factor = feature_radius_factor
        self.max_iterations = max_iterations
        self.confidence = confidence
        self.trials = trials
        self.match_threshold = match_threshold
        self.icp = icp
        self.max_hypotheses = max_hypotheses
        self.normal_radius = normal_radius
        self.seed = seed

    def _features(self, points: Points3, normals: Points3):  # -> (cloud, feature)
        import open3d as o3d

        cloud = o3d_cloud(points, normals).voxel_down_sample(self.voxel)
        cloud.normalize_normals()
        feature = o3d.pipelines.registration.compute_fpfh_feature(
            cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=self.feature_radius_factor * self.voxel, max_nn=100)
        )
        return cloud, feature

    def model_data(self, model: Model) -> tuple[ModelCloud, Any, Any]:
        key = model.key()
        if key not in self._cache:
            cloud = model_cloud(model.mesh, self.voxel, normal_radius=self.normal_radius)
            down, feature = self._features(cloud.points, cloud.normals)
            self._cache[key] = (cloud, down, feature)
        return self._cache[key]

    def recognize_model(self, cluster: Cluster, model: Model, scans: Mapping[int, Scan]) -> list[Hypothesis]:
        import open3d as o3d

        reg = o3d.pipelines.registration
        started = time.perf_counter()
        cloud, model_down, model_feature = self.model_data(model)
        scene_down, scene_feature = self._features(cluster.points, cluster.normals)
        if len(scene_down.points) < 5:
            return []
        distance = 1.5 * self.voxel
        candidates = []
        for trial in range(self.trials):
            with open3d_serial():  # per-thread generators: only one thread repeats its draws
                o3d.utility.random.seed(self.seed + trial)
                result = reg.registration_ransac_based_on_feature_matching(
                    model_down, scene_down, model_feature, scene_feature, False, distance,
                    reg.TransformationEstimationPointToPoint(False), 3,
                    [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                     reg.CorrespondenceCheckerBasedOnDistance(distance)],
                    reg.RANSACConvergenceCriteria(self.max_iterations, self.confidence),
                )
            candidates.append((np.asarray(result.transformation).copy(),
                               {"ransac_fitness": float(result.fitness), "trial": trial}))
        return self._finish(cluster, model, cloud, candidates, scans, started)
