"""6-DoF pose of an EM sensor from its 9 induced voltages, as real trackers solve it.

Model (:func:`wearpose.interference.field.ideal_voltages`): ``V = R^T D(p)`` in the source frame.
EM-POSE Sec. 3.1: "We can solve for the 6D pose in the least squares sense by minimizing the
measured voltage and the model voltage along each emitter and sensor axis". :class:`EMTracker`
does exactly that per frame with ``scipy.optimize.least_squares`` (Levenberg-Marquardt,
analytic Jacobian) over ``(p, delta)``, ``R = R_0 exp([delta]_x)``, warm-started from the previous
frame's solution as tracking systems do (Raab et al. 1979 track by iterating from the last pose).

**Closed form** (initial acquisition and re-acquisition): ``D`` is symmetric and
``V^T V = D^2 = (3 u u^T + I) / r^6`` does not depend on ``R``; its trace gives ``r`` and its
top eigenvector the direction ``u`` up to sign; then ``R = (V D^{-1})^T`` projected onto SO(3).

**Hemisphere ambiguity**: ``D(-p) = D(p)``, so ``(R, p)`` and ``(R, -p)`` give identical voltages.
Like commercial trackers (a configured operating hemisphere, then continuity) the tracker picks
the sign with ``p . hemisphere >= 0`` at acquisition and afterwards the sign on the side of the
last position solved from an undistorted field (relative residual below ``good_residual``, at
most ``good_memory`` frames ago; otherwise the previous frame's side: "hemisphere tracking"),
since both signs fit the voltages equally. Severe distortion can still pull the solver to a distant local minimum: that failure
mode is part of what metal does to real trackers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from wearpose.errors import ShapeError
from wearpose.interference._so3 import exp_so3 as _exp
from wearpose.interference._so3 import hat, project_so3 as _project_so3


#: ``_GENERATORS[:, :, k] = [e_k]_x``.
_GENERATORS = np.stack([hat(e) for e in np.eye(3)], axis=-1)
_I3 = np.eye(3)
_I6 = np.eye(6)


def closed_form_pose(V: np.ndarray, hemisphere: np.ndarray, near: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Direct pose from voltages ``V (3, 3)`` (module doc): ``(R (3, 3), p (3,))``.

    Args:
        hemisphere: ``(3,)`` direction; the sign of ``p`` is chosen with ``p . hemisphere >= 0``
            unless ``near`` (a previous position) is given, then the sign nearer to it.
    """
    S = V.T @ V
    w, E = np.linalg.eigh(S)
    r = (6.0 / max(float(np.trace(S)), 1e-300)) ** (1.0 / 6.0)
    u = E[:, -1]
    ref = near if near is not None else hemisphere
    if float(u @ ref) < 0:
        u = -u
    p = r * u
    Dinv = r ** 3 * (1.5 * np.outer(u, u) - _I3)
    R = _project_so3((V @ Dinv).T)
    return R, p


def _coupling1(p: np.ndarray) -> np.ndarray:
    """:func:`~wearpose.interference.field.coupling` of one vector, without broadcasting overhead."""
    r2 = float(p @ p)
    return (3.0 * np.outer(p, p) / r2 - _I3) / (r2 * np.sqrt(r2))


def _coupling_jac(p: np.ndarray) -> np.ndarray:
    """``dD/dp_j`` as ``(3, 3, 3)`` (last index j)."""
    r2 = float(p @ p)
    r5 = r2 * r2 * np.sqrt(r2)
    I = np.eye(3)
    # d/dp_j [3 p p^T / r^5 - I / r^3] = 3 (e_j p^T + p e_j^T) / r^5 - 15 p p^T p_j / r^7 + 3 I p_j / r^5
    return (3.0 * (I[:, None, :] * p[None, :, None] + p[:, None, None] * I[None, :, :]) / r5
            - 15.0 * np.outer(p, p)[:, :, None] * p[None, None, :] / (r5 * r2) + 3.0 * I[:, :, None] * p[None, None, :] / r5)


@dataclass
class TrackerConfig:
    """Solver settings.

    Attributes:
        hemisphere: operating hemisphere in the source frame (acquisition sign choice).
        reacquire_rel_residual: relative residual ``|V - V_model| / |V|`` above which the tracker
            also tries the closed-form solution and keeps the better fit.
        max_nfev: LM iterations (evaluations) per frame.
        good_residual: relative residual below which a solution counts as undistorted and
            becomes the hemisphere reference.
        good_memory: frames an undistorted reference stays in use; older, continuity rules.
        solver: ``"scipy"`` (``scipy.optimize.least_squares``, method ``"lm"``) or ``"numpy"``
            (the same problem by an in-house Levenberg-Marquardt loop; identical solutions to
            ~1e-9, several times faster, used for bulk simulation).
    """

    hemisphere: tuple[float, float, float] = (1.0, 0.0, 0.0)
    reacquire_rel_residual: float = 0.05
    max_nfev: int = 50
    solver: str = "scipy"
    good_residual: float = 1e-2
    good_memory: int = 120


