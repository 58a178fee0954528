"""MI-Poser sensor-position calibration from a T-pose (Arakawa et al., MI-Poser Sec. 4.2).

"the user simply maintained the default T-pose for a few seconds ... We first estimated a
scaling factor by comparing the arm span between actual sensor measurements and the SMPL model
definition. To compensate for minor sensor offsets, we applied spatial transformations to the
sensor output, ensuring alignment with the SMPL model definitions in the default pose" -- the
glasses map to SMPL joint 15 (head) and the wrist EMF sensors to joints 20/21 (App. A).

Our reading, with the body model's standard shape (betas 0 by default) as "the SMPL model
definition" and every input pose in one world frame M (the headset's VIO world; wrist EM poses
composed with the headset pose, see :func:`em_to_world`), averaged over the static window:

- scale ``s = |w_l - w_r| / |p_lw - p_rw|``: the model's span between the wrist *sites* the
  sensors are worn at over the measured span (comparing with the joint span instead would fold
  the sensor's inboard position into the scale, 4 % on our body); the single-wrist variant uses
  the head-site-to-wrist-site distance;
- world alignment ``R^{WM} = R_y(psi)`` (VIO worlds are gravity-aligned, Y up once canonical):
  ``psi`` makes the measured right->left wrist direction point to +X (one wrist: the headset's
  heading relative to the model's head-site frame); origin: the measured headset position maps
  to the model's ``head`` site;
- per-sensor offsets so that each calibrated sensor equals its target joint at the T-pose::

    R_off_j = (R^{WM} R_j)^T G_j                      (G_j: joint's global rotation, identity at T-pose)
    t_off_j = (R^{WM} R_j)^T (J_j - c_j)              (c_j: the scaled, aligned sensor position)

Applied per frame (:func:`apply_miposer`)::

    R_cal = R^{WM} R_j(t) R_off_j
    p_cal = s R^{WM} (p_j(t) - p_head) + h + R^{WM} R_j(t) t_off_j

(``h`` the model head site, ``p_head`` the mean T-pose headset position). The rotation offsets
compensate sensor mounting, the translation offsets the sensor-to-joint lever arm, which turns
with the sensor.
"""

from __future__ import annotations

from typing import Any, Sequence

import torch

from wearpose.body.skeleton import JOINT_INDEX
from wearpose.calibration._common import F64, CalibrationError, chordal_mean, rotation_y, t64
from wearpose.calibration.result import CalibrationResult
from wearpose.geometry import best_yaw

#: Target SMPL joint of each MI-Poser sensor role (App. A: joints 15, 20, 21).
TARGET_JOINT = {"head": "head", "left_wrist": "left_wrist", "right_wrist": "right_wrist"}


