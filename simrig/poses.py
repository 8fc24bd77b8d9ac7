"""Named joint poses of the simulated rig (no MuJoCo import: policies use them as priors)."""

from __future__ import annotations

import numpy as np

# Both grippers open and pointing down at (−0.08, ±0.34, 0.16) m, beside and above the workspace, so
# the arms hide as little of the table as possible from the head camera (solved with pilworld's IK).
HOME_Q14 = np.array(
    [-0.2586, -1.8292, 2.26, -2.0016, -1.5708, 0.0414, 1.0, -0.474, -1.8292, 2.26, -2.0016, -1.5708, -0.284, 1.0],
    dtype=np.float64,
)
