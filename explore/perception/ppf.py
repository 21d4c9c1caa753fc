"""Drost et al. 2010 point-pair features (Kriegel thesis Eq. 3.9): voting over (model reference point, alpha),
pose clustering, ICP refinement and render-and-compare verification q_h as quality."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, mean_pose
from explore.perception.hypotheses import Q_H_MIN, Hypothesis, Model
from explore.perception.model_data import ModelCloud, has_normal, model_cloud, oriented
from explore.perception.ppf_votes import best_votes, pairs_within
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
    """Hash table of a model's point pairs: sorted keys with (reference index, alpha_m); the distinct
    keys and where each one's entries start (``starts`` ends with the number of entries)."""

    cloud: ModelCloud
    keys: np.ndarray
    refs: np.ndarray
    alphas: Array
    rotations: np.ndarray
    translations: Points3
    distance_step: float
    angle_bins: int
    diameter: float
    distinct: np.ndarray = field(init=False)
    starts: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.distinct, first = np.unique(self.keys, return_index=True)
        self.starts = np.append(first, len(self.keys))

    def entries(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): the table entries ``lo:hi`` of each key (lo = hi where the table has none)."""
        at = np.minimum(np.searchsorted(self.distinct, keys), len(self.distinct) - 1)
        found = self.distinct[at] == keys
        return np.where(found, self.starts[at], 0), np.where(found, self.starts[at + 1], 0)


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
        best, votes, total, rot_s, trans_s = self.vote(sp, sn, refs, table)
        diag: dict[str, Any] = {"scene_points": len(sp), "references": n_ref, "matches": total}
        if total == 0:
            return []
        na = self.alpha_bins
        m_ref, a_best = best // na, best % na
        angle = (a_best + 0.5) * 2.0 * math.pi / na - math.pi
        voted = np.flatnonzero(votes > 0)  # a reference none of whose pairs matched has no pose
        poses = np.empty((len(voted), 4, 4))
        for i, k in enumerate(voted):
            poses[i] = self._pose(rot_s[k], trans_s[k], table.rotations[m_ref[k]], table.translations[m_ref[k]],
                                  -angle[k])
        candidates = self._cluster_poses(poses, votes[voted], table.diameter, keep=self.peaks)
        diag["vote_seconds"] = time.perf_counter() - started
        chosen = [(pose, {**diag, "votes": int(v)}) for pose, v in candidates]
        return self._finish(cluster, model, table.cloud, chosen, scans, started)

    def vote(self, sp: Points3, sn: Points3, refs: np.ndarray, table: PPFTable
             ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, Points3]:
        """Drost's voting (Sec. 3.3) for the scene references ``refs`` of the oriented points (sp, sn):
        per reference the best accumulator cell (model reference * alpha_bins + alpha bin) and its
        votes, the number of table matches, and the references' alignments T_{s→g} (R, t)."""
        ri, pi = pairs_within(sp, refs, table.diameter)
        dist, f1, f2, f3 = _pair_features(sp[refs[ri]], sn[refs[ri]], sp[pi], sn[pi])
        close = dist <= table.diameter
        ri, pi, dist, f1, f2, f3 = ri[close], pi[close], dist[close], f1[close], f2[close], f3[close]
        keys = self._keys(dist, f1, f2, f3, table.distance_step)
        rot_s, trans_s = _align_to_x(sp[refs], sn[refs])
        lo, hi = table.entries(keys)
        total = int((hi - lo).sum())
        if total == 0:
            return np.zeros(len(refs), np.int64), np.zeros(len(refs), np.int64), 0, rot_s, trans_s
        alpha_s = _alpha(rot_s, trans_s, ri, sp[pi])
        best, votes = best_votes(ri, lo, hi, table.alphas, table.refs, alpha_s, len(refs), len(table.cloud.points),
                                 self.alpha_bins)
        return best, votes, total, rot_s, trans_s

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

    def _cluster_poses(self, poses: np.ndarray, votes: np.ndarray, diameter: float,
                       keep: int | None = None) -> list[tuple[Pose, int]]:
        """Greedy pose clustering (Drost §3.4): sum the votes of similar poses, average each cluster;
        the ``keep`` clusters with the most votes (all by default), most first.

        A pose joins the first cluster whose first pose lies within the translation and rotation
        limits. A reference point none of whose pairs matched has no vote and no pose; it is left
        out (a cluster of such points alone has no weight to average with)."""
        voted = votes > 0
        poses, votes = poses[voted], votes[voted]
        order = np.argsort(-votes, kind="stable")
        max_t = self.cluster_translation * diameter
        max_r = math.radians(self.cluster_rotation_deg)
        head_t, head_r = np.empty((len(order), 3)), np.empty((len(order), 3, 3))
        groups: list[list[int]] = []
        for k in order:
            n = len(groups)
            near = np.flatnonzero(np.linalg.norm(head_t[:n] - poses[k, :3, 3], axis=1) <= max_t)
            trace = np.einsum("nij,ij->n", head_r[near], poses[k, :3, :3])  # trace(head^T R)
            turned = np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))
            within = near[turned <= max_r]
            if len(within):
                groups[int(within[0])].append(int(k))
            else:
                head_t[n], head_r[n] = poses[k, :3, 3], poses[k, :3, :3]
                groups.append([int(k)])
        totals = [int(votes[g].sum()) for g in groups]
        ranked = sorted(range(len(groups)), key=lambda g: -totals[g])[:keep]
        return [(mean_pose(poses[groups[g]], votes[groups[g]]), totals[g]) for g in ranked]
