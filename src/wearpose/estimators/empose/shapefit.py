"""Per-recording body-shape fit from the measurements (issue 24: EM-POSE on wearers of every size).

EM-POSE estimates one body shape per sequence (Sec. 5.3), but a network trained on one body
answers that body whatever the wearer. The shape is observable from the measurements
themselves: the sensor offsets are a calibration the estimator knows (the recording's
``subject["offsets"]``), so the EM sensors' positions relative to the source pin down where the
skin sites are, i.e. the bone lengths. The fit solves, over ``n`` frames of the recording,

    min_{u_1..u_n, beta}  sum_i L_r(u_i, beta) + w * ||beta||^2

- ``u_i``: frame i's pose, the 6D rotations of the 20 estimated joints (as in
  :mod:`~wearpose.estimators.empose.refine`), started at the learned estimate; one ``beta``
  ``(10,)`` shared by every frame (one body per wearer), started at the learned sequence shape;
- ``w * ||beta||^2``: the shape prior, the Gaussian N(0, I) of the shape space
  (:mod:`wearpose.body.shapes`: every component one standard deviation), in units of L_r (the
  MAP weight would be the measurement noise variance per residual component; frames of one
  recording are correlated, so the weight is chosen on validation clips, ``docs/empose.md``);
  ``w`` is ``EmposeConfig.shape_fit_prior``. It is a constant, not scaled with ``n``;
- L_r and its gradient in pose and shape: the closed-form kernel of
  :mod:`~wearpose.estimators.empose.fastgrad` (its backward returns dL_r/dbeta beside the pose
  gradient; a float64 test checks the whole gradient against autograd), summed over frames for
  the shared ``beta``; one L-BFGS problem of ``n * 120 + 10`` unknowns
  (:func:`~wearpose.estimators.empose.refine.lbfgs`, ``steps`` iterations, Armijo steps only);
- the guard: the fit is kept only if the summed L_r over the fit frames at the fitted poses and
  shape is not above the learned estimate's (its per-frame poses and shapes). The objective
  never increases, but the prior can trade L_r for a smaller ``||beta||``; a rejected fit
  leaves the learned shape (``ShapeFit.accepted`` False).

The frames (:func:`fit_frames`): offline, ``n`` frames with every sensor valid spread evenly
over the recording (varied poses constrain more bones); online, the first ``n`` such frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from wearpose.estimators.empose.model import PRED_JOINTS
from wearpose.estimators.empose.refine import POSE_DIM, lbfgs
from wearpose.geometry import matrix_to_rot6d


@dataclass(frozen=True)
class ShapeFit:
    """Result of :func:`fit_shape` over ``n`` frames.

    Attributes:
        betas: ``(10,)`` the fitted shape (the learned one when not ``accepted``).
        local_rot: ``(n, 24, 3, 3)`` the fitted poses of the fit frames (root as given).
        rec_before: ``(n,)`` L_r of the learned estimate (its per-frame poses and shapes).
        rec_after: ``(n,)`` L_r at the fitted poses and shape (``rec_before`` when not accepted).
        accepted: whether the fit lowered the summed L_r (module doc, the guard).
    """

    betas: torch.Tensor
    local_rot: torch.Tensor
    rec_before: torch.Tensor
    rec_after: torch.Tensor
    accepted: bool

    def summary(self) -> dict[str, Any]:
        """Plain numbers for a track's extras: frames, summed L_r before / after, accepted."""
        return {"frames": int(self.rec_before.numel()), "rec_before": float(self.rec_before.sum()),
                "rec_after": float(self.rec_after.sum()), "accepted": self.accepted}


def fit_frames(valid: torch.Tensor, n: int, spread: bool = True) -> torch.Tensor:
    """Indices of the fit frames: ``n`` of the frames where ``valid`` ``(T,)`` is True, evenly
    spread (``spread``) or the first ``n``; all of them when there are fewer. ``(k,)`` long."""
    idx = valid.nonzero().squeeze(1)
    if idx.numel() <= n:
        return idx
    if not spread:
        return idx[:n]
    pick = torch.linspace(0, idx.numel() - 1, n, dtype=torch.float64).round().long()
    return idx[pick]


def fit_shape(kernel: Any, local_rot: torch.Tensor, betas: torch.Tensor, rec: torch.Tensor, meas_p: torch.Tensor,
              meas_R: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor, *, steps: int, prior: float,
              rec_weights: tuple[float, float] = (1.0, 1.0)) -> ShapeFit:
    """Fit one shape to ``n`` frames, jointly with their poses (module doc).

    Args:
        kernel: :class:`~wearpose.estimators.empose.fastgrad.LeanSensorGrad` of the estimator's
            sensors (:meth:`VirtualSensors.lean`).
        local_rot: ``(n, 24, 3, 3)`` learned local rotations (root in the source frame);
            betas ``(n, 10)`` the learned per-frame shapes; rec ``(n,)`` their L_r.
        meas_p: ``(n, S, 3)`` m, meas_R ``(n, S, 3, 3)``: measurements relative to the source.
        off_R: ``(S, 3, 3)``; off_t ``(S, 3)`` m: the subject offsets.
        steps: L-BFGS iterations; prior: the weight ``w`` of ``||beta||^2`` (L_r units).
        rec_weights: L_r's (position, rotation) weights (the model's, ``LGDRNN.rec_weights``).

    Returns:
        :class:`ShapeFit`.
    """
    n = local_rot.shape[0]
    u0 = matrix_to_rot6d(local_rot[:, list(PRED_JOINTS)]).reshape(n, POSE_DIM)
    b0 = betas.mean(0)
    B = b0.numel()

    def split(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return x[0, :n * POSE_DIM].view(n, POSE_DIM), x[0, n * POSE_DIM:]

    def fg(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        u, b = split(x)
        ctx = kernel.forward(torch.cat([u, b.expand(n, B)], -1), meas_p, meas_R, off_R, off_t, rec_weights)
        g = kernel.backward(ctx)
        f = ctx["rec"].sum() + prior * (b * b).sum()
        gb = g[:, POSE_DIM:].sum(0) + 2.0 * prior * b
        return f.reshape(1), torch.cat([g[:, :POSE_DIM].reshape(-1), gb])[None]

    x, _ = lbfgs(fg, torch.cat([u0.reshape(-1), b0])[None], steps)
    u, b = split(x)
    ctx = kernel.forward(torch.cat([u, b.expand(n, B)], -1), meas_p, meas_R, off_R, off_t, rec_weights)
    after = ctx["rec"].to(rec.dtype)
    if not bool(torch.isfinite(after).all()) or float(after.sum()) > float(rec.sum()):
        return ShapeFit(b0.clone(), local_rot.clone(), rec.clone(), rec.clone(), False)
    out_rot = ctx["local_rot"].to(local_rot.dtype)
    out_rot[:, 0] = local_rot[:, 0]  # the root is the learned one (L_r does not see it: refine's module doc)
    return ShapeFit(b.detach().clone().to(betas.dtype), out_rot, rec.clone(), after, True)