class EMTracker:
    """Online pose solver for one sensor (module doc). ``reset()``, then ``solve(V)`` per frame."""

    def __init__(self, config: TrackerConfig | None = None):
        self.config = config or TrackerConfig()
        self.reset()

    def reset(self) -> None:
        self._R: np.ndarray | None = None
        self._p: np.ndarray | None = None
        self._p_good: np.ndarray | None = None
        self._since_good = 0

    @staticmethod
    def _residual(x: np.ndarray, R0: np.ndarray, V: np.ndarray) -> np.ndarray:
        R = R0 @ _exp(x[3:])
        return (R.T @ _coupling1(x[:3]) - V).ravel()

    @staticmethod
    def _jac(x: np.ndarray, R0: np.ndarray, V: np.ndarray) -> np.ndarray:
        R = R0 @ _exp(x[3:])
        D = _coupling1(x[:3])
        RtD = R.T @ D
        dD = _coupling_jac(x[:3])
        J = np.empty((9, 6))
        J[:, :3] = np.einsum("ai,ibj->abj", R.T, dD).reshape(9, 3)
        # right perturbation R exp(e) ~ R (I + [e]): (R (I+[e]))^T D = R^T D - [e] R^T D
        J[:, 3:] = -np.einsum("iak,ab->ibk", _GENERATORS, RtD).reshape(9, 3)
        return J

    def _fit(self, V: np.ndarray, R0: np.ndarray, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        if self.config.solver == "scipy":
            x0 = np.concatenate([p0, np.zeros(3)])
            res = least_squares(self._residual, x0, jac=self._jac, args=(R0, V), method="lm",
                                xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=self.config.max_nfev)
            x = res.x
            return R0 @ _exp(x[3:]), x[:3].copy(), float(np.linalg.norm(res.fun))
        return self._fit_lm(V, R0, p0)

    def _fit_lm(self, V: np.ndarray, R0: np.ndarray, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """The same least-squares problem by a small Levenberg-Marquardt loop in numpy (the
        rotation re-linearised at each accepted step): ~10x less overhead than scipy's wrapper."""
        R, p = R0.copy(), p0.copy()
        f = (R.T @ _coupling1(p) - V).ravel()
        c = float(f @ f)
        lam = 1e-3
        for _ in range(self.config.max_nfev):
            x = np.concatenate([p, np.zeros(3)])
            J = self._jac(x, R, V)
            A = J.T @ J
            g = J.T @ f
            if float(np.abs(g).max()) < 1e-14:
                break
            step = np.linalg.solve(A + lam * (A * _I6 + 1e-12 * _I6), -g)
            Rn, pn = R @ _exp(step[3:]), p + step[:3]
            fn = (Rn.T @ _coupling1(pn) - V).ravel()
            cn = float(fn @ fn)
            if cn <= c:
                done = float(np.abs(step).max()) < 1e-10 or (c - cn) <= 1e-9 * c
                R, p, f, c = Rn, pn, fn, cn
                lam = max(lam * 0.1, 1e-9)
                if done:
                    break
            else:
                lam *= 10.0
                if lam > 1e4:
                    break
        return R, p, float(np.sqrt(c))

    def solve(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """One frame: voltages ``(3, 3)`` -> ``(R (3, 3), p (3,), relative residual)`` in the source frame."""
        V = np.asarray(V, dtype=np.float64)
        if V.shape != (3, 3):
            raise ShapeError(f"EMTracker.solve: expected voltages (3, 3), got {V.shape}")
        hemi = np.asarray(self.config.hemisphere, dtype=np.float64)
        vn = max(float(np.linalg.norm(V)), 1e-300)
        if self._p is None:
            R0, p0 = closed_form_pose(V, hemi)
            R, p, c = self._fit(V, R0, p0)
        else:
            R, p, c = self._fit(V, self._R, self._p)
            if c / vn > self.config.reacquire_rel_residual:
                R0, p0 = closed_form_pose(V, hemi, near=self._p_good if self._p_good is not None else self._p)
                R2, p2, c2 = self._fit(V, R0, p0)
                if c2 < c:
                    R, p, c = R2, p2, c2
        # hemisphere tracking: (R, p) and (R, -p) fit equally; keep the side of the last position
        # solved from an undistorted field (small residual), so a solver dragged around the
        # source by heavy distortion comes back on the right side once the field is clean again
        # (within ``good_memory`` frames; otherwise plain continuity with the previous frame)
        if self._p_good is not None and self._since_good <= self.config.good_memory:
            ref = self._p_good
        else:
            ref = self._p if self._p is not None else hemi
        if float(p @ ref) < 0:
            p = -p
        self._since_good += 1
        if c / vn < self.config.good_residual:
            self._p_good = p.copy()
            self._since_good = 0
        self._R, self._p = R, p
        return R, p, c / vn

    def track(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Offline convenience: ``V (T, 3, 3)`` -> ``R (T, 3, 3)``, ``p (T, 3)``, residual ``(T,)`` (resets first)."""
        if V.ndim != 3 or V.shape[1:] != (3, 3):
            raise ShapeError(f"EMTracker.track: expected voltages (T, 3, 3), got {V.shape}")
        self.reset()
        T = V.shape[0]
        Rs, ps, rs = np.empty((T, 3, 3)), np.empty((T, 3)), np.empty(T)
        for t in range(T):
            Rs[t], ps[t], rs[t] = self.solve(V[t])
        return Rs, ps, rs
