"""Hand-eye / robot-world calibration ``A_i X = Y B_i`` (MI-Poser App. B.1, Eq. 6; Shah 2013).

MI-Poser aligns a reference tracker (iPhone VIO, poses ``X_t`` in its world) with an EM sensor
(poses ``Y_t`` relative to the EM source) rigidly mounted together: ``X_t B = A Y_t`` (Eq. 6)
with ``A`` = EM origin in the iPhone world and ``B`` = EM sensor in the iPhone frame. In the
usual notation ``A_i X = Y B_i`` (Shah, "Solving the robot-world/hand-eye calibration problem
using the Kronecker product", J. Mech. Robot. 2013 -- MI-Poser's ref. [48]) that is
``A_i := X_t``, ``X := B``, ``Y := A``, ``B_i := Y_t``; the ground-truth EM pose is then
``Y^{-1} A_i X`` (MI-Poser's ``A^-1 X_t B``).

**Closed form** (Shah 2013). Rotation: ``R_A R_X = R_Y R_B`` is linear in ``vec R_X, vec R_Y``::

    [ I (x) R_A_i ,  -(R_B_i^T (x) I) ] [vec R_X; vec R_Y] = 0       (column-major vec)

stacked over ``i``: the right singular vector of the smallest singular value, rescaled to
``det = 1`` and projected onto SO(3). Translation, given ``R_Y``: ``R_A_i t_X - t_Y = R_Y t_B_i - t_A_i``,
linear least squares in ``(t_X, t_Y)``.

**Refinement**: ``scipy.optimize.least_squares`` over both rotations (local rotation vectors) and
both translations, residuals ``log((R_Y R_B)^T R_A R_X) / sigma_r`` and
``(R_A t_X + t_A - R_Y t_B - t_Y) / sigma_t`` -- the closed form weighs rotation and translation
arbitrarily and treats the rotation algebraically; the refinement is the maximum-likelihood
estimate under isotropic noise of the stated scales.

**Degeneracy**: with fewer than 3 poses, or when all ``A_i`` rotate about one axis (or not at
all), ``X`` and ``Y`` are not unique: the rotation system has a second (near-)zero singular
value, or the translation system is rank deficient. :class:`DegenerateCalibrationError` says so.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from wearpose.calibration._common import F64, CalibrationError, DegenerateCalibrationError, t64
from wearpose.calibration.result import CalibrationResult

#: Minimum ratio of the second-smallest to the largest singular value of the rotation system.
ROTATION_CONDITION = 1e-3
#: Minimum ratio of the smallest to the largest singular value of the translation system.
TRANSLATION_CONDITION = 1e-3


def _split(T: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 4, 4)`` homogeneous or ``(R (N, 3, 3), t (N, 3))`` -> numpy float64 pair."""
    if isinstance(T, (tuple, list)) and len(T) == 2:
        R, t = (t64(x).numpy() for x in T)
    else:
        M = t64(T).numpy()
        if M.ndim != 3 or M.shape[1:] != (4, 4):
            raise CalibrationError(f"hand-eye: {name} must be (N, 4, 4) homogeneous transforms or a pair (R (N, 3, 3), t (N, 3)), got shape {M.shape}")
        R, t = M[:, :3, :3], M[:, :3, 3]
    if R.ndim != 3 or R.shape[1:] != (3, 3) or t.shape != (R.shape[0], 3):
        raise CalibrationError(f"hand-eye: {name} rotations (N, 3, 3) and translations (N, 3) expected, got {R.shape} and {t.shape}")
    if not (np.isfinite(R).all() and np.isfinite(t).all()):
        raise CalibrationError(f"hand-eye: {name} contains NaN or infinite values; drop invalid frames first")
    return R, t


