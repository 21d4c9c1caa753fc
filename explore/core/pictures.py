"""Pictures people want to look at: point clouds, meshes and curves as PNG (headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from explore.core.typed import Points3  # noqa: E402


def equal_axes(ax, points: Points3) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    center, half = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo)) + 1e-6
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")


def save_points_png(
    points: Points3,
    path: str | Path,
    title: str = "",
    colors: np.ndarray | None = None,
    extra: dict[str, Points3] | None = None,
    max_points: int = 40000,
    seed: int = 0,
    color_label: str = "height z [m]",
) -> None:
    """3-D scatter of a point cloud coloured by height (or by ``colors``, named ``color_label``), with a
    colour bar as its key."""
    fig = plt.figure(figsize=(7, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    if len(points):
        pick = np.random.default_rng(seed).permutation(len(points))[:max_points]
        shown = points[pick]
        c = colors[pick] if colors is not None else shown[:, 2]
        cloud = ax.scatter(shown[:, 0], shown[:, 1], shown[:, 2], c=c, s=0.6, cmap="viridis", depthshade=False)
        fig.colorbar(cloud, ax=ax, shrink=0.6, pad=0.1, label=color_label)
        everything = [shown] + [v for v in (extra or {}).values() if len(v)]
        equal_axes(ax, np.vstack(everything))
    for label, pts in (extra or {}).items():
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=14, marker="^", label=label)
    if extra:
        ax.legend(loc="upper left")
    ax.set_title(title or f"{len(points)} points")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_mesh_png(vertices: Points3, triangles: np.ndarray, path: str | Path, title: str = "") -> None:
    """Shaded snapshot of a triangle mesh."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(7, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    if len(triangles):
        tris = vertices[triangles]
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
        light = np.array([0.4, -0.5, 0.77])
        shade = 0.35 + 0.65 * np.abs(normals @ light)
        colors = plt.cm.bone(0.25 + 0.7 * shade)
        ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, linewidths=0))
        equal_axes(ax, vertices)
    ax.set_title(title or f"{len(triangles)} triangles")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_curves_png(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    path: str | Path,
    xlabel: str,
    ylabel: str,
    title: str = "",
) -> None:
    """Line plot of named (x, y) curves, with a legend; whole-number x (scans, views) gets whole ticks."""
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(6.5, 4), dpi=110)
    for label, (x, y) in curves.items():
        ax.plot(x, y, marker="o", markersize=3, label=label)
    if all(np.allclose(np.asarray(x, dtype=float), np.round(np.asarray(x, dtype=float))) for x, _ in curves.values()):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if title:
        ax.set_title(title)
    if curves:
        ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
