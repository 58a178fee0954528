"""Sensor-to-segment and inertial-frame calibration from a static T-pose or I-pose, and heading
reset for drifting 6-axis IMUs.

**Model** (BiRAE Sec. III-D, Eq. 2a-2b; TransPose/PIP T-pose calibration). A sensor reports
``R^{MS}(t)``: sensor frame S -> the sensor's own world M (its AHRS/fusion frame: gravity-aligned
or not, any heading). The bone B it is strapped to has global rotation::

    R^{WB}(t) = R^{WM} R^{MS}(t) (R^{BS})^T          (Eq. 2a then 2b)

with ``R^{WM}`` (BiRAE's ``R^{GI_i}``) mapping M to wearpose's world W (Y up, the subject faces
+Z at calibration) and ``R^{BS}`` the constant sensor-to-bone rotation. During a static
calibration pose the bones have the known global rotations ``G_j`` of that pose on the body
model (T-pose: zero pose; I-pose: arms down), so once ``R^{WM}`` is known::

    R^{BS}_j = G_j^T R^{WM} mean_t R^{MS}_j(t)       (chordal mean over the static window)

**World alignment without a ground-truth initial pose.** ``R^{WM} = R_y(psi) R_tilt``:

- tilt: gravity. A static accelerometer measures ``f = -g``; a recording in canonical form stores
  the free acceleration the device computed with *its* idea of gravity, ``a = R^{MS} f + g``, so
  ``R^{MS} f = a - g`` is the up direction of M whatever M is. ``R_tilt`` rotates it onto +Y.
  Without acceleration M is assumed level (canonical recordings are Y-up).
- heading ``psi`` (the subject faces +Z during the calibration pose -- this is what defines our
  world, so no initial pose is needed from elsewhere), from one of:

  * ``"normals"`` (default): a sensor lies flat on the skin, so its ``normal_axis`` (+z for
    most IMUs: perpendicular to the case bottom) is the outward skin normal at its site, which
    the body model knows for the calibration pose (EM-POSE Eq. 3 site frame, third column).
    ``psi`` aligns the measured normals with the model's in the horizontal plane (closed-form
    1-D Wahba: ``psi = atan2(sum (m x n)_y, sum m . n)``, horizontal components). The spin of a
    sensor about its normal -- the least repeatable part of strapping -- does not matter.
    Sensors whose normal is vertical at the pose (forearms in a T-pose) carry no heading.
  * ``"reference"``: one sensor with a declared sensor-to-bone rotation (identity by default):
    TransPose's "put IMU 1 aligned with the body frame", BiRAE's "R^{TG} from the root sensor".
  * a number: the heading in radians, given.

**Per-sensor worlds** (``shared_world=False``): 6-axis IMUs without magnetometers each have their
own heading; then each sensor's tilt comes from its own accelerometer and its heading from its
own skin normal (it must be horizontal at the pose: use an I-pose for forearm sensors).

**Heading reset** (:func:`heading_reset`): yaw drift of a 6-axis IMU is a rotation about the
vertical of M, i.e. ``R^{WB} -> R_y(d(t)) R^{WB}``. At a later static calibration pose (a declared
heading-reset event) the expected bone rotations are known again, so the accumulated drift
``d_j`` of each sensor is measured as the best-fit yaw between computed and expected bone
rotations and removed -- as a step from the event on (``"step"``, causal/online) or linearly
interpolated between events and extrapolated at the last rate (``"linear"``, offline; exact for
linear drift).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
import torch

from wearpose.body.poses import IPOSE_ANGLE, POSES, calibration_pose
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.calibration._common import (
    E_Y, F64, G_VEC, CalibrationError, DegenerateCalibrationError, chordal_mean, rotation_y, t64, window_mask,
)
from wearpose.calibration.result import CalibrationResult
from wearpose.geometry import best_yaw, geodesic_angle, rotation_between

#: Acceleration magnitude accepted as "static" gravity, m/s^2 (|f| within 15 % of 9.81).
GRAVITY_TOLERANCE = 0.15


def pose_targets(body: Any, sites: Sequence[str], segments: Sequence[str], pose: str = "tpose",
                 betas: torch.Tensor | None = None, ipose_angle: float = IPOSE_ANGLE) -> tuple[torch.Tensor, torch.Tensor]:
    """Bone rotations and skin normals of a calibration pose on ``body``.

    Returns:
        ``(G (S, 3, 3), n (S, 3))``: global rotation (bone -> world) of each sensor's segment
        and the outward unit skin normal at each site, wearpose world, subject facing +Z.
    """
    P = calibration_pose(pose, ipose_angle)
    so = body.sites(P.to(body.dtype), None if betas is None else t64(betas).to(body.dtype), None, list(sites))
    G = so.global_rot.to(F64)[[JOINT_INDEX[s] for s in segments]]
    return G, so.rotations.to(F64)[:, :, 2]


def _segment_of(site: str) -> str:
    from wearpose.sensors import SITE_SEGMENT  # start-up: wearpose.sensors adds ~110 ms to import wearpose.calibration

    if site in SITE_SEGMENT:
        return SITE_SEGMENT[site]
    if site in JOINT_INDEX:
        return site
    raise CalibrationError(f"no bone segment known for site {site!r}; known sites: {sorted(SITE_SEGMENT)} "
                           "(or give segments=... with SMPL joint names)")


def segment_calibration(R_MS: torch.Tensor, sites: Sequence[str], body: Any, *, acc: torch.Tensor | None = None,
                        valid: torch.Tensor | None = None, names: Sequence[str] | None = None,
                        segments: Sequence[str] | None = None, pose: str = "tpose", betas: torch.Tensor | None = None,
                        heading: str | float = "normals", normal_axis: int = 2, reference_sensor: str | None = None,
                        reference_R_BS: torch.Tensor | None = None, shared_world: bool = True,
                        ipose_angle: float = IPOSE_ANGLE, min_heading_strength: float = 0.3,
                        max_motion_deg: float = 5.0) -> CalibrationResult:
    """Sensor-to-segment ``R^{BS}`` and world alignment ``R^{WM}`` from a static calibration pose.

    Args:
        R_MS: ``(N, S, 3, 3)`` sensor orientations during the static window (sensor -> M).
        sites: ``S`` body sites the sensors are worn at.
        body: :class:`wearpose.body.BodyModel` (site normals and bone rotations of the pose).
        acc: ``(N, S, 3)`` canonical free acceleration (M frame, m/s^2) during the window, for
            the tilt; ``None`` = M is level.
        valid: ``(N, S)`` bool.
        names: sensor names (default: ``sites``).
        segments: SMPL joint per sensor (default: :data:`wearpose.sensors.SITE_SEGMENT`).
        pose: ``"tpose"`` or ``"ipose"``.
        betas: subject shape for the model's pose (default mean shape).
        heading: ``"normals"``, ``"reference"`` or an angle in radians (module doc).
        normal_axis: sensor axis (0, 1, 2) perpendicular to the skin, pointing out.
        reference_sensor: sensor name for ``heading="reference"``.
        reference_R_BS: its declared sensor-to-bone rotation ``(3, 3)`` (default identity).
        shared_world: one ``R^{WM}`` for all sensors (True) or one per sensor.
        ipose_angle: arm angle of the I-pose, rad.
        min_heading_strength: minimum summed horizontal normal length for ``"normals"``.
        max_motion_deg: largest deviation (deg) of a sensor from its mean orientation accepted
            in the window; more means the subject was not holding the pose.

    Returns:
        ``tpose``/``ipose`` :class:`CalibrationResult`: ``rotation`` = ``R^{BS}`` (S, 3, 3),
        ``world_rotation`` = ``R^{WM}`` per sensor (S, 3, 3); ``quality``: per-sensor angle
        between measured and model skin normal (deg), gravity magnitude (m/s^2), stillness
        (deg, spread of the orientation over the window).

    Raises:
        DegenerateCalibrationError: no heading information (normals all vertical).
        CalibrationError: missing frames, accelerations not looking like gravity.
    """
    R = t64(R_MS)
    if R.dim() != 4 or R.shape[-2:] != (3, 3):
        raise CalibrationError(f"segment calibration: R_MS must be (N, S, 3, 3), got {tuple(R.shape)}")
    N, S = R.shape[:2]
    sites = list(sites)
    names = list(names) if names is not None else list(sites)
    if len(sites) != S or len(names) != S:
        raise CalibrationError(f"segment calibration: {S} sensors but {len(sites)} sites / {len(names)} names")
    segments = list(segments) if segments is not None else [_segment_of(s) for s in sites]
    ok = torch.isfinite(R).all(-1).all(-1)
    if valid is not None:
        ok = ok & torch.as_tensor(valid, dtype=torch.bool).reshape(N, S)
    empty = [names[j] for j in range(S) if not ok[:, j].any()]
    if empty:
        raise CalibrationError(f"segment calibration: sensor(s) {empty} have no valid frame in the calibration window")
    w = ok.to(F64)
    Rbar = chordal_mean(torch.where(ok[..., None, None], R, torch.zeros((), dtype=F64)), w)  # (S, 3, 3)
    still = torch.stack([geodesic_angle(Rbar[j].expand(int(ok[:, j].sum()), 3, 3), R[ok[:, j], j]).max() for j in range(S)])

    quality: dict[str, Any] = {"stillness_max_deg": torch.rad2deg(still).tolist()}
    moving = [names[j] for j in range(S) if math.degrees(float(still[j])) > max_motion_deg]
    if moving:
        raise CalibrationError(f"segment calibration: sensor(s) {moving} turn by up to "
                               f"{[round(math.degrees(float(still[names.index(n)])), 1) for n in moving]} deg during the calibration "
                               f"window (> {max_motion_deg} deg): the subject was not static in the {pose}; choose a window "
                               "where the pose is held")
    # Tilt: up direction of M from gravity.
    if acc is not None:
        a = t64(acc)
        okA = ok & torch.isfinite(a).all(-1)
        f = torch.where(okA[..., None], a - G_VEC, torch.zeros((), dtype=F64))  # R^{MS} f_S = a - g
        cnt = okA.sum(0).clamp_min(1).to(F64)
        f_s = f.sum(0) / cnt[:, None]  # (S, 3) mean specific force in M per sensor
        mag = f_s.norm(dim=-1)
        quality["gravity_norm_ms2"] = mag.tolist()
        bad = [names[j] for j in range(S) if abs(float(mag[j]) - 9.81) > GRAVITY_TOLERANCE * 9.81]
        if bad:
            raise CalibrationError(f"segment calibration: during the calibration window the acceleration of {bad} is not "
                                   f"gravity (|a - g| = {[round(float(mag[names.index(b)]), 2) for b in bad]} m/s^2, expected "
                                   "~9.81): the subject was not static, or the acceleration is not canonical free acceleration "
                                   "in m/s^2 (declare acc_unit/acc_frame/acc_gravity and call Recording.to_canonical())")
        up = f_s if not shared_world else f_s.sum(0, keepdim=True).expand(S, 3)
    else:
        up = E_Y.expand(S, 3)
    R_tilt = rotation_between(up, E_Y.expand(S, 3))  # (S, 3, 3)

    G, n_model = pose_targets(body, sites, segments, pose, betas, ipose_angle)
    m = (R_tilt @ Rbar)[..., :, normal_axis]  # measured skin normals after tilt, (S, 3)
    if isinstance(heading, (int, float)) and not isinstance(heading, bool):
        psi = torch.full((S,), float(heading), dtype=F64)
    elif heading == "normals":
        mh, nh = m.clone(), n_model.clone()
        mh[:, 1] = 0.0
        nh[:, 1] = 0.0
        cross_y = torch.cross(mh, nh, dim=-1)[:, 1]
        dot = (mh * nh).sum(-1)
        strength = mh.norm(dim=-1) * nh.norm(dim=-1)
        quality["heading_strength"] = strength.tolist()
        if shared_world:
            if float(strength.sum()) < min_heading_strength:
                raise DegenerateCalibrationError(
                    f"segment calibration: no heading information in the {pose}: every sensor's skin normal is (nearly) "
                    f"vertical (horizontal strengths {[round(float(s), 2) for s in strength]}, need a sum >= {min_heading_strength}). "
                    "Use heading='reference' with a sensor of known mounting, an I-pose, or give the heading in radians")
            psi = torch.atan2(cross_y.sum(), dot.sum()).expand(S).clone()
        else:
            weak = [names[j] for j in range(S) if float(strength[j]) < min_heading_strength]
            if weak:
                raise DegenerateCalibrationError(
                    f"segment calibration (per-sensor worlds): the skin normal of {weak} is (nearly) vertical in the {pose}, "
                    "so its own heading cannot be found; use an I-pose (forearm normals point sideways) or shared_world=True")
            psi = torch.atan2(cross_y, dot)
    elif heading == "reference":
        if reference_sensor is None or reference_sensor not in names:
            raise CalibrationError(f"segment calibration: heading='reference' needs reference_sensor, one of {names}; got {reference_sensor!r}")
        j = names.index(reference_sensor)
        RBS = torch.eye(3, dtype=F64) if reference_R_BS is None else t64(reference_R_BS)
        full = G[j] @ RBS @ Rbar[j].transpose(-1, -2)  # R^{WM} that makes the reference bone exact
        psi = best_yaw(full @ R_tilt[j].transpose(-1, -2)).expand(S).clone()
    else:
        raise CalibrationError(f"segment calibration: heading must be 'normals', 'reference' or an angle in radians, got {heading!r}")

    R_WM = rotation_y(psi) @ R_tilt  # (S, 3, 3)
    R_BS = G.transpose(-1, -2) @ R_WM @ Rbar
    normal_err = torch.rad2deg(torch.acos(((R_WM @ Rbar)[..., :, normal_axis] * n_model).sum(-1).clamp(-1, 1)))
    quality["normal_angle_deg"] = normal_err.tolist()
    return CalibrationResult(pose, tuple(names), rotation=R_BS, world_rotation=R_WM, quality=quality,
                             params={"pose": pose, "sites": sites, "segments": segments,
                                     "heading": heading if isinstance(heading, str) else float(heading),
                                     "normal_axis": int(normal_axis), "reference_sensor": reference_sensor,
                                     "shared_world": bool(shared_world), "ipose_angle": float(ipose_angle),
                                     "equations": "BiRAE Eq. 2a-2b; TransPose/PIP T-pose calibration"})


def heading_correction(result: CalibrationResult, timestamps: torch.Tensor | np.ndarray) -> torch.Tensor:
    """Yaw correction ``(T, S)`` rad at ``timestamps`` from the heading-reset anchors in ``result``.

    Zero when ``result`` has no anchors. ``"step"``: the latest anchor at or before ``t`` (what an
    online system can do); ``"linear"``: a piecewise-linear drift model through the anchors,
    continued at the first/last segment's rate before the first and after the last anchor.
    """
    ts = t64(timestamps)
    S = len(result.sensors)
    if "heading_times" not in result.extras:
        return torch.zeros(ts.shape[0], S, dtype=F64)
    at, ay = result.extras["heading_times"], result.extras["heading_yaw"]
    mode = result.params.get("heading_interpolation", "linear")
    if mode == "step":
        k = torch.searchsorted(at, ts + 1e-9, right=True) - 1
        return torch.where((k >= 0)[:, None], ay[k.clamp_min(0)], torch.zeros((), dtype=F64))
    out = torch.empty(ts.shape[0], S, dtype=F64)
    x, xa = ts.numpy(), at.numpy()
    for j in range(S):
        ya = ay[:, j].numpy()
        y = np.interp(x, xa, ya)
        if len(xa) >= 2:
            # A piecewise-linear drift model: continue the first/last segment's rate outside.
            lo, hi = x < xa[0], x > xa[-1]
            y[lo] = ya[0] + (x[lo] - xa[0]) * (ya[1] - ya[0]) / (xa[1] - xa[0])
            y[hi] = ya[-1] + (x[hi] - xa[-1]) * (ya[-1] - ya[-2]) / (xa[-1] - xa[-2])
        out[:, j] = torch.from_numpy(y)
    return out


def bone_orientations(R_MS: torch.Tensor, result: CalibrationResult, timestamps: torch.Tensor | np.ndarray | None = None
                      ) -> torch.Tensor:
    """Apply a ``tpose``/``ipose`` calibration: ``R^{WB} = R_y(d(t)) R^{WM} R^{MS} (R^{BS})^T`` (BiRAE Eq. 2a-2b).

    Args:
        R_MS: ``(T, S, 3, 3)`` sensor orientations (sensor -> M), sensors in ``result.sensors`` order.
        result: the calibration.
        timestamps: ``(T,)`` s, needed when ``result`` holds heading-reset anchors.

    Returns:
        ``(T, S, 3, 3)`` bone orientations (bone -> wearpose world).
    """
    R = t64(R_MS)
    out = result.world_rotation @ R @ result.rotation.transpose(-1, -2)
    if "heading_times" in result.extras:
        if timestamps is None:
            raise CalibrationError("bone_orientations: this calibration has heading resets; pass the timestamps")
        out = rotation_y(heading_correction(result, timestamps)) @ out
    return out


def heading_reset(R_MS: torch.Tensor, timestamps: torch.Tensor | np.ndarray, result: CalibrationResult,
                  events: Sequence[tuple[float, float]], body: Any, *, pose: str | None = None,
                  betas: torch.Tensor | None = None, facing: str = "initial", reference_sensor: str | None = None,
                  interpolation: str = "linear", valid: torch.Tensor | None = None) -> CalibrationResult:
    """Re-estimate each sensor's heading at later static calibration poses (heading-reset events).

    Args:
        R_MS: ``(T, S, 3, 3)`` sensor orientations of the whole recording (``result.sensors`` order).
        timestamps: ``(T,)`` s.
        result: the initial ``tpose``/``ipose`` calibration.
        events: ``[(start_s, stop_s), ...]`` windows in which the subject again holds the
            calibration pose, in time order.
        body, betas: the body model (bone rotations of the pose).
        pose: pose held at the events (default: the calibration's).
        facing: ``"initial"`` -- the subject faces the same direction as at the first calibration
            (e.g. a floor mark), so each sensor's absolute drift is removed; ``"root"`` -- any
            direction: drifts are removed relative to ``reference_sensor`` (default: the sensor
            on the pelvis), leaving a common heading that root-relative estimators ignore.
        interpolation: ``"linear"`` (offline) or ``"step"`` (online).
        valid: ``(T, S)`` bool.

    Returns:
        A copy of ``result`` with ``extras["heading_times"]`` ``(K+1,)`` s and
        ``extras["heading_yaw"]`` ``(K+1, S)`` rad (the correction at each anchor, the first one
        0 at the initial calibration), applied by :func:`bone_orientations`.
    """
    if result.method not in POSES:
        raise CalibrationError(f"heading_reset: needs a tpose/ipose calibration, got {result.method!r}")
    if interpolation not in ("linear", "step"):
        raise CalibrationError(f"heading_reset: interpolation must be 'linear' or 'step', got {interpolation!r}")
    if facing not in ("initial", "root"):
        raise CalibrationError(f"heading_reset: facing must be 'initial' or 'root', got {facing!r}")
    R = t64(R_MS)
    ts = t64(timestamps)
    S = len(result.sensors)
    pose = pose or result.params.get("pose", result.method)
    sites, segments = result.params["sites"], result.params["segments"]
    G, _ = pose_targets(body, sites, segments, pose, betas, result.params.get("ipose_angle", IPOSE_ANGLE))
    ok = torch.isfinite(R).all(-1).all(-1)
    if valid is not None:
        ok = ok & torch.as_tensor(valid, dtype=torch.bool)
    if facing == "root":
        ref = reference_sensor
        if ref is None:
            ref = next((n for n, s in zip(result.sensors, sites) if s == "pelvis"), None)
        if ref is None or ref not in result.sensors:
            raise CalibrationError(f"heading_reset(facing='root'): reference_sensor must be one of {list(result.sensors)}; got {ref!r}")
        jref = result.sensors.index(ref)
    base = result.world_rotation @ R @ result.rotation.transpose(-1, -2)  # uncorrected bones
    win = result.params.get("window")
    t_anchor = [0.5 * (float(win[0]) + float(win[1])) if win else float(ts[0])]
    y_anchor = [torch.zeros(S, dtype=F64)]
    for (t0, t1) in events:
        m = torch.from_numpy(window_mask(ts.numpy(), (t0, t1), "heading_reset"))
        okw = ok[m]
        if not okw.any(0).all():
            raise CalibrationError(f"heading_reset: some sensors have no valid frame in the event window [{t0}, {t1}) s")
        Rb = chordal_mean(torch.where(okw[..., None, None], base[m], torch.zeros((), dtype=F64)), okw.to(F64))  # (S, 3, 3)
        e = best_yaw(Rb @ G.transpose(-1, -2))  # accumulated yaw error of each sensor
        if facing == "root":
            e = e - e[jref]
        corr = -e
        # Unwrap against the previous anchor so interpolation takes the short way.
        prev = y_anchor[-1]
        corr = prev + torch.remainder(corr - prev + math.pi, 2 * math.pi) - math.pi
        t_anchor.append(0.5 * (float(t0) + float(t1)))
        y_anchor.append(corr)
    extras = dict(result.extras)
    extras["heading_times"] = torch.tensor(t_anchor, dtype=F64)
    extras["heading_yaw"] = torch.stack(y_anchor)
    params = dict(result.params)
    params.update(heading_interpolation=interpolation, heading_facing=facing, heading_events=[list(map(float, e)) for e in events])
    quality = dict(result.quality)
    quality["heading_reset_yaw_deg"] = torch.rad2deg(torch.stack(y_anchor)).tolist()
    return CalibrationResult(result.method, result.sensors, rotation=result.rotation, world_rotation=result.world_rotation,
                             extras=extras, quality=quality, params=params)
