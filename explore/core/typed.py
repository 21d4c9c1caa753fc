"""Array aliases used in signatures; shapes are given in the docstrings."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Points3 = NDArray[np.float64]  # (n, 3)
Pose = NDArray[np.float64]  # (4, 4) homogeneous world_T_frame
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
