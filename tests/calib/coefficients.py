"""OpenCV distortion coefficient sets shared by the calibration tests."""

from __future__ import annotations

import numpy as np

# Coefficient sets of the kind OpenCV calibrations produce (OpenCV order), one per allowed count.
REALISTIC = {
    0: [],
    4: [-0.21, 0.045, 8e-4, -5e-4],
    5: [-0.28, 0.071, 1.2e-4, -3.1e-4, -0.0062],
    # CALIB_RATIONAL_MODEL fits typically have large, partly cancelling numerator/denominator terms.
    8: [2.31, -0.42, 2e-4, -1e-4, -0.06, 2.62, 0.31, -0.09],
    12: [-0.25, 0.06, 3e-4, 2e-4, -0.004, 0.01, -0.02, 0.003, 1.1e-3, -2e-4, -8e-4, 1e-4],
    14: [-0.25, 0.06, 3e-4, 2e-4, -0.004, 0.01, -0.02, 0.003, 1.1e-3, -2e-4, -8e-4, 1e-4, 0.012, -0.008],
}


def random_dist(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random but realistic OpenCV coefficients (first ``n`` of k1 k2 p1 p2 k3 k4 k5 k6 s1..s4 τx τy)."""
    full = np.concatenate(
        [
            [rng.uniform(-0.4, 0.15), rng.uniform(-0.1, 0.25)],  # k1, k2
            rng.uniform(-1e-3, 1e-3, 2),  # p1, p2
            [rng.uniform(-0.05, 0.05)],  # k3
            rng.uniform(-0.15, 0.3, 3),  # k4..k6
            rng.uniform(-2e-3, 2e-3, 4),  # s1..s4
            rng.uniform(-0.03, 0.03, 2),  # τx, τy (rad)
        ]
    )
    return full[:n]
