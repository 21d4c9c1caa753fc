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
from numba import njit

DEPTH = 16
CENTER = 1 << (DEPTH - 1)  # OctoMap's tree_max_val: key of the voxel at the origin
OCCUPIED, FREE, INNER = 0b10, 0b01, 0b11  # two-bit child codes of the format (bit 2i + 1, bit 2i)
_ALL = {code: sum(code << (2 * i) for i in range(8)) for code in (OCCUPIED, FREE)}  # eight equal leaves


def _morton(keys: np.ndarray) -> np.ndarray:
    """Depth-first order of tree positions: the keys' bits interleaved (x lowest), top level first."""
    code = np.zeros(len(keys), dtype=np.int64)
    for bit in range(DEPTH - 1, -1, -1):
        digit = ((keys[:, 0] >> bit) & 1) | (((keys[:, 1] >> bit) & 1) << 1) | (((keys[:, 2] >> bit) & 1) << 2)
        code = (code << 3) | digit
    return code


def _levels_above(keys: np.ndarray, state: np.ndarray, depth: int, words: list, depths: list, prefixes: list) -> int:
    """Append the inner nodes above the nodes ``keys`` (n, 3) at ``depth`` (states: a leaf code or INNER) up to
    the root: their child words, depths and full-width keys; returns the number of child nodes they hold."""
    nodes = 0
    for level in range(depth, 0, -1):  # children at ``level``, parents at level - 1
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
        if level > 1:
            for leaf in (OCCUPIED, FREE):
                pruned |= (count == 8) & (word == _ALL[leaf])
        inner = ~pruned
        words.append(word[inner])
        depths.append(np.full(int(inner.sum()), level - 1))
        prefixes.append(parents[inner] << (DEPTH - level + 1))  # back to full-width keys for the order
        nodes += int(count[inner].sum())
        keys = parents
        state = np.where(pruned, word & 0b11, INNER)
    return nodes


def _in_order(words: list, depths: list, prefixes: list) -> np.ndarray:
    if not words:
        return np.zeros(0, dtype=np.uint16)
    order = np.lexsort((np.concatenate(depths), _morton(np.concatenate(prefixes))))  # ancestors first
    return np.concatenate(words)[order].astype(np.uint16)


def tree_of(keys: np.ndarray, occupied: np.ndarray) -> tuple[np.ndarray, int]:
    """The inner nodes' child words (pre-order, uint16) and the tree's node count.

    ``keys`` (n, 3) are distinct OctoMap keys of the observed leaves (depth 16), ``occupied``
    (n,) their maximum-likelihood states.
    """
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    state = np.where(np.asarray(occupied, dtype=bool), OCCUPIED, FREE).astype(np.int64)
    words: list = []
    depths: list = []
    prefixes: list = []
    nodes = _levels_above(keys, state, DEPTH, words, depths, prefixes)
    return _in_order(words, depths, prefixes), (nodes + 1 if any(len(w) for w in words) else 0)


def tree_of_blocks(block_keys: np.ndarray, log_odds: np.ndarray, uniform_keys: np.ndarray,
                   uniform_log_odds: np.ndarray, chunk: int = 1 << 15) -> tuple[np.ndarray, int]:
    """:func:`tree_of` for a map of 8^3-voxel blocks (the sparse PVS), without listing its voxels.

    ``block_keys`` (m, 3) are the OctoMap keys of stored blocks at depth 13 (voxel key >> 3) with
    ``log_odds`` (m, 512) (local index x * 64 + y * 8 + z, 0: unobserved); ``uniform_keys`` (u, 3) and
    ``uniform_log_odds`` (u,) the blocks of one value. The three levels inside each block are built
    from the (x, y, z, 2, 2, 2) reshapes of its codes, the levels above from the blocks' states.
    """
    words: list = []
    depths: list = []
    prefixes: list = []
    nodes = 0
    states = []
    shifts = (2 * np.arange(8)).astype(np.int32)
    for start in range(0, len(block_keys), chunk):
        values = log_odds[start: start + chunk]
        m = len(values)
        codes = np.where(values > 0.0, OCCUPIED, np.where(values < 0.0, FREE, 0)).astype(np.int8).reshape(m, 8, 8, 8)
        base = block_keys[start: start + chunk].astype(np.int64) << 3
        n = 8
        for level in (DEPTH, DEPTH - 1, DEPTH - 2):  # children at ``level``, parents at level - 1
            half = n // 2
            children = codes.reshape(m, half, 2, half, 2, half, 2).transpose(0, 1, 3, 5, 6, 4, 2)
            children = children.reshape(m, half, half, half, 8).astype(np.int32)
            word = (children << shifts).sum(axis=-1)
            known = np.count_nonzero(children, axis=-1)
            pruned = (known == 8) & ((word == _ALL[FREE]) | (word == _ALL[OCCUPIED]))
            inner = (known > 0) & ~pruned
            at = np.nonzero(inner)
            words.append(word[inner].astype(np.int64))
            depths.append(np.full(len(at[0]), level - 1))
            prefixes.append(base[at[0]] + (np.column_stack(at[1:]).astype(np.int64) << (DEPTH - level + 1)))
            nodes += int(known[inner].sum())
            codes = np.where(pruned, word & 0b11, np.where(inner, INNER, 0)).astype(np.int8)
            n = half
        states.append(codes.reshape(m).astype(np.int64))
    uniform = np.where(uniform_log_odds > 0.0, OCCUPIED, np.where(uniform_log_odds < 0.0, FREE, 0))
    keys = np.concatenate([np.asarray(block_keys, np.int64).reshape(-1, 3), np.asarray(uniform_keys, np.int64)])
    state = np.concatenate([*states, uniform.astype(np.int64)])
    observed = state != 0
    nodes += _levels_above(keys[observed], state[observed], DEPTH - 3, words, depths, prefixes)
    return _in_order(words, depths, prefixes), (nodes + 1 if any(len(w) for w in words) else 0)


