"""The dynamic grasp metric μs (pure functions; the probing that feeds them is in sensitivity.py).

G(t) = ∂η̈_o/∂η̈_r, and the paper scores S = G − I₆: how much the object's acceleration departs
from the gripper's (at the gripper-fixed point where the object's centre of mass is) per unit
of base acceleration. The probes perturb the base's acceleration along each axis and record
the realised base response (columns of A_r) and the object's response relative to the hand
(columns of A_rel = A_o − A_r); S = A_rel A_r⁻¹. Linear and angular accelerations are made
commensurable with a characteristic length L: angular rows and columns are multiplied by L
(α·L is the tangential acceleration of a point at distance L).
μs = min over instants of (1 − σ_max(S)), clipped to [0, 1].
"""

from __future__ import annotations

import numpy as np


def scaling(length: float) -> np.ndarray:
    return np.diag([1.0, 1.0, 1.0, length, length, length])


def deviation_matrix(delta_base: np.ndarray, delta_relative: np.ndarray,
                     length: float) -> np.ndarray:
    """S = G − I from probe responses (6 × n columns each, SI units: the base's realised
    perturbation and the object's response relative to the hand), dimensionless by `length`."""
    d = scaling(length)
    a_r = d @ delta_base
    a_rel = d @ delta_relative
    # Least squares: the realised base responses are not exactly the commanded axes.
    s_t, *_ = np.linalg.lstsq(a_r.T, a_rel.T, rcond=1e-6)
    return s_t.T


def sensitivity_matrix(delta_reference: np.ndarray, delta_object: np.ndarray,
                       length: float) -> np.ndarray:
    """G from absolute responses of the base and of the object."""
    return np.eye(6) + deviation_matrix(delta_reference, delta_object - delta_reference, length)


def instant_quality_of_deviation(s: np.ndarray) -> float:
    """1 − σ_max(S): 1 when the object follows the base exactly, 0 when it ignores it."""
    return 1.0 - float(np.linalg.svd(s, compute_uv=False)[0])


def instant_quality(g: np.ndarray) -> float:
    """1 − σ_max(G − I)."""
    return instant_quality_of_deviation(g - np.eye(g.shape[0]))


def mu_s(qualities: list[float]) -> float:
    if not qualities:
        return 0.0
    return float(np.clip(min(qualities), 0.0, 1.0))
