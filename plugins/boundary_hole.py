"""Built-in view generators from the model's surface: Boundary Search, Hole Rescan and both
together (Kriegel thesis Sec. 4.2-4.4; Algorithm 1 splits borders, Algorithm 3 repairs candidates)."""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.api import ViewGenerator
from explore.core import Array, Param, Points3, fibonacci_sphere
from explore.mapping import SUPPORT_MARGIN, first_blocked
from explore.nbv import (
    Candidate,
    PlanningContext,
    RepairSettings,
    any_sweep,
    footprint_width,
    frame_from,
    in_environment_boxes,
    make_target,
    repair,
    segments_hit_boxes,
    standoff_for,
)
from explore.sim import ScanPath


# ---------------------------------------------------------------------------------------
# boundary search (thesis Sec. 4.2-4.3)
# ---------------------------------------------------------------------------------------
def _segments(walk: np.ndarray, edge_dirs: Points3, axes: tuple[Array, Array], alpha_t: float, rho_t: int,
              b_min: int) -> list[tuple[int, int, int]]:
    """Algorithm 1 on one border walk: split into straight boundaries.

    ``edge_dirs`` are the unit directions of the walk's edges. The first edge of a boundary
    picks the sensor axis it is closest to (Table 4.1); later edges count as deviating when
    their angle to that (signed) axis exceeds ``alpha_t``; ``rho_t`` + 1 deviating edges in a
    row end the boundary. Returns (first edge, last edge, axis index) of boundaries with at
    least ``b_min`` edges.
    """
    out = []
    n = len(edge_dirs)
    cos_t = np.cos(alpha_t)
    i = 0
    while i < n:
        c = [float(np.dot(edge_dirs[i], a)) for a in axes]
        axis = int(np.argmax(np.abs(c)))
        s = np.sign(c[axis]) * axes[axis]
        rho = 0
        j = i + 1
        last_good = i
        while j < n:
            if float(np.dot(edge_dirs[j], s)) < cos_t:
                rho += 1
                if rho > rho_t:
                    break
            else:
                rho = 0
                last_good = j
            j += 1
        if last_good - i + 1 >= b_min:
            out.append((i, last_good, axis))
        i = last_good + 1 if last_good > i else i + 1
    return out