def em_to_world(head_R: torch.Tensor, head_p: torch.Tensor, em_R: torch.Tensor, em_p: torch.Tensor,
                source_R: torch.Tensor | None = None, source_t: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """EM poses relative to a head-worn source -> the headset's world.

    Args:
        head_R, head_p: ``(T, 3, 3)``, ``(T, 3)`` headset pose in its world M (m).
        em_R, em_p: ``(T, 3, 3)``, ``(T, 3)`` EM sensor pose in the source frame.
        source_R, source_t: the source's fixed pose in the headset frame (MI-Poser: "the EMF
            source on the back of the head which has a fixed relative pose to AR glasses");
            default identity / zero (the simulator puts both on the ``head`` site).

    Returns:
        ``(R (T, 3, 3), p (T, 3))`` in M.
    """
    hR, hp, eR, ep = t64(head_R), t64(head_p), t64(em_R), t64(em_p)
    sR = torch.eye(3, dtype=F64) if source_R is None else t64(source_R)
    st = torch.zeros(3, dtype=F64) if source_t is None else t64(source_t)
    srcR = hR @ sR
    srcp = hp + (hR @ st)
    return srcR @ eR, srcp + (srcR @ ep.unsqueeze(-1)).squeeze(-1)


def miposer_tpose(head_R: torch.Tensor, head_p: torch.Tensor, wrist_R: torch.Tensor, wrist_p: torch.Tensor,
                  body: Any, *, wrists: Sequence[str] = ("left_wrist", "right_wrist"), betas: torch.Tensor | None = None,
                  names: Sequence[str] | None = None, head_site: str = "head",
                  wrist_sites: Sequence[str] | None = None) -> CalibrationResult:
    """MI-Poser T-pose calibration: arm-span scale, world alignment and per-sensor offsets.

    Args:
        head_R, head_p: ``(N, 3, 3)``, ``(N, 3)`` headset poses during the static T-pose, world M.
        wrist_R, wrist_p: ``(N, W, 3, 3)``, ``(N, W, 3)`` wrist sensor poses in M (``W`` = 1 or 2).
        body: :class:`wearpose.body.BodyModel` (the "SMPL model definition").
        wrists: target joint of each wrist sensor (``"left_wrist"``/``"right_wrist"``).
        betas: model shape (default: mean shape, as MI-Poser uses a standard body).
        names: sensor names, head first (default ``("head", *wrists)``).
        head_site: body site the headset position corresponds to.
        wrist_sites: body sites the wrist sensors are worn at (default: the ``wrists`` names,
            which are also site names of the embedded asset).

    Returns:
        ``miposer-tpose`` :class:`CalibrationResult` over ``(head, *wrists)``: ``rotation`` =
        ``R_off``, ``translation`` = ``t_off`` (m, model scale, sensor frame), ``world_rotation``
        = ``R^{WM}`` (repeated), ``world_translation`` = ``h - s R^{WM} p_head`` (repeated),
        ``scale`` = ``s``; ``extras["head_position"]`` = ``p_head`` (3,) m.
    """
    hR, hp = t64(head_R), t64(head_p)
    wR, wp = t64(wrist_R), t64(wrist_p)
    if wR.dim() == 3:
        wR, wp = wR[:, None], wp[:, None]
    W = wR.shape[1]
    wrists = list(wrists)[:W] if W < len(wrists) else list(wrists)
    if len(wrists) != W or W not in (1, 2):
        raise CalibrationError(f"miposer calibration: expected 1 or 2 wrist sensors with target joints, got {W} and {wrists}")
    if not (torch.isfinite(hR).all() and torch.isfinite(hp).all() and torch.isfinite(wR).all() and torch.isfinite(wp).all()):
        raise CalibrationError("miposer calibration: NaN in the T-pose window; pass valid frames only")
    names = list(names) if names is not None else ["head", *wrists]
    wrist_sites = list(wrist_sites) if wrist_sites is not None else list(wrists)
    Rh, ph = chordal_mean(hR), hp.mean(0)
    Rw, pw = chordal_mean(wR), wp.mean(0)  # (W, 3, 3), (W, 3)
    zero = torch.eye(3, dtype=body.dtype).repeat(24, 1, 1)
    so = body.sites(zero, None if betas is None else t64(betas).to(body.dtype), None, [head_site, *wrist_sites])
    J = so.joints.to(F64)
    G = so.global_rot.to(F64)
    h = so.positions[0].to(F64)
    ws = so.positions[1:].to(F64)
    Rh_site = so.rotations[0].to(F64)
    jw = [JOINT_INDEX[w] for w in wrists]
    if W == 2:
        span_model = (ws[0] - ws[1]).norm()
        d = pw[0] - pw[1] if wrists[0].startswith("left") else pw[1] - pw[0]  # right -> left
        span_meas = d.norm()
        dh = d.clone()
        dh[1] = 0.0
        if float(dh.norm()) < 0.5 * float(span_meas):
            raise CalibrationError("miposer calibration: the wrist-to-wrist direction is mostly vertical; "
                                   "is the subject in a T-pose (arms horizontal) during the window?")
        psi = torch.atan2(dh[2], dh[0])  # R_y(psi) d points along +X
        quality = {"span_measured_m": float(span_meas), "span_model_m": float(span_model)}
    else:
        span_model = (ws[0] - h).norm()
        span_meas = (pw[0] - ph).norm()
        psi = best_yaw(Rh_site @ Rh.transpose(-1, -2))
        quality = {"head_wrist_measured_m": float(span_meas), "head_wrist_model_m": float(span_model)}
    if float(span_meas) < 1e-3:
        raise CalibrationError("miposer calibration: measured span is ~0 m; are the sensors distinct and tracking?")
    s = float(span_model / span_meas)
    R_WM = rotation_y(psi)
    sens_R = torch.cat([Rh[None], Rw])
    sens_p = torch.cat([ph[None], pw])
    targets = [JOINT_INDEX["head"], *jw]
    c = s * (R_WM @ (sens_p - ph).unsqueeze(-1)).squeeze(-1) + h  # aligned, scaled sensor positions
    A = R_WM @ sens_R  # sensor -> W
    R_off = A.transpose(-1, -2) @ G[targets]
    t_off = (A.transpose(-1, -2) @ (J[targets] - c).unsqueeze(-1)).squeeze(-1)
    S = 1 + W
    quality["lever_arm_m"] = t_off.norm(dim=-1).tolist()
    return CalibrationResult("miposer-tpose", tuple(names), rotation=R_off, translation=t_off,
                             world_rotation=R_WM.expand(S, 3, 3).clone(),
                             world_translation=(h - s * (R_WM @ ph)).expand(S, 3).clone(), scale=s,
                             extras={"head_position": ph}, quality=quality,
                             params={"wrists": wrists, "head_site": head_site, "wrist_sites": wrist_sites, "targets": ["head", *wrists],
                                     "equations": "MI-Poser Sec. 4.2 (arm-span scale, alignment to SMPL T-pose)"})


def apply_miposer(result: CalibrationResult, R: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Calibrated target-joint poses from sensor poses in M.

    Args:
        result: ``miposer-tpose`` calibration.
        R: ``(T, S, 3, 3)`` sensor orientations in M, ``result.sensors`` order (head first).
        p: ``(T, S, 3)`` positions in M, m.

    Returns:
        ``(R_cal (T, S, 3, 3), p_cal (T, S, 3))``: target joint positions (m, model scale) and
        rotations (-> wearpose world), the subject facing +Z at the T-pose. A wrist sensor rides
        on the forearm, so its calibrated rotation is the forearm's (SMPL joint 18/19 global
        rotation; equal to joint 20/21's at the T-pose): the hand's rotation about the wrist is
        not observed.
    """
    if result.method != "miposer-tpose":
        raise CalibrationError(f"apply_miposer: needs a 'miposer-tpose' calibration, got {result.method!r}")
    R, p = t64(R), t64(p)
    A = result.world_rotation @ R
    p_cal = result.scale * (result.world_rotation @ p.unsqueeze(-1)).squeeze(-1) + result.world_translation \
        + (A @ result.translation.unsqueeze(-1)).squeeze(-1)
    return A @ result.rotation, p_cal