def write_bt(path: str | Path, keys: np.ndarray, occupied: np.ndarray, resolution: float) -> int:
    """Write an OctoMap ``.bt`` file of the observed leaves; returns the number of tree nodes."""
    return write_tree(path, *tree_of(keys, occupied), resolution)


def write_tree(path: str | Path, words: np.ndarray, nodes: int, resolution: float) -> int:
    """Write the child words of a tree (:func:`tree_of`, :func:`tree_of_blocks`) as a ``.bt`` file."""
    header = ("# Octomap OcTree binary file\n# (feel free to add / change comments, but leave the first line as it is!)"
              f"\n#\nid OcTree\nsize {nodes}\nres {resolution!r}\ndata\n")
    with open(path, "wb") as handle:
        handle.write(header.encode("ascii"))
        handle.write(words.astype("<u2").tobytes())
    return nodes


@njit(cache=True, nogil=True)
def _leaves_of(words, count_only, cap):
    """Leaves (depth, key prefix x/y/z, state) of a pre-order child-word stream (iterative depth-first walk) in
    arrays of ``cap``; with ``count_only`` just their number (a first pass, to allocate the arrays to size)."""
    depth = np.empty(cap, np.int8)
    prefix = np.empty((cap, 3), np.int32)
    state = np.empty(cap, np.int8)
    stack_word = np.empty(DEPTH + 1, np.int64)
    stack_next = np.empty(DEPTH + 1, np.int64)
    stack_key = np.zeros((DEPTH + 1, 3), np.int64)
    n = 0
    if words.shape[0] == 0:
        return depth, prefix, state, 0, 0
    top = 0
    stack_word[0] = words[0]
    stack_next[0] = 0
    used = 1
    while top >= 0:
        i = stack_next[top]
        if i == 8:
            top -= 1
            continue
        stack_next[top] = i + 1
        code = (stack_word[top] >> (2 * i)) & 0b11
        if code == 0:
            continue
        k0 = (stack_key[top, 0] << 1) | (i & 1)
        k1 = (stack_key[top, 1] << 1) | ((i >> 1) & 1)
        k2 = (stack_key[top, 2] << 1) | ((i >> 2) & 1)
        if code == INNER:
            if used >= words.shape[0] or top + 1 > DEPTH - 1:
                return depth[:n], prefix[:n], state[:n], -1, n
            top += 1
            stack_word[top] = words[used]
            used += 1
            stack_next[top] = 0
            stack_key[top, 0] = k0
            stack_key[top, 1] = k1
            stack_key[top, 2] = k2
        else:
            if not count_only:
                depth[n] = top + 1
                prefix[n, 0] = k0
                prefix[n, 1] = k1
                prefix[n, 2] = k2
                state[n] = code
            n += 1
    return depth[:n], prefix[:n], state[:n], used, n


def read_bt_leaves(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Read an OctoMap ``.bt`` file as its leaves: depth (n,), key prefix at that depth (n, 3, int32), state
    (n,: OCCUPIED or FREE) and the resolution. A leaf at depth k covers 2^(16 - k) voxels per axis."""
    data = Path(path).read_bytes()
    marker = data.find(b"\ndata\n")
    if marker < 0:
        raise ValueError(f"{path}: no 'data' line: not an OctoMap .bt file")
    resolution = None
    for line in data[:marker].decode("ascii", "replace").splitlines():
        if line.startswith("res "):
            resolution = float(line.split()[1])
    if resolution is None:
        raise ValueError(f"{path}: no 'res' line: not an OctoMap .bt file")
    words = np.frombuffer(data[marker + len(b"\ndata\n"):], dtype="<u2").astype(np.int64)
    depth, prefix, state, used, _ = _leaves_of(words, False, _leaves_of(words, True, 0)[4])
    if used != len(words):
        raise ValueError(f"{path}: the tree data is truncated or has trailing bytes")
    return depth, prefix, state, resolution


def expand_leaves(depth: np.ndarray, prefix: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The depth-16 keys (n, 3) and states (True occupied) of the voxels that leaves cover."""
    keys, occupied = [], []
    for level in np.unique(depth):
        pick = depth == level
        span = 1 << (DEPTH - int(level))
        grid = np.stack(np.meshgrid(*(np.arange(span),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        keys.append(((prefix[pick] * span)[:, None, :] + grid[None]).reshape(-1, 3))
        occupied.append(np.repeat(state[pick] == OCCUPIED, len(grid)))
    if not keys:
        return np.zeros((0, 3), np.int64), np.zeros(0, bool)
    return np.concatenate(keys), np.concatenate(occupied)


def read_bt(path: str | Path) -> tuple[np.ndarray, np.ndarray, float]:
    """Read an OctoMap ``.bt`` file: the keys (n, 3) of its observed depth-16 voxels (pruned leaves expanded),
    their maximum-likelihood states (True occupied) and the resolution."""
    depth, prefix, state, resolution = read_bt_leaves(path)
    return (*expand_leaves(depth, prefix, state), resolution)
