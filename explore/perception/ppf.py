"""Drost et al. 2010 point-pair features (Kriegel thesis Eq. 3.9): voting over (model reference point, alpha),
pose clustering, ICP refinement and render-and-compare verification q_h as quality."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, mean_pose
from explore.perception.hypotheses import Q_H_MIN, Hypothesis, Model
from explore.perception.model_data import ModelCloud, has_normal, model_cloud, oriented
from explore.perception.recognizer_base import RecognizerBase
from explore.perception.segmentation import Cluster
from explore.perception.verification import (
    o3d_cloud,
)
from explore.sim import Scan


# -- PPF (Drost 2010) -----------------------------------------------------------------------
def _align_to_x(points: Points3, normals: Points3) -> tuple[np.ndarray, Points3]:
    """Rotations R (n, 3, 3) with R n = +x and translations t = −R p (Drost's T_{m→g})."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    a = np.column_stack([np.zeros(len(n)), n[:, 2], -n[:, 1]])  # n × e_x
    s2 = np.einsum("ij,ij->i", a, a)
    c = n[:, 0]
    k = np.zeros((len(n), 3, 3))
    k[:, 0, 1], k[:, 0, 2] = -a[:, 2], a[:, 1]
    k[:, 1, 0], k[:, 1, 2] = a[:, 2], -a[:, 0]
    k[:, 2, 0], k[:, 2, 1] = -a[:, 1], a[:, 0]
    factor = np.where(s2 > 1e-12, (1.0 - c) / np.maximum(s2, 1e-12), 0.0)
    r = np.eye(3)[None] + k + factor[:, None, None] * (k @ k)
    flip = (s2 <= 1e-12) & (c < 0)
    r[flip] = np.diag([-1.0, -1.0, 1.0])
    t = -np.einsum("nij,nj->ni", r, points)
    return r, t


def _pair_features(p1: Points3, n1: Points3, p2: Points3, n2: Points3) -> tuple[Array, Array, Array, Array]:
    """F(m1, m2) = (‖d‖, ∠(n1, d), ∠(n2, d), ∠(n1, n2)) (Kriegel Eq. 3.9, Drost 2010)."""
    d = p2 - p1
    dist = np.linalg.norm(d, axis=1)
    dn = d / np.maximum(dist, 1e-12)[:, None]
    f1 = np.arccos(np.clip(np.einsum("ij,ij->i", n1, dn), -1.0, 1.0))
    f2 = np.arccos(np.clip(np.einsum("ij,ij->i", n2, dn), -1.0, 1.0))
    f3 = np.arccos(np.clip(np.einsum("ij,ij->i", n1, n2), -1.0, 1.0))
    return dist, f1, f2, f3


def _alpha(r: np.ndarray, t: Points3, ref: np.ndarray, other: Points3) -> Array:
    """Angle of the transformed partner point about the x axis (Drost's alpha_m / alpha_s)."""
    q = np.einsum("nij,nj->ni", r[ref], other) + t[ref]
    return np.arctan2(q[:, 2], q[:, 1])


@dataclass
class PPFTable:
    """Hash table of a model's point pairs: sorted keys with (reference index, alpha_m)."""

    cloud: ModelCloud
    keys: np.ndarray
    refs: np.ndarray
    alphas: Array
    rotations: np.ndarray
    translations: Points3
    distance_step: float
    angle_bins: int
    diameter: float


class PPFRecognizer(RecognizerBase):
    """Drost point-pair features: voting over (model point, alpha), ICP, q_h verification (Eq. 3.10)."""

    name = "ppf"
    descriptor_kind = "ppf"

    def __init__(
        self,
        relative_sampling: float = 0.05,
        min_sampling: float = 0.004,
        angle_bins: int = 30,
        alpha_bins: int = 30,
        reference_fraction: float = 0.25,
        peaks: int = 5,
        cluster_translation: float = 0.1,
        cluster_rotation_deg: float = 24.0,
        match_threshold: float = 0.005,
        icp: bool = True,
        max_hypotheses: int = 3,
        normal_radius: float = 0.01,
        max_bin: int = 40,
        seed: int = 0,
        min_q_h: float = Q_H_MIN,
    ) -> None:
        super().__init__()
        self.min_q_h = min_q_h
        self.max_bin = max_bin
        self.relative_sampling = relative_sampling
        self.min_sampling = min_sampling
        self.angle_bins = angle_bins
        self.alpha_bins = alpha_bins
        self.reference_fraction = reference_fraction
        self.peaks = peaks
        self.cluster_translation = cluster_translation
        self.cluster_rotation_deg = cluster_rotation_deg
        self.match_threshold = match_threshold
        self.icp = icp
        self.max_hypotheses = max_hypotheses
        self.normal_radius = normal_radius
        self.seed = seed

    def sampling(self, model: Model) -> float:
        return max(self.relative_sampling * model.diameter, self.min_sampling)

    def descriptor_params(self) -> dict[str, Any]:
        return {"relative_sampling": self.relative_sampling, "min_sampling": self.min_sampling,
                "normal_radius": self.normal_radius}

    def describe(self, model: Model) -> tuple[np.ndarray, dict[str, Any]]:
        """The database descriptor: the sampled and the dense oriented clouds (n, 7): xyz, normal, is_sampled."""
        cloud = self.table(model).cloud
        sampled = np.hstack([cloud.points, cloud.normals, np.ones((len(cloud.points), 1))])
        dense = np.hstack([cloud.dense_points, cloud.dense_normals, np.zeros((len(cloud.dense_points), 1))])
        return np.vstack([sampled, dense]), self.descriptor_params()

    def table(self, model: Model) -> PPFTable:
        """Build (or fetch) the model's PPF hash table."""
        key = model.key()
        if key in self._cache:
            return self._cache[key]
        stored = model.descriptors.get(self.descriptor_kind)
        if (stored is not None and stored[1] == self.descriptor_params() and stored[0].ndim == 2
                and stored[0].shape[1] == 7):
            arr = stored[0]
            arr = arr[has_normal(arr[:, 3:6])]  # stored before vanished normals were dropped
            s, d = arr[arr[:, 6] > 0.5], arr[arr[:, 6] <= 0.5]
            cloud = ModelCloud(d[:, :3], d[:, 3:6], s[:, :3], s[:, 3:6])
        else:
            cloud = model_cloud(model.mesh, self.sampling(model), normal_radius=self.normal_radius)
        pts, nrm = cloud.points, cloud.normals
        n = len(pts)
        i, j = np.nonzero(~np.eye(n, dtype=bool))
        step = self.sampling(model)
        keys = self._keys(*_pair_features(pts[i], nrm[i], pts[j], nrm[j]), step)
        rot, trans = _align_to_x(pts, nrm)
        alphas = _alpha(rot, trans, i, pts[j])
        # random order inside each bin, then cap crowded bins (planar faces share one feature)
        shuffle = np.random.default_rng(self.seed).permutation(len(keys))
        order = shuffle[np.argsort(keys[shuffle], kind="stable")]
        sorted_keys = keys[order]
        starts = np.searchsorted(sorted_keys, sorted_keys, "left")
        keep = np.arange(len(sorted_keys)) - starts < self.max_bin
        order = order[keep]
        table = PPFTable(cloud, keys[order], i[order].astype(np.int32), alphas[order], rot, trans, step,
                         self.angle_bins, model.diameter)
        self._cache[key] = table
        return table

    def _keys(self, dist: Array, f1: Array, f2: Array, f3: Array, step: float) -> np.ndarray:
        nb = self.angle_bins
        scale = nb / math.pi
        a = np.minimum((f1 * scale).astype(np.int64), nb - 1)
        b = np.minimum((f2 * scale).astype(np.int64), nb - 1)
        c = np.minimum((f3 * scale).astype(np.int64), nb - 1)
        d = (dist / step).astype(np.int64)
        return ((d * nb + a) * nb + b) * nb + c

    def recognize_model(self, cluster: Cluster, model: Model, scans: Mapping[int, Scan]) -> list[Hypothesis]:
        started = time.perf_counter()
        table = self.table(model)
        scene = o3d_cloud(cluster.points, cluster.normals).voxel_down_sample(table.distance_step)
        sp, sn = oriented(scene)
        if len(sp) < 5:
            return []
        rng = np.random.default_rng(self.seed)
        n_ref = max(1, int(round(self.reference_fraction * len(sp))))
        refs = np.sort(rng.choice(len(sp), size=n_ref, replace=False))
        ri = np.repeat(np.arange(n_ref), len(sp))
        pi = np.tile(np.arange(len(sp)), n_ref)
        valid = refs[ri] != pi
        ri, pi = ri[valid], pi[valid]
        dist, f1, f2, f3 = _pair_features(sp[refs[ri]], sn[refs[ri]], sp[pi], sn[pi])
        close = dist <= table.diameter
        ri, pi, dist, f1, f2, f3 = ri[close], pi[close], dist[close], f1[close], f2[close], f3[close]
        keys = self._keys(dist, f1, f2, f3, table.distance_step)
        rot_s, trans_s = _align_to_x(sp[refs], sn[refs])
        alpha_s = _alpha(rot_s, trans_s, ri, sp[pi])
        lo = np.searchsorted(table.keys, keys, "left")
        hi = np.searchsorted(table.keys, keys, "right")
        counts = hi - lo
        total = int(counts.sum())
        diag: dict[str, Any] = {"scene_points": len(sp), "references": n_ref, "matches": total}
        if total == 0:
            return []
        pair = np.repeat(np.arange(len(keys)), counts)
        entry = np.repeat(lo, counts) + (np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts))
        alpha = table.alphas[entry] - alpha_s[pair]  # rotation about x taking the model partner onto the scene's
        na = self.alpha_bins
        abin = (np.floor((alpha + math.pi) / (2.0 * math.pi) * na).astype(np.int64)) % na
        n_m = len(table.cloud.points)
        flat = (ri[pair].astype(np.int64) * n_m + table.refs[entry]) * na + abin
        acc = np.bincount(flat, minlength=n_ref * n_m * na).reshape(n_ref, n_m * na)
        best = acc.argmax(axis=1)
        votes = acc[np.arange(n_ref), best]
        m_ref, a_best = best // na, best % na
        angle = (a_best + 0.5) * 2.0 * math.pi / na - math.pi
        poses = np.empty((n_ref, 4, 4))
        for k in range(n_ref):
            poses[k] = self._pose(rot_s[k], trans_s[k], table.rotations[m_ref[k]], table.translations[m_ref[k]],
                                  -angle[k])
        candidates = self._cluster_poses(poses, votes, table.diameter)
        diag["vote_seconds"] = time.perf_counter() - started
        chosen = [(pose, {**diag, "votes": int(v)}) for pose, v in candidates[: self.peaks]]
        return self._finish(cluster, model, table.cloud, chosen, scans, started)

    @staticmethod
    def _pose(r_s: np.ndarray, t_s: Array, r_m: np.ndarray, t_m: Array, alpha: float) -> Pose:
        """world_T_model = T_{s→g}^{-1} R_x(alpha) T_{m→g} (Drost Eq. 2)."""
        c, s = math.cos(alpha), math.sin(alpha)
        rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
        rot = r_s.T @ rx @ r_m
        out = np.eye(4)
        out[:3, :3] = rot
        out[:3, 3] = r_s.T @ (rx @ t_m - t_s)
        return out

    def _cluster_poses(self, poses: np.ndarray, votes: np.ndarray, diameter: float) -> list[tuple[Pose, int]]:
        """Greedy pose clustering (Drost §3.4): sum the votes of similar poses, average each cluster.

        A reference point none of whose pairs matched has no vote and no pose; it is left out (a
        cluster of such points alone has no weight to average with)."""
        voted = votes > 0
        poses, votes = poses[voted], votes[voted]
        order = np.argsort(-votes, kind="stable")
        max_t = self.cluster_translation * diameter
        max_r = math.radians(self.cluster_rotation_deg)
        groups: list[list[int]] = []
        for k in order:
            for group in groups:
                head = poses[group[0]]
                if np.linalg.norm(poses[k, :3, 3] - head[:3, 3]) > max_t:
                    continue
                r = head[:3, :3].T @ poses[k, :3, :3]
                if math.acos(float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))) <= max_r:
                    group.append(int(k))
                    break
            else:
                groups.append([int(k)])
        scored = [(mean_pose(poses[g], votes[g]), int(votes[g].sum())) for g in groups]
        scored.sort(key=lambda item: -item[1])
        return scored
