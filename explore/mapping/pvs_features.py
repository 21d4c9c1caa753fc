"""Surface features stored per voxel of the PVS (border, density, normals of the surface model, thesis Sec. 4.4),
for the utilities to read along their beams, and saving / loading the PVS with them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Array, Points3, equal_axes, plt
from explore.mapping.octomap_bt import CENTER, DEPTH, write_bt
from explore.mapping.pvs_grid import (
    FORMAT,
    logit,
)

if TYPE_CHECKING:
    from explore.mapping.pvs import PVS


class PVSFeatures:
    """Part of :class:`PVS`: per-voxel features and the npz file."""

    def save_png(self, path: str | Path, axis: int = 2, index: int | None = None, title: str = "") -> None:
        """Picture: a probability slice (black free, grey unknown, white occupied) and a 3-D view."""
        prob = 1.0 / (1.0 + np.exp(-self.log_odds.astype(np.float64)))
        occ = self.log_odds >= np.float32(logit(0.75))
        if index is None:
            per_slice = occ.sum(axis=tuple(a for a in range(3) if a != axis))
            index = int(np.argmax(per_slice)) if per_slice.any() else self.shape[axis] // 2
        index = int(np.clip(index, 0, self.shape[axis] - 1))
        plane = np.take(prob, index, axis=axis)
        other = [a for a in range(3) if a != axis]
        lo, hi = self.min_corner, self.max_corner
        fig = plt.figure(figsize=(11, 5), dpi=100)
        ax = fig.add_subplot(1, 2, 1)
        image = ax.imshow(
            plane.T, origin="lower", cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest",
            extent=(lo[other[0]], hi[other[0]], lo[other[1]], hi[other[1]]),
        )
        fig.colorbar(image, ax=ax, label="p(occupied): 0 free, 0.5 unknown, 1 occupied")
        names = "xyz"
        ax.set_xlabel(f"{names[other[0]]} [m]")
        ax.set_ylabel(f"{names[other[1]]} [m]")
        coord = (self.lattice[axis] + index + 0.5) * self.resolution
        ax.set_title(f"p at {names[axis]} = {coord:.3f} m")
        ax3 = fig.add_subplot(1, 2, 2, projection="3d")
        pts = self.occupied_points()
        if len(pts):
            pick = np.random.default_rng(0).permutation(len(pts))[:30000]
            shown = pts[pick]
            ax3.scatter(shown[:, 0], shown[:, 1], shown[:, 2], c=shown[:, 2], s=1.0, cmap="viridis")
            equal_axes(ax3, shown)
        c = self.counts()
        ax3.set_title(f"occupied {c['occupied']}, unknown {c['unknown']}, free {c['free']}")
        fig.suptitle(title or f"PVS {self.shape} @ {self.resolution * 1000:.0f} mm ({self.mode})")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)

    # -- surface features (thesis Sec. 4.5.1) -------------------------------------------
    def _feature(self, name: str, channels: int = 0) -> np.ndarray:
        if name not in self.features:
            shape = self.shape + ((channels,) if channels else ())
            self.features[name] = np.full(shape, np.nan, dtype=np.float32)
        return self.features[name]

    def set_features(
        self,
        points: Points3,
        density: Array | None = None,
        normals: Points3 | None = None,
        border: Array | None = None,
    ) -> int:
        """Write surface features at the voxels containing ``points`` (thesis Eqs. 4.24-4.28).

        Per voxel the values of the points inside it are averaged: density d̄_i (4.26),
        normal n̄_i (4.27, not re-normalised), border-edge ratio b_i (4.28). Voxels touched
        are overwritten; others keep their values (NaN where never set). Returns the number
        of voxels written.
        """
        ijk, inside = self.index(points)
        if not inside.any():
            return 0
        flat = np.ravel_multi_index(tuple(ijk[inside].T), self.shape)
        cells, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)

        def mean(values: np.ndarray) -> np.ndarray:
            values = np.asarray(values, dtype=np.float64)[inside]
            if values.ndim == 1:
                return np.bincount(inverse, values, len(cells)) / counts
            return np.column_stack(
                [np.bincount(inverse, values[:, c], len(cells)) for c in range(values.shape[1])]
            ) / counts[:, None]

        where = np.unravel_index(cells, self.shape)
        if density is not None:
            self._feature("density")[where] = mean(density)
        if border is not None:
            self._feature("border")[where] = mean(border)
        if normals is not None:
            self._feature("normal", 3)[where] = mean(np.asarray(normals).reshape(-1, 3))
        self._touch()
        return len(cells)

    def feature(self, name: str, points: Points3) -> np.ndarray:
        """Feature values at the voxels containing ``points`` (NaN where unset or outside)."""
        if name not in self.features:
            return np.full((len(np.asarray(points).reshape(-1, 3)),) + ((3,) if name == "normal" else ()), np.nan)
        values = self.features[name]
        ijk, inside = self.index(points)
        out = np.full((len(ijk),) + values.shape[3:], np.nan)
        out[inside] = values[tuple(ijk[inside].T)]
        return out

    # -- persistence -------------------------------------------------------------------
    def _params(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "resolution": self.resolution,
            "mode": self.mode,
            "p_free": self.p_free,
            "p_occ": self.p_occ,
            "clamp": list(self.clamp),
            "k_sigma": self.k_sigma,
            "sigma_floor": self.sigma_floor,
            "independence_filter": self.independence_filter,
            "independence_cell": self.independence_cell,
            "independence_angle_deg": self.independence_angle_deg,
            "hit_wins": self.hit_wins,
        }

    def save_octomap(self, path: str | Path) -> int:
        """Write the observed voxels as an OctoMap binary tree (``.bt``, maximum likelihood: log-odds
        > 0 occupied, < 0 free; unobserved voxels stay unknown); returns the tree's node count."""
        ijk = np.argwhere(self.log_odds != 0.0)
        keys = ijk + self.lattice + CENTER
        if len(keys) and (keys.min() < 0 or keys.max() >= 1 << DEPTH):
            raise ValueError(f"{path}: the PVS reaches beyond OctoMap's key range (+-{CENTER} voxels from the origin)")
        occupied = self.log_odds[ijk[:, 0], ijk[:, 1], ijk[:, 2]] > 0.0
        return write_bt(path, keys, occupied, self.resolution)

    def save(self, path: str | Path) -> None:
        """Write the PVS (log-odds, parameters, features, filter state) to a ``.npz`` file."""
        arrays = {
            "log_odds": self.log_odds,
            "lattice": self.lattice,
            "beam_keys": self._beam_keys,
            "params": np.array(json.dumps(self._params())),
        }
        for name, values in self.features.items():
            arrays[f"feature_{name}"] = values
        with open(path, "wb") as handle:
            np.savez_compressed(handle, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> PVS:
        """Read a PVS written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as data:
            params = json.loads(str(data["params"]))
            if params.pop("format", None) != FORMAT:
                raise ValueError(f"{path}: not a PVS file of format {FORMAT}")
            lattice = data["lattice"].astype(np.int64)
            log_odds = data["log_odds"].astype(np.float32)
            resolution = params.pop("resolution")
            lo = lattice * resolution
            hi = (lattice + np.asarray(log_odds.shape)) * resolution
            pvs = cls(lo, hi, resolution, clamp=tuple(params.pop("clamp")), **params)
            if pvs.shape != log_odds.shape:  # guard the lattice rounding
                raise ValueError(f"{path}: grid shape mismatch")
            pvs.lattice = lattice
            pvs.log_odds = log_odds
            pvs._beam_keys = data["beam_keys"].astype(np.int64)
            for key in data.files:
                if key.startswith("feature_"):
                    pvs.features[key[len("feature_") :]] = data[key].astype(np.float32)
        return pvs