def _project(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def axyb_closed_form(RA: np.ndarray, tA: np.ndarray, RB: np.ndarray, tB: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, float]]:
    """Shah (2013) Kronecker closed form of ``A_i X = Y B_i``. numpy float64.

    Returns ``(R_X, t_X, R_Y, t_Y, diagnostics)``; raises :class:`DegenerateCalibrationError`.
    """
    N = RA.shape[0]
    if N < 3:
        raise DegenerateCalibrationError(f"hand-eye AX=YB: {N} pose pair(s); at least 3 with rotations about different axes are needed")
    I3 = np.eye(3)
    # vec(R_A R_X) = (I (x) R_A) vec R_X ; vec(R_Y R_B) = (R_B^T (x) I) vec R_Y  (column-major vec)
    K = np.concatenate([np.stack([np.kron(I3, RA[i]) for i in range(N)]),
                        -np.stack([np.kron(RB[i].T, I3) for i in range(N)])], axis=2).reshape(9 * N, 18)
    _, s, Vt = np.linalg.svd(K, full_matrices=False)
    cond = float(s[-2] / s[0])
    if cond < ROTATION_CONDITION:
        raise DegenerateCalibrationError(
            f"hand-eye AX=YB: the rotations do not determine X and Y (second-smallest/largest singular value {cond:.2e} < "
            f"{ROTATION_CONDITION:g}): the A poses rotate about a single axis or not at all. Move the rig about at least two "
            "different axes during the calibration")
    v = Vt[-1]
    RX = v[:9].reshape(3, 3, order="F")
    RY = v[9:].reshape(3, 3, order="F")
    # The null vector has arbitrary scale and sign: normalise so det(R_X) = +1.
    d = np.linalg.det(RX)
    scale = np.sign(d) / abs(d) ** (1.0 / 3.0)
    RX, RY = _project(RX * scale), _project(RY * scale)
    # Translation: R_A t_X - t_Y = R_Y t_B - t_A
    C = np.concatenate([RA, -np.broadcast_to(I3, RA.shape)], axis=2).reshape(3 * N, 6)
    rhs = (np.einsum("ij,nj->ni", RY, tB) - tA).reshape(3 * N)
    sc = np.linalg.svd(C, compute_uv=False)
    tcond = float(sc[-1] / sc[0])
    if tcond < TRANSLATION_CONDITION:
        raise DegenerateCalibrationError(
            f"hand-eye AX=YB: the translations are not determined (condition {tcond:.2e} < {TRANSLATION_CONDITION:g}): "
            "all A rotations share one axis, so a shift along it is unobservable. Rotate about a second axis")
    sol = np.linalg.lstsq(C, rhs, rcond=None)[0]
    return RX, sol[:3], RY, sol[3:], {"rotation_condition": cond, "translation_condition": tcond}


def _residuals(RA, tA, RB, tB, RX, tX, RY, tY, sigma_r, sigma_t) -> tuple[np.ndarray, np.ndarray]:
    left = RA @ RX
    right = np.einsum("ij,njk->nik", RY, RB)
    rot = Rotation.from_matrix(np.einsum("nji,njk->nik", right, left)).as_rotvec()
    tr = np.einsum("nij,j->ni", RA, tX) + tA - np.einsum("ij,nj->ni", RY, tB) - tY
    return rot / sigma_r, tr / sigma_t


