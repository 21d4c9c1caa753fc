"""OctoMap's binary tree format (``.bt``): the field's exchange format for occupancy maps.

A ``.bt`` file holds the maximum-likelihood state of an ``OcTree`` (Hornung et al. 2013):
a short text header, then the inner nodes in depth-first pre-order, two bytes each, that give
the state of the node's eight children in two bits apiece (00 unknown, 01 free leaf, 10
occupied leaf, 11 inner node; children 0-3 in the first byte, lowest bits first). A key is
``floor(x / resolution) + 2^15`` per axis on a tree of depth 16, which is the PVS's own
lattice, so every observed voxel becomes one leaf; eight equal leaves are pruned into their
parent as OctoMap does before writing. Readers: ``octovis``, ``octomap::OcTree::readBinary``,
``pyoctomap.OcTree.readBinary``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

DEPTH = 16
CENTER = 1 << (DEPTH - 1)  # OctoMap's tree_max_val: key of the voxel at the origin
OCCUPIED, FREE, INNER = 0b10, 0b01, 0b11  # two-bit child codes of the format (bit 2i + 1, bit 2i)


def _morton(keys: np.ndarray) -> np.ndarray:
    """Depth-first order of tree positions: the keys' bits interleaved (x lowest), top level first."""
    code = np.zeros(len(keys), dtype=np.int64)
    for bit in range(DEPTH - 1, -1, -1):
        digit = ((keys[:, 0] >> bit) & 1) | (((keys[:, 1] >> bit) & 1) << 1) | (((keys[:, 2] >> bit) & 1) << 2)
        code = (code << 3) | digit
    return code


def tree_of(keys: np.ndarray, occupied: np.ndarray) -> tuple[np.ndarray, int]:
    """The inner nodes' child words (pre-order, uint16) and the tree's node count.

    ``keys`` (n, 3) are distinct OctoMap keys of the observed leaves (depth 16), ``occupied``
    (n,) their maximum-likelihood states.
    """
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    state = np.where(np.asarray(occupied, dtype=bool), OCCUPIED, FREE).astype(np.int64)
    words, depths, prefixes = [], [], []
    nodes = 1  # the root
    for depth in range(DEPTH, 0, -1):  # children at ``depth``, parents at depth - 1
        if not len(keys):
            break
        child = (keys[:, 0] & 1) | ((keys[:, 1] & 1) << 1) | ((keys[:, 2] & 1) << 2)
        parents, inverse = np.unique(keys >> 1, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        word = np.zeros(len(parents), dtype=np.int64)
        np.add.at(word, inverse, state << (2 * child))
        count = np.bincount(inverse, minlength=len(parents))
        # eight leaves of one state become one leaf (OctoMap prunes before writing); never the root
        pruned = np.zeros(len(parents), dtype=bool)
        if depth > 1:
            for leaf in (OCCUPIED, FREE):
                pruned |= (count == 8) & (word == sum(leaf << (2 * i) for i in range(8)))
        inner = ~pruned
        words.append(word[inner])
        depths.append(np.full(int(inner.sum()), depth - 1))
        prefixes.append(parents[inner] << (DEPTH - depth + 1))  # back to full-width keys for the order
        nodes += int(count[inner].sum())
        keys = parents
        state = np.where(pruned, word & 0b11, INNER)
    if not words:
        return np.zeros(0, dtype=np.uint16), 0
    word = np.concatenate(words)
    order = np.lexsort((np.concatenate(depths), _morton(np.concatenate(prefixes))))  # ancestors first
    return word[order].astype(np.uint16), nodes


def write_bt(path: str | Path, keys: np.ndarray, occupied: np.ndarray, resolution: float) -> int:
    """Write an OctoMap ``.bt`` file of the observed leaves; returns the number of tree nodes."""
    words, nodes = tree_of(keys, occupied)
    header = ("# Octomap OcTree binary file\n# (feel free to add / change comments, but leave the first line as it is!)"
              f"\n#\nid OcTree\nsize {nodes}\nres {resolution!r}\ndata\n")
    with open(path, "wb") as handle:
        handle.write(header.encode("ascii"))
        handle.write(words.astype("<u2").tobytes())
    return nodes
