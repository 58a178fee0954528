"""Single-rotation numpy helpers for the per-frame hot paths (tracker solve, MIM step).

:mod:`wearpose.geometry` is the library's rotation module (torch, batched); calling it for one
3 x 3 matrix per frame costs ~50 us of tensor overhead, more than MIM's whole per-frame budget.
These are the same formulas on plain numpy arrays; ``tests/interference`` checks them against
:mod:`wearpose.geometry`.
"""

from __future__ import annotations

import numpy as np

I3 = np.eye(3)


def hat(v: np.ndarray) -> np.ndarray:
    """``[v]_x`` (3, 3) of a 3-vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def exp_so3(v: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``v`` (rad), Rodrigues' formula."""
    th = float(np.sqrt(v @ v))
    K = hat(v)
    if th < 1e-8:
        return I3 + K + 0.5 * (K @ K)
    return I3 + (np.sin(th) / th) * K + ((1.0 - np.cos(th)) / (th * th)) * (K @ K)


def angle_between(R1: np.ndarray, R2: np.ndarray) -> float:
    """Geodesic angle (rad) of ``R1^T R2``, accurate near 0 (atan2 of sine and cosine parts)."""
    M = R1.T @ R2
    s = 0.5 * np.sqrt((M[2, 1] - M[1, 2]) ** 2 + (M[0, 2] - M[2, 0]) ** 2 + (M[1, 0] - M[0, 1]) ** 2)
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)
    return float(np.arctan2(s, c))


def project_so3(M: np.ndarray) -> np.ndarray:
    """Nearest rotation to a 3 x 3 matrix (SVD)."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    return U @ np.diag([1.0, 1.0, d]) @ Vt