class Boundary(ViewGenerator):
    """Boundary Search: scan paths that extend the latest scan's mesh boundaries (thesis Sec. 4.2-4.3)."""

    name = "boundary"
    params = (
        Param("alpha_t_deg", float, 45.0, "deg", "angle threshold alpha_t (Algorithm 1)", low=0.0, high=180.0),
        Param("rho_t", int, 5, "", "deviating edges in a row that end a boundary (rho_t)", low=0),
        Param("b_min", int, 15, "", "minimum boundary length in edges", low=2),
        Param("overlap", float, 0.3, "", "overlap o of the new view with the known mesh (Eq. 4.14) [UNSPEC]",
              low=0.0, high=0.95),
        Param("step", float, 0.002, "m", "step Delta p along the extrapolated patch [UNSPEC]", low=1e-4),
        Param("max_turn_deg", float, 60.0, "deg", "stop extrapolating when the patch normal turns more", low=1.0),
        Param("region_radius", float, 0.03, "m", "radius of the region grown into the mesh for the patch fit",
              low=0.005),
        Param("weight_sigma", float, 0.01, "m", "w_i = exp(-dist to boundary / sigma) (Eq. 4.11 [INTERP])",
              low=1e-4),
        Param("planar_eig", float, 0.09, "", "planar if both larger eigenvalues of C_N <= this (Eq. 4.19-4.21)",
              low=0.0),
        Param("corner_deg", float, 45.0, "deg", "rotation about the boundary at a sharp corner", low=0.0),
        Param("standoff", float, 0.0, "m", "sensor distance d_s; 0 = the sensor's optimal distance", low=0.0),
        Param("floor_margin", float, 0.012, "m", "ignore boundaries this close to the region floor (the support)",
              low=0.0),
        Param("whole_mesh_fallback", bool, True, "", "search the whole mesh when the latest scan gives none"),
        Param("max_candidates", int, 40, "", "keep at most this many per iteration (longest boundaries)", low=1),
        Param("repair", bool, True, "", "occlusion/collision repair (Algorithm 3)"),
    )

    def boundaries(self, ctx: PlanningContext, current_only: bool = True) -> list[dict[str, Any]]:
        """Detected boundaries: vertex indices, type, outward direction (thesis Sec. 4.2.1)."""
        surface = ctx.surface
        mesh = surface.mesh
        if len(mesh.triangles) == 0:
            return []
        vertices = mesh.vertices
        normals = surface.vertex_normals
        current = surface.current_vertices() if current_only else np.ones(len(vertices), dtype=bool)
        pose = ctx.last_scan.sensor_poses[len(ctx.last_scan.sensor_poses) // 2] if ctx.last_scan is not None \
            else np.eye(4)
        axes = (pose[:3, 1], pose[:3, 0])  # Table 4.1: s = y axis (scan direction), s = x axis (fan)
        floor = ctx.region_min[2] + self.floor_margin
        found = []
        border = {(int(a), int(b)) for a, b in surface.border_edges()}
        for walk in surface.boundary_loops():
            closed = len(walk) > 2 and (int(walk[-1]), int(walk[0])) in border
            if closed:  # start a closed loop at its sharpest turn, so no straight part is split
                d = np.diff(vertices[np.append(walk, walk[0])], axis=0)
                d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
                turn = np.einsum("ij,ij->i", d, np.roll(d, 1, axis=0))
                walk = np.roll(walk, -int(np.argmin(turn)))
            seq = np.append(walk, walk[0]) if closed else walk
            # runs of edges inside M_cur and above the floor
            ok = current[seq[:-1]] & current[seq[1:]] & (vertices[seq[:-1], 2] > floor) & (vertices[seq[1:], 2] > floor)
            if not ok.any():
                continue
            edges = np.diff(vertices[seq], axis=0)
            lengths = np.linalg.norm(edges, axis=1)
            dirs = edges / np.maximum(lengths[:, None], 1e-12)
            run_start = None
            for e in range(len(ok) + 1):
                if e < len(ok) and ok[e]:
                    run_start = e if run_start is None else run_start
                    continue
                if run_start is None:
                    continue
                run = np.arange(run_start, e)
                run_start = None
                for a, b, axis in _segments(walk, dirs[run], axes, np.deg2rad(self.alpha_t_deg), self.rho_t,
                                            self.b_min):
                    idx = seq[run[a] : run[b] + 2]
                    pts = vertices[idx]
                    n_mean = normals[idx].mean(axis=0)
                    n_mean /= max(np.linalg.norm(n_mean), 1e-12)
                    d_b = pts[-1] - pts[0]
                    if np.linalg.norm(d_b) < 1e-6:
                        continue
                    d_b /= np.linalg.norm(d_b)
                    outward = np.cross(d_b, n_mean)  # surface on the left of the walk: unknown on the right
                    outward -= np.dot(outward, n_mean) * n_mean
                    outward /= max(np.linalg.norm(outward), 1e-12)
                    if current_only and np.dot(n_mean, -pose[:3, 2]) < 0.0:  # faces away from the sensor
                        continue
                    if axis == 0:
                        kind = "left" if np.dot(outward, pose[:3, 0]) < 0 else "right"
                    else:
                        kind = "top" if np.dot(outward, pose[:3, 1]) < 0 else "bottom"
                    found.append({"vertices": idx, "type": kind, "direction": d_b, "outward": outward,
                                  "normal": n_mean, "length": float(lengths[run[a] : run[b] + 1].sum())})
        found.sort(key=lambda f: -f["length"])
        return found

    def _trend(self, ctx: PlanningContext, boundary: dict[str, Any]) -> dict[str, Any] | None:
        """Quadratic patch z = f(u, v) by weighted least squares (Eq. 4.5-4.11) and the viewpoint (4.12-4.18)."""
        vertices = ctx.surface.mesh.vertices
        normals = ctx.surface.vertex_normals
        idx = boundary["vertices"]
        c_b = vertices[idx[len(idx) // 2]]  # Eq. 4.4
        d_b, out, n0 = boundary["direction"], boundary["outward"], boundary["normal"]
        # local frame: u along the boundary, v towards the unknown, w along the normal
        v_axis = out
        w_axis = np.cross(d_b, v_axis)
        if np.dot(w_axis, n0) < 0:
            w_axis = -w_axis
        u_axis = np.cross(v_axis, w_axis)
        half = 0.5 * boundary["length"]
        rel = vertices - c_b
        u, v, w = rel @ u_axis, rel @ v_axis, rel @ w_axis
        near = (np.abs(u) <= half + 0.005) & (v <= 0.005) & (v >= -self.region_radius)
        near &= np.abs(w) < self.region_radius
        near &= normals @ n0 > 0.0
        if np.count_nonzero(near) < 6:
            return None
        bpts = vertices[idx]
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(bpts).query(vertices[near])
        weight = np.exp(-dist / self.weight_sigma)
        uu, vv, ww = u[near], v[near], w[near]
        design = np.column_stack([uu**2, uu * vv, vv**2, uu, vv, np.ones_like(uu)])
        sw = np.sqrt(weight)
        coef, *_ = np.linalg.lstsq(design * sw[:, None], ww * sw, rcond=None)  # SVD-based (Eq. 4.10)
        a1, a2, a3, a4, a5, a6 = coef

        def patch(vq: float) -> tuple[Array, Array]:
            z = a3 * vq**2 + a5 * vq + a6
            n_local = np.array([a4 + a2 * vq, 2 * a3 * vq + a5, -1.0])  # Eq. 4.13 at u = 0
            point = c_b + vq * v_axis + z * w_axis
            normal = -(n_local[0] * u_axis + n_local[1] * v_axis + n_local[2] * w_axis)
            return point, normal / np.linalg.norm(normal)

        standoff = standoff_for(ctx, self.standoff)
        target_v = footprint_width(ctx, standoff) * (0.5 - self.overlap)  # Eq. 4.14: overlap o of the stripe
        p, n = patch(0.0)
        n_start = n
        vq = 0.0
        while vq + self.step <= target_v:
            p_next, n_next = patch(vq + self.step)
            if np.degrees(np.arccos(np.clip(np.dot(n_next, n_start), -1, 1))) > self.max_turn_deg:
                break
            vq += self.step
            p, n = p_next, n_next
        # planarity of the region (Eq. 4.19-4.21) and the sharp-corner rotation (Fig. 4.7)
        region_normals = normals[near]
        centred = region_normals - region_normals.mean(axis=0)
        eig = np.sort(np.linalg.eigvalsh(centred.T @ centred / len(centred)))
        planar = bool(eig[1] <= self.planar_eig and eig[2] <= self.planar_eig)
        at_fov_limit = self._at_fov_limit(ctx, bpts)
        corner = planar and not at_fov_limit and self.corner_deg > 0
        if corner:
            view_normal = np.cos(np.deg2rad(self.corner_deg)) * n0 + np.sin(np.deg2rad(self.corner_deg)) * out
            n = view_normal / np.linalg.norm(view_normal)
            p = c_b
        return {"point": p, "normal": n, "c_b": c_b, "corner": corner, "planar": planar}

    @staticmethod
    def _at_fov_limit(ctx: PlanningContext, points: Points3) -> bool:
        """True if the boundary lies on the limiting line of sight of the latest scan."""
        scan = ctx.last_scan
        if scan is None:
            return True
        poses = scan.sensor_poses
        mid = poses[len(poses) // 2]
        local = (points - mid[:3, 3]) @ mid[:3, :3]
        dirs = ctx.sensor.local_directions()
        half = float(np.max(np.abs(dirs[:, 0] / np.maximum(dirs[:, 2], 1e-6))))
        ratio = np.abs(local[:, 0]) / np.maximum(local[:, 2], 1e-6)
        if np.median(ratio) > 0.85 * half:
            return True
        if len(poses) > 1:
            y0 = (poses[0][:3, 3] - mid[:3, 3]) @ mid[:3, 1]
            y1 = (poses[-1][:3, 3] - mid[:3, 3]) @ mid[:3, 1]
            lo, hi = min(y0, y1), max(y0, y1)
            ys = local[:, 1]
            if np.median(ys) < lo + 0.01 or np.median(ys) > hi - 0.01:
                return True
        return False

    def candidates_for(self, ctx: PlanningContext, boundaries: list[dict[str, Any]]) -> list[Candidate]:
        out = []
        standoff = standoff_for(ctx, self.standoff)
        vertices = ctx.surface.mesh.vertices
        for number, boundary in enumerate(boundaries[: self.max_candidates]):
            trend = self._trend(ctx, boundary)
            if trend is None:
                continue
            view = -trend["normal"]
            pose = frame_from(view, boundary["direction"], trend["point"] - standoff * view)  # Eq. 4.15-4.18
            if pose is None:
                continue
            target = make_target(ctx.sensor, pose, vertices, standoff)  # Sec. 4.3.2: across the object extent
            focus = vertices[boundary["vertices"][:: max(1, len(boundary["vertices"]) // 12)]]
            info = {"kind": "boundary", "id": number, "type": boundary["type"], "corner": trend["corner"],
                    "length": boundary["length"]}
            cand = Candidate(target, self.name, info, focus, ctx.iteration)
            if self.repair:
                cand = repair(cand, ctx, trend["point"], standoff, vertices, RepairSettings())
                if cand is None:
                    continue
            out.append(cand)
        return out

    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        found = self.boundaries(ctx, current_only=True)
        cands = self.candidates_for(ctx, found)
        if not cands and self.whole_mesh_fallback and (ctx.stack is None or len(ctx.stack) == 0):
            cands = self.candidates_for(ctx, self.boundaries(ctx, current_only=False))
        return cands


# ---------------------------------------------------------------------------------------
# hole rescan (thesis Sec. 4.4)
# ---------------------------------------------------------------------------------------
class HoleRescan(ViewGenerator):
    """Hole Rescan: one short scan path over each closed hole, occlusion-free normal (thesis Sec. 4.4)."""

    name = "hole"
    params = (
        Param("h_min", int, 5, "", "smallest hole in border edges [UNSPEC]", low=3),
        Param("h_max", int, 300, "", "largest hole in border edges (excludes the bottom opening) [UNSPEC]", low=3),
        Param("directions", int, 200, "", "directions sampled for the occlusion-free normal (Alg. 2)", low=8),
        Param("p_block", float, 0.75, "", "voxels from this occupancy on occlude a direction (Alg. 2); "
              "0.75 = the thesis' occupied class, so thin surfaces not yet at 0.95 still occlude",
              low=0.5, high=1.0),
        Param("pick", float, 0.2, "", "lower_bound(front + pick (back - front)) of the free directions",
              low=0.0, high=1.0),
        Param("extend", float, 1.1, "", "path ends at c_h -/+ extend * d_h (Eq. 4.22-4.23)", low=0.1),
        Param("merge_distance", float, 0.02, "m", "merge holes with centres this close ...", low=0.0),
        Param("merge_angle_deg", float, 30.0, "deg", "... and normals within this angle", low=0.0),
        Param("contact_band", float, SUPPORT_MARGIN, "m",
              "skip holes lying entirely this close to the support (its contact footprint, unobservable); "
              "holes that touch the support and rise above it are scanned", low=0.0),
        Param("standoff", float, 0.0, "m", "sensor distance d_s; 0 = the sensor's optimal distance", low=0.0),
        Param("min_path", float, 0.03, "m", "shortest scan path", low=0.0),
        Param("repair", bool, True, "", "occlusion/collision repair (Algorithm 3)"),
        Param("max_directions", int, 8, "",
              "free directions of Algorithm 2 tried in turn when Algorithm 3 cannot repair the first "
              "(1 = the thesis' single direction)", low=1),
        Param("same_rim", float, 0.8, "",
              "a hole counts as already scanned when this share of its rim lies on the rim of a scanned "
              "hole (it did not change since); a hole the scan shrank is a new hole", low=0.0, high=1.0),
        Param("rim_tolerance", float, 0.004, "m", "rim vertices this close count as the same rim", low=0.0),
        Param("max_rescans", int, 3, "", "scans of one unchanged hole, each from a new direction (thesis: 1)",
              low=1),
        Param("rescan_angle_deg", float, 45.0, "deg",
              "a further scan of an unchanged hole must view it this differently from the earlier ones", low=0.0),
    )

    def reset(self) -> None:
        self.scanned: list[tuple[Array, Array, Points3, Array]] = []  # centre, normal, rim, view direction
        self._rims: dict[tuple[int, int], Points3] = {}  # (iteration, id) -> rim of the offered holes

    def remember(self, candidate: Candidate) -> None:
        """Called when a hole candidate is selected: the hole is not scanned again from there (Sec. 4.4)."""
        rim = self._rims.get((candidate.created, candidate.info.get("id", -1)))
        if rim is not None:
            info = candidate.info
            view = -np.asarray(candidate.pose)[:3, 2]
            self.scanned.append((np.asarray(info["centre"]), np.asarray(info["normal"]), rim, view))

    def used_directions(self, centre: Array, normal: Array, rim: Points3) -> Points3:
        """Directions (towards the sensor) this hole was scanned from before, (k, 3).

        The same hole = similar centre and normal and (``same_rim``) the same rim; a hole whose
        rim changed (the last scans closed part of it) is a new hole.
        """
        from scipy.spatial import cKDTree

        used = []
        for c, n, old_rim, view in self.scanned:
            if not self._similar(centre, normal, c, n):
                continue
            dist, _ = cKDTree(old_rim).query(rim, distance_upper_bound=self.rim_tolerance)
            if np.mean(np.isfinite(dist)) >= self.same_rim:
                used.append(view)
        return np.asarray(used).reshape(-1, 3)

    def _similar(self, c1: Array, n1: Array, c2: Array, n2: Array) -> bool:
        return bool(np.linalg.norm(c1 - c2) <= self.merge_distance
                    and np.dot(n1, n2) >= np.cos(np.deg2rad(self.merge_angle_deg)))

    def free_directions(self, ctx: PlanningContext, centre: Array, normal: Array, standoff: float) -> Points3:
        """Algorithm 2: occlusion-free view directions of a hole, best first.

        Of the ``directions`` samples, those whose ray from c_h out to d_s meets no occupied
        voxel (and no known environment box, and whose viewpoint is not below the support)
        are sorted by d_n = ‖n_h − ñ‖; the first returned is the thesis' choice
        lower_bound(front + 0.2 (back − front)), then the following ones in map order, then
        the ones before it (closest to n_h last), so a caller can fall back to the next free
        direction when Algorithm 3 cannot repair the first. Empty if the hole has no valid view.
        """
        dirs = fibonacci_sphere(self.directions)
        start = centre + 1.5 * ctx.grid.resolution * dirs
        t = first_blocked(ctx.grid, start, dirs, standoff, p_block=self.p_block)
        free = ~np.isfinite(t)
        eyes = centre + standoff * dirs
        free &= ~in_environment_boxes(ctx, eyes)
        free &= ~segments_hit_boxes(start, eyes, ctx.environment_boxes)  # the known environment occludes too
        free &= eyes[:, 2] >= ctx.lowest_sensor_z  # objects cannot be viewed from below (Sec. 4.1)
        if not free.any():
            return np.zeros((0, 3))
        candidates = dirs[free]
        key = np.linalg.norm(normal - candidates, axis=1)
        order = np.argsort(key, kind="stable")
        front, back = key[order[0]], key[order[-1]]
        first = int(np.searchsorted(key[order], front + self.pick * (back - front)))
        first = min(first, len(order) - 1)
        ranked = np.concatenate([order[first:], order[:first][::-1]])
        return candidates[ranked]

    def free_direction(self, ctx: PlanningContext, centre: Array, normal: Array, standoff: float) -> Array | None:
        """The thesis' single choice of Algorithm 2 (None if the hole has no valid view)."""
        found = self.free_directions(ctx, centre, normal, standoff)
        return found[0] if len(found) else None

    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        surface = ctx.surface
        holes = surface.holes(min_edges=self.h_min, max_edges=self.h_max)
        vertices = surface.mesh.vertices
        band = ctx.region_min[2] + self.contact_band
        kept = [h for h in holes if vertices[h.loop, 2].max() > band]
        # merge holes with similar centre and orientation
        groups: list[list[Any]] = []
        for hole in kept:
            for group in groups:
                if self._similar(group[0].centre, group[0].normal, hole.centre, hole.normal):
                    group.append(hole)
                    break
            else:
                groups.append([hole])
        standoff = standoff_for(ctx, self.standoff)
        out = []
        for number, group in enumerate(groups):
            loop_pts = np.vstack([vertices[h.loop] for h in group])
            centre = loop_pts.mean(axis=0)
            normal = group[0].normal / np.linalg.norm(group[0].normal)
            used = self.used_directions(centre, normal, loop_pts)
            if len(used) >= self.max_rescans:
                continue
            info = {"kind": "hole", "id": number, "centre": centre.tolist(), "normal": normal.tolist(),
                    "holes": len(group), "edges": int(sum(h.size for h in group))}
            self._rims[(ctx.iteration, number)] = loop_pts
            tried = 0
            anchor = centre
            directions = self.free_directions(ctx, centre, normal, standoff)
            if len(directions) == 0:
                ring = loop_pts[:: max(1, len(loop_pts) // 8)]
                for point in centre + 0.5 * (ring - centre):
                    directions = self.free_directions(ctx, point, normal, standoff)
                    if len(directions):
                        anchor = point
                        break
            for n_h in directions:
                if tried >= self.max_directions:
                    break
                if len(used) and np.max(used @ n_h) > np.cos(np.deg2rad(self.rescan_angle_deg)):
                    continue  # scanned from about here already
                tried += 1
                cand = self._candidate(ctx, anchor, loop_pts, n_h, standoff, info)
                if cand is not None:
                    out.append(cand)
                    break
        return out

    def _candidate(self, ctx: PlanningContext, centre: Array, loop_pts: Points3, n_h: Array, standoff: float,
                   info: dict[str, Any]) -> Candidate | None:
        """The hole scan viewed along -n_h: path per Eq. 4.22-4.23, repaired by Algorithm 3."""
        far = loop_pts[np.argmax(np.linalg.norm(loop_pts - centre, axis=1))]
        d_h = far - centre  # hole-radius length [INTERP]
        d_h -= np.dot(d_h, n_h) * n_h
        if np.linalg.norm(d_h) < 1e-6:
            d_h = any_sweep(-n_h) * 0.01
        half = max(self.extend * np.linalg.norm(d_h), 0.5 * self.min_path)
        sweep = d_h / np.linalg.norm(d_h)
        pose = frame_from(-n_h, sweep, centre + standoff * n_h)
        if pose is None:
            return None
        if ctx.sensor.geometry == "line":
            start, end = pose.copy(), pose.copy()
            start[:3, 3] = centre - half * pose[:3, 1] + standoff * n_h  # Eq. 4.22
            end[:3, 3] = centre + half * pose[:3, 1] + standoff * n_h  # Eq. 4.23
            target: Any = ScanPath(start, end, getattr(ctx.sensor, "speed", 0.05))
        else:
            target = pose
        # Alg. 3 occlusion test for holes: surface points along d_h, across the middle of the hole
        focus = centre + np.linspace(-0.5, 0.5, 9)[:, None] * d_h[None, :]
        cand = Candidate(target, self.name, dict(info), focus, ctx.iteration)
        if not self.repair:
            return cand
        extent = np.vstack([centre - half * pose[:3, 1], centre + half * pose[:3, 1]])
        return repair(cand, ctx, centre, standoff, extent, RepairSettings())


class BoundaryHole(ViewGenerator):
    """Boundary Search, switching once to Hole Rescan when ĉ_m grows by less than 1 % (Eq. 4.38)."""

    name = "boundary_hole"
    params = Boundary.params + tuple(
        p for p in HoleRescan.params if p.name not in {b.name for b in Boundary.params}
    ) + (
        Param("switch_delta", float, 0.01, "", "switch when ĉ_m^i - ĉ_m^(i-1) < this (Eq. 4.38)", low=0.0),
        Param("min_scans", int, 3, "", "scans before a switch may happen", low=1),
        Param("force_after", int, 15, "", "switch at the latest after this many scans (IROS safety limit)", low=1),
        Param("with_boundaries", bool, True, "",
              "in hole mode also offer boundary paths of the whole mesh (the open rims the hole finder skips)"),
    )

    def __init__(self, **values: Any) -> None:
        names_b = {p.name for p in Boundary.params}
        names_h = {p.name for p in HoleRescan.params}
        self.boundary = Boundary(**{k: v for k, v in values.items() if k in names_b})
        self.hole = HoleRescan(**{k: v for k, v in values.items() if k in names_h})
        super().__init__(**values)

    def reset(self) -> None:
        self.boundary.reset()
        self.hole.reset()
        self.switched_at: int | None = None

    def should_switch(self, ctx: PlanningContext) -> bool:
        if ctx.mode == "hole":
            return True
        history = ctx.coverage_history
        if len(history) >= max(2, self.min_scans) and history[-1] - history[-2] < self.switch_delta:
            return True
        return ctx.iteration >= self.force_after

    def generate(self, ctx: PlanningContext) -> list[Candidate]:
        if self.switched_at is None and self.should_switch(ctx):
            self.switched_at = ctx.iteration
            ctx.mode = "hole"
            if ctx.stack is not None:
                ctx.stack.clear("boundary")  # the remaining boundary candidates are discarded
        if self.switched_at is None:
            return self.boundary.generate(ctx)
        cands = self.hole.generate(ctx)
        if ctx.stack is not None:  # re-detected every iteration: replace the old ones
            ctx.stack.clear("hole")
            if self.with_boundaries:
                ctx.stack.clear("boundary")
        if self.with_boundaries or (not cands and (ctx.stack is None or len(ctx.stack) == 0)):
            cands = cands + self.boundary.candidates_for(ctx, self.boundary.boundaries(ctx, current_only=False))
        return cands

    def remember(self, candidate: Candidate) -> None:
        if candidate.source == "hole":
            self.hole.remember(candidate)


PLUGINS = [Boundary, HoleRescan, BoundaryHole]
