"""A run's video (``explore run ... --video`` writes ``run.mp4``): one frame per scan.

Each frame shows, side by side, the scan's depth image (colour-mapped; a line sensor's sweep as
an image of stripes), the growing model (every return so far, on a 5 mm grid, seen from a fixed
viewpoint above the region) and a horizontal slice of the run's probabilistic voxel space through
the objects (occupied / free / unknown), with the scan number, the running
step and the run's status line (its coverage) written above them (OpenCV ``VideoWriter``).

:func:`record_scans` wraps the simulation's sensor: every acquisition is handed on unchanged
(the same beams, noise and random numbers, so a video changes no metric) and the frame of what
came back is drawn.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import invert, look_at, transform_points

PANEL = (320, 240)  # width, height of each panel
BANNER = 36  # px of text above the panels
FPS = 2.0
_UNKNOWN, _FREE, _OCCUPIED = (90, 90, 90), (235, 225, 200), (40, 40, 200)  # BGR


class RunVideo:
    """Frames of a run's scans, written to ``path`` as they come."""

    def __init__(self, path: Path, context: Any) -> None:
        import cv2

        self.path = path
        self.context = context
        self.frames = 0
        self._points = np.zeros((0, 3))
        self._lock = threading.Lock()
        size = (3 * PANEL[0], PANEL[1] + BANNER)
        self._writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), FPS, size)
        if not self._writer.isOpened():
            raise OSError(f"{path}: OpenCV cannot write an mp4 video here")
        spec = context.sim.spec
        centre = 0.5 * (spec.region_min + spec.region_max)
        extent = float(np.linalg.norm(spec.region_max - spec.region_min))
        eye = centre + extent * np.array([0.6, -0.9, 0.8]) if spec.overview is None else spec.overview[:3]
        self._view = invert(look_at(eye, centre if spec.overview is None else spec.overview[3:]))
        self._spread = np.full(2, 1e-3)  # the largest extent of the model seen so far (tan of the angle)

    def add(self, scan: Any) -> None:
        """Draw and write the frame of one scan (any thread; frames keep the order of the scans)."""
        with self._lock:
            hits = scan.points()
            keys = np.unique(np.floor(np.vstack([self._points, hits]) / 0.005).astype(np.int64), axis=0)
            self._points = (keys + 0.5) * 0.005
            self.frames += 1
            panels = [self._depth_panel(scan), self._model_panel(), self._pvs_panel()]
            frame = np.vstack([self._banner(), np.hstack(panels)])
            self._writer.write(frame)

    def close(self) -> None:
        self._writer.release()

    # -- panels ----------------------------------------------------------------------------------
    def _banner(self) -> np.ndarray:
        import cv2

        image = np.full((BANNER, 3 * PANEL[0], 3), 255, np.uint8)
        step = self.context.activity or ""
        text = f"scan {self.frames}  {self.context.status_line or ''}  {step}".strip()
        cv2.putText(image, text[:110], (6, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        return image

    @staticmethod
    def _depth_panel(scan: Any) -> np.ndarray:
        import cv2

        ranges = np.asarray(scan.ranges, dtype=float)
        shape = scan.image_shape
        image = ranges.reshape(shape)[0] if shape is not None else ranges[None, :]
        valid = np.isfinite(image)
        lo, hi = (np.nanmin(image), np.nanmax(image)) if valid.any() else (0.0, 1.0)
        scaled = np.where(valid, 255.0 * (image - lo) / max(hi - lo, 1e-9), 0.0).astype(np.uint8)
        coloured = cv2.applyColorMap(255 - scaled, cv2.COLORMAP_TURBO)
        coloured[~valid] = 0
        return cv2.resize(coloured, PANEL, interpolation=cv2.INTER_NEAREST)

    def _model_panel(self) -> np.ndarray:
        """The returns so far seen from the fixed viewpoint (a pinhole splat, near points on top)."""
        image = np.full((PANEL[1], PANEL[0], 3), 255, np.uint8)
        local = transform_points(self._view, self._points)
        front = local[:, 2] > 1e-3
        local = local[front]
        if len(local) == 0:
            return image
        spread = np.percentile(np.abs(local[:, :2] / local[:, 2:]), 99.5, axis=0)
        self._spread = np.maximum(self._spread, spread)  # zoom out as the model grows, never in
        f = 0.45 * min(PANEL[0] / self._spread[0], PANEL[1] / self._spread[1])
        u = (f * local[:, 0] / local[:, 2] + 0.5 * PANEL[0]).astype(int)
        v = (f * local[:, 1] / local[:, 2] + 0.5 * PANEL[1]).astype(int)
        inside = (u >= 0) & (u < PANEL[0]) & (v >= 0) & (v < PANEL[1])
        order = np.argsort(-local[inside, 2])  # far first, near last (drawn on top)
        height = self._points[front][inside][order, 2]
        shade = (60 + 180 * (height - height.min()) / max(np.ptp(height), 1e-9)).astype(np.uint8)
        colours = np.column_stack([shade, 255 - shade, 120 * np.ones_like(shade)])
        rows, cols = v[inside][order], u[inside][order]
        for dr, dc in ((0, 0), (0, 1), (1, 0), (1, 1)):  # 2 x 2 px splats: a surface, not dots
            image[np.minimum(rows + dr, PANEL[1] - 1), np.minimum(cols + dc, PANEL[0] - 1)] = colours
        return image

    def _pvs_panel(self) -> np.ndarray:
        """A horizontal slice of the run's PVS through the objects (:func:`slice_height`)."""
        import cv2

        pvs = _find_pvs(self.context.state)
        image = np.full((PANEL[1], PANEL[0], 3), 255, np.uint8)
        if pvs is None:
            return image
        layer = pvs_layer(pvs)[::-1]  # rows: y up, columns: x
        colours = np.empty((*layer.shape, 3), np.uint8)
        colours[:] = _UNKNOWN
        colours[layer < -1e-3] = _FREE
        colours[layer > 1e-3] = _OCCUPIED
        scale = min(PANEL[0] / layer.shape[1], PANEL[1] / layer.shape[0])
        size = (max(1, int(layer.shape[1] * scale)), max(1, int(layer.shape[0] * scale)))
        small = cv2.resize(colours, size, interpolation=cv2.INTER_NEAREST)
        image[: size[1], : size[0]] = small
        return image


def pvs_layer(pvs: Any, cells: int = 2 * PANEL[0]) -> np.ndarray:
    """Log-odds (ny, nx) of the horizontal layer of voxels :func:`slice_height` picks, sampled at voxel
    centres (at most ``cells`` per side): the same picture from a dense grid and from a sparse one."""
    occupied = pvs.occupied_points(0.5003)  # log-odds above 1e-3
    heights = np.floor(occupied[:, 2] / pvs.resolution).astype(np.int64) - pvs.lattice[2]
    k = slice_height(np.bincount(heights, minlength=pvs.shape[2])) if len(occupied) else pvs.shape[2] // 2
    step = max(1, int(np.ceil(max(pvs.shape[:2]) / cells)))
    i, j = np.arange(0, pvs.shape[0], step), np.arange(0, pvs.shape[1], step)
    ijk = np.stack(np.meshgrid(i, j, [k], indexing="xy"), axis=-1).reshape(-1, 3)
    return pvs.log_odds_at(pvs.centers(ijk)).reshape(len(j), len(i))


def slice_height(counts: np.ndarray) -> int:
    """The z index of the slice to show, from the occupied voxels per layer: the layer with the most, or,
    when that layer is a support (a table top: over a third of them), the median height of those above it."""
    k = int(np.argmax(counts))
    above = counts[k + 2:]
    if counts[k] > counts.sum() / 3 and above.sum() > 0:
        cumulative = np.cumsum(above)
        return k + 2 + int(np.searchsorted(cumulative, cumulative[-1] / 2))
    return k


def _find_pvs(state: dict[str, Any]) -> Any:
    """The PVS of the run's session (a modelling, NBVS or scene session kept in the run's state)."""
    for value in list(state.values()):
        for holder in (value, getattr(value, "session", None)):
            pvs = getattr(holder, "pvs", None)
            if pvs is not None and hasattr(pvs, "occupied_points"):
                return pvs
    return None


def record_scans(sensor: Any, video: RunVideo) -> None:
    """Have every acquisition of ``sensor`` also drawn into ``video``: its ``acquire`` is wrapped
    on the instance (the class, and every other call, stay the sensor's own)."""
    acquire = sensor.acquire

    def recorded(sim: Any, target: Any, rng: np.random.Generator) -> Any:
        scan = acquire(sim, target, rng)
        video.add(scan)
        return scan

    sensor.acquire = recorded


def read_frames(path: Path) -> list[np.ndarray]:
    """Every frame of a video (BGR), for checks and the report."""
    import cv2

    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return frames