def solve_axyb(A: Any, B: Any, *, refine: bool = True, sigma_rotation: float = math.radians(0.5),
               sigma_translation: float = 0.001, loss: str = "linear", name: str = "B") -> CalibrationResult:
    """Solve ``A_i X = Y B_i`` for ``X`` and ``Y`` from ``N`` pose pairs.

    Args:
        A: ``(N, 4, 4)`` homogeneous poses or a pair ``(R (N, 3, 3), t (N, 3))`` (m).
        B: same, the other stream, frame-aligned with ``A``.
        refine: run the nonlinear least-squares refinement after the closed form.
        sigma_rotation: rotation noise scale, rad (residual weighting).
        sigma_translation: translation noise scale, m (residual weighting).
        loss: scipy ``least_squares`` loss (``"linear"``, ``"soft_l1"``, ``"huber"``...) --
            a robust loss helps when some pairs are outliers (e.g. EM distortion near metal).
        name: the result's single "sensor" name (the B stream being aligned).

    Returns:
        ``hand-eye`` :class:`CalibrationResult` with ``sensors = (name,)``, X in
        ``rotation[0]``/``translation[0]``, Y in ``world_rotation[0]``/``world_translation[0]``;
        ``quality``: RMS rotation residual (deg) and translation residual (mm), closed form and
        refined, and the conditioning of both linear systems.

    Raises:
        DegenerateCalibrationError: too few poses, or poses that do not determine X and Y.
    """
    RA, tA = _split(A, "A")
    RB, tB = _split(B, "B")
    if RA.shape[0] != RB.shape[0]:
        raise CalibrationError(f"hand-eye: {RA.shape[0]} A poses but {RB.shape[0]} B poses; they must be paired")
    RX, tX, RY, tY, diag = axyb_closed_form(RA, tA, RB, tB)

    def rms(RX, tX, RY, tY) -> tuple[float, float]:
        r, t = _residuals(RA, tA, RB, tB, RX, tX, RY, tY, 1.0, 1.0)
        return (math.degrees(float(np.sqrt((r ** 2).sum(1).mean()))), 1e3 * float(np.sqrt((t ** 2).sum(1).mean())))

    q: dict[str, Any] = dict(diag)
    q["closed_form_rms_rotation_deg"], q["closed_form_rms_translation_mm"] = rms(RX, tX, RY, tY)
    if refine:
        RX0, RY0 = RX, RY

        def fun(x: np.ndarray) -> np.ndarray:
            RXx = RX0 @ Rotation.from_rotvec(x[0:3]).as_matrix()
            RYx = RY0 @ Rotation.from_rotvec(x[6:9]).as_matrix()
            r, t = _residuals(RA, tA, RB, tB, RXx, x[3:6], RYx, x[9:12], sigma_rotation, sigma_translation)
            return np.concatenate([r.ravel(), t.ravel()])

        x0 = np.concatenate([np.zeros(3), tX, np.zeros(3), tY])
        sol = least_squares(fun, x0, loss=loss, x_scale="jac")
        RX = RX0 @ Rotation.from_rotvec(sol.x[0:3]).as_matrix()
        RY = RY0 @ Rotation.from_rotvec(sol.x[6:9]).as_matrix()
        tX, tY = sol.x[3:6], sol.x[9:12]
        q["refine_status"] = int(sol.status)
    q["rms_rotation_deg"], q["rms_translation_mm"] = rms(RX, tX, RY, tY)
    one = lambda a: torch.from_numpy(np.asarray(a)[None].copy())  # noqa: E731
    return CalibrationResult("hand-eye", (str(name),), rotation=one(RX), translation=one(tX), world_rotation=one(RY),
                             world_translation=one(tY), quality=q,
                             params={"pairs": int(RA.shape[0]), "refine": bool(refine), "loss": loss,
                                     "sigma_rotation": float(sigma_rotation), "sigma_translation": float(sigma_translation),
                                     "equations": "A_i X = Y B_i (Shah 2013); MI-Poser App. B.1 Eq. 6 with A_i=X_t, X=B, Y=A, B_i=Y_t"})


def handeye_transforms(result: CalibrationResult) -> tuple[torch.Tensor, torch.Tensor]:
    """``(X (4, 4), Y (4, 4))`` homogeneous float64 from a ``hand-eye`` result."""
    if result.method != "hand-eye":
        raise CalibrationError(f"handeye_transforms: needs a 'hand-eye' calibration, got {result.method!r}")
    X = torch.eye(4, dtype=F64)
    Y = torch.eye(4, dtype=F64)
    X[:3, :3], X[:3, 3] = result.rotation[0], result.translation[0]
    Y[:3, :3], Y[:3, 3] = result.world_rotation[0], result.world_translation[0]
    return X, Y
