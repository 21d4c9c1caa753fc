"""Colour as a recognition cue: which colours an object shows, and whether a cluster shows a model's.

Geometry alone cannot tell two blocks of the same size apart (room40's random_626 and random_651: 2.1 x 6.1 x
8.1 cm and 8.1 x 6.0 x 2.1 cm, within 2 mm of each other both ways). An RGB-D sensor sees that one is red and
the other cyan. Colours are compared in normalised rg chromaticity (r, g) / (r + g + b), which shading scales
out for a Lambertian surface; pixels too dark for their chromaticity to mean anything are left out. A model's
colours are its *signature*: the chromaticities that hold a share of its points (a mug may be red with a white
handle); a cluster agrees with a model when most of its bright points lie near one of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: r + g + b (of 765) below which a pixel's chromaticity is noise (a shadowed or black surface)
MIN_BRIGHTNESS = 60.0
#: bright points needed before colours say anything
MIN_POINTS = 30
#: width of the chromaticity bins a signature is gathered from
BIN = 0.01
#: share of an object's bright points a bin needs to be one of its colours
MIN_SHARE = 0.05
#: chromaticity distance within which a point shows one of a model's colours: a pixel's chromaticity moves
#: by up to ~0.02 under sensor noise and mixed edge pixels, two random colours lie ~0.2 apart (median)
TOLERANCE = 0.05
#: share of the bright points a hypothesis explains that must show the model's colours
MIN_COLOUR_AGREEMENT = 0.5

#: the database descriptor kind a signature is stored under
COLOUR_KIND = "colour"


@dataclass(frozen=True)
class ColourSignature:
    """The colours of an object: chromaticities (k, 2) and the share of its bright points at each (k,)."""

    chromaticities: np.ndarray
    shares: np.ndarray

    def as_array(self) -> np.ndarray:
        """(k, 3): r, g chromaticity and share, as the database stores it."""
        return np.column_stack([self.chromaticities, self.shares])

    @classmethod
    def from_array(cls, array: np.ndarray) -> ColourSignature:
        array = np.asarray(array, dtype=float).reshape(-1, 3)
        return cls(array[:, :2], array[:, 2])


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(r, g) / (r + g + b) of the pixels bright enough to have one ((m, 2), m <= n)."""
    rgb = np.asarray(rgb, dtype=float).reshape(-1, 3)
    total = rgb.sum(axis=1)
    bright = total >= MIN_BRIGHTNESS
    return rgb[bright, :2] / total[bright, None]


def colour_signature(rgb: np.ndarray) -> ColourSignature | None:
    """The colours an object's pixels (n, 3) show: their chromaticities gathered into colours no wider than
    ``TOLERANCE`` (the fullest ``BIN``-wide bins first, each joining the first colour within reach), each with
    its share of the bright pixels; those holding at least ``MIN_SHARE``. None when too few pixels are
    bright or no colour holds that share (a speckled texture)."""
    chroma = chromaticity(rgb)
    if len(chroma) < MIN_POINTS:
        return None
    _, inverse, counts = np.unique(np.floor(chroma / BIN).astype(np.int64), axis=0, return_inverse=True,
                                   return_counts=True)
    inverse = inverse.reshape(-1)
    bin_means = np.array([chroma[inverse == k].mean(axis=0) for k in range(len(counts))])
    colours: list[int] = []  # the bin each colour started from
    colour_of_bin = np.empty(len(counts), dtype=np.int64)
    for k in np.argsort(-counts, kind="stable"):
        near = [c for c, seed in enumerate(colours) if np.linalg.norm(bin_means[k] - bin_means[seed]) <= TOLERANCE]
        colour_of_bin[k] = near[0] if near else len(colours)
        if not near:
            colours.append(int(k))
    of_point = colour_of_bin[inverse]
    shares = np.bincount(of_point, minlength=len(colours)) / len(chroma)
    kept = np.flatnonzero(shares >= MIN_SHARE)
    if len(kept) == 0:
        return None
    return ColourSignature(np.array([chroma[of_point == c].mean(axis=0) for c in kept]), shares[kept])


def material_signature(rgb: np.ndarray) -> ColourSignature | None:
    """The signature of a surface of one material colour (3,) in [0, 1] (a given model's); None when the colour
    is too dark for its chromaticity to mean anything."""
    chroma = chromaticity(255.0 * np.asarray(rgb, dtype=float)[:3])
    return ColourSignature(chroma, np.ones(1)) if len(chroma) else None


def colour_agreement(signature: ColourSignature, rgb: np.ndarray) -> float:
    """Share of the bright pixels (n, 3) within ``TOLERANCE`` of one of the signature's colours; NaN when too
    few pixels are bright to say."""
    chroma = chromaticity(rgb)
    if len(chroma) < MIN_POINTS:
        return float("nan")
    gaps = np.linalg.norm(chroma[:, None, :] - signature.chromaticities[None, :, :], axis=2)
    return float(np.mean(gaps.min(axis=1) <= TOLERANCE))


def shows_colours_of(signature: ColourSignature | None, rgb: np.ndarray | None) -> tuple[bool, float]:
    """Whether pixels (n, 3) may be of an object with this signature, and the agreement they reach. Without
    colour on either side (a grey-only sensor, a model stored without colour, too few bright pixels) colour
    rules nothing out."""
    if signature is None or rgb is None:
        return True, float("nan")
    agreement = colour_agreement(signature, rgb)
    return bool(np.isnan(agreement) or agreement >= MIN_COLOUR_AGREEMENT), agreement
