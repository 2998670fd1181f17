"""The dynamic grasp metric μs (pure functions; the probing that feeds them is in sensitivity.py).

G(t) = ∂η̈_o/∂η̈_r is estimated column by column from probes: each probe perturbs the gripper
base's acceleration along one axis and records the change in realised base acceleration
(columns of A_r) and object acceleration (columns of A_o); G = A_o A_r⁻¹. Linear and angular
accelerations are made commensurable with a characteristic length L: angular rows and columns
are multiplied by L (α·L is the tangential acceleration of a point at distance L).
S = G − I₆ and μs = min over instants of (1 − σ_max(S)), clipped to [0, 1].
"""

from __future__ import annotations

import numpy as np


def scaling(length: float) -> np.ndarray:
    return np.diag([1.0, 1.0, 1.0, length, length, length])


def sensitivity_matrix(delta_reference: np.ndarray, delta_object: np.ndarray,
                       length: float) -> np.ndarray:
    """G from probe responses (6 × n columns each, SI units), made dimensionless by `length`."""
    d = scaling(length)
    a_r = d @ delta_reference
    a_o = d @ delta_object
    # Least squares: the realised base responses are not exactly the commanded axes.
    g_t, *_ = np.linalg.lstsq(a_r.T, a_o.T, rcond=1e-6)
    return g_t.T


def instant_quality(g: np.ndarray) -> float:
    """1 − σ_max(G − I): 1 when the object follows the base exactly, 0 when it ignores it."""
    return 1.0 - float(np.linalg.svd(g - np.eye(g.shape[0]), compute_uv=False)[0])


def mu_s(qualities: list[float]) -> float:
    if not qualities:
        return 0.0
    return float(np.clip(min(qualities), 0.0, 1.0))
