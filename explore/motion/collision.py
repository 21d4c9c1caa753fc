"""Collision checking of robot parts against pybullet bodies, in the style of pybullet-planning's
get_collision_fn: AABB pre-filter, getClosestPoints with a margin, precomputed self-collision link pairs."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from explore.sim import body_aabb, p


# -- pybullet collision checking ---------------------------------------------------------------
@dataclass(frozen=True)
class Part:
    """One movable collision part: a pybullet body and link (-1 for the base)."""

    body: int
    link: int
    name: str = ""


class BulletCollider:
    """Collision tests of robot parts vs obstacle bodies and of self-collision link pairs.

    Set the robot's pybullet state first; then :meth:`collides` returns the names of the
    obstacle bodies hit (AABB pre-filter, ``getClosestPoints`` with distance < ``margin``).
    """

    def __init__(
        self,
        client: int,
        parts: Sequence[Part],
        self_pairs: Sequence[tuple[Part, Part]] = (),
        ignore: Sequence[tuple[Part, int]] = (),
    ) -> None:
        self.p = p
        self.client = client
        self.parts = list(parts)
        self.self_pairs = list(self_pairs)
        self.ignore = set(ignore)
        self._aabb: dict[int, tuple[tuple, tuple]] = {}
        # integer indices of the parts (a frozen dataclass hashes slowly in the inner loop)
        index = {part: i for i, part in enumerate(self.parts)}
        self._pair_index = [(index.get(a, -1), index.get(b, -1)) for a, b in self.self_pairs]
        self._pair_a = np.array([i for i, _ in self._pair_index], dtype=np.int64)
        self._pair_b = np.array([j for _, j in self._pair_index], dtype=np.int64)
        self._ignore_index = {(index[part], body) for part, body in self.ignore if part in index}

    def obstacle_aabbs(self, bodies: Sequence[int]) -> list[tuple[int, tuple, tuple]]:
        """Cached AABBs (lo, hi tuples) of static bodies (obstacles do not move)."""
        out = []
        for body in bodies:
            if body not in self._aabb:
                self._aabb[body] = body_aabb(body, self.client)
            out.append((body, *self._aabb[body]))
        return out

    def collides(self, obstacles: Sequence[int], margin: float = 0.0, self_check: bool = True) -> list[int]:
        """Obstacle body ids (and -1 for self-collision) within ``margin`` of the robot.

        AABB overlap tests (one numpy comparison of every part box with every obstacle box)
        prune both the obstacle and the self-collision pairs before ``getClosestPoints``.
        """
        p, c = self.p, self.client
        hits: list[int] = []
        boxes = self.obstacle_aabbs(obstacles)
        part_boxes = np.array([[*lo, *hi] for lo, hi in (p.getAABB(part.body, part.link, physicsClientId=c)
                                                         for part in self.parts)]).reshape(-1, 6)
        if boxes:
            ids = [body for body, _, _ in boxes]
            obstacle_boxes = np.array([[*lo, *hi] for _, lo, hi in boxes])
            near = np.all(part_boxes[:, None, :3] - margin <= obstacle_boxes[None, :, 3:], axis=2) & \
                np.all(part_boxes[:, None, 3:] + margin >= obstacle_boxes[None, :, :3], axis=2)
            for i, j in zip(*np.nonzero(near), strict=True):
                body = ids[j]
                if body in hits or (self._ignore_index and (int(i), body) in self._ignore_index):
                    continue
                part = self.parts[i]
                points = p.getClosestPoints(part.body, body, margin, linkIndexA=part.link, physicsClientId=c)
                if points and min(pt[8] for pt in points) < margin:
                    hits.append(body)
        if self_check and self.self_pairs:
            ia, ib = self._pair_a, self._pair_b
            known = (ia >= 0) & (ib >= 0)
            a_box, b_box = part_boxes[np.where(known, ia, 0)], part_boxes[np.where(known, ib, 0)]
            touching = ~known | (np.all(a_box[:, :3] <= b_box[:, 3:], axis=1) & np.all(a_box[:, 3:] >= b_box[:, :3],
                                                                                     axis=1))
            for index in np.flatnonzero(touching):  # disjoint boxes cannot penetrate
                a, b = self.self_pairs[index]
                points = p.getClosestPoints(
                    a.body, b.body, 0.0, linkIndexA=a.link, linkIndexB=b.link, physicsClientId=c
                )
                if points and min(pt[8] for pt in points) < 0.0:
                    hits.append(-1)
                    break
        return hits


def self_collision_pairs(
    client: int, parts: Sequence[Part], adjacent: Callable[[Part, Part], bool], tolerance: float = 0.0
) -> list[tuple[Part, Part]]:
    """Non-adjacent part pairs that do not touch in the current (home) state."""
    pairs = []
    for i, a in enumerate(parts):
        for b in parts[i + 1 :]:
            if adjacent(a, b):
                continue
            points = p.getClosestPoints(
                a.body, b.body, tolerance, linkIndexA=a.link, linkIndexB=b.link, physicsClientId=client
            )
            if points and min(pt[8] for pt in points) < tolerance:
                continue  # touching at home: treated as permanently in contact
            pairs.append((a, b))
    return pairs
