"""EM-POSE subject offsets ``O_p`` from a calibration sequence (Kaufmann et al. ICCV 2021, supp. Sec. 1).

The virtual sensor of EM-POSE Eq. 4 (:func:`wearpose.sensors.apply_offsets`) is
``R^v = R~ R_off``, ``p^v = p~ + R~ t_off`` with the skin-site frame ``(p~, R~)`` of Eq. 3
(:meth:`wearpose.body.BodyModel.sites`). Replacing ``(R^v, p^v)`` by the real measurements
``(R_s, p_s)`` of a calibration sequence whose body pose is known (EM-POSE's reference poses
come from a multi-view capture, ours from ``Recording.ground_truth``) gives one offset per frame::

    R(t) = R~(t)^T R_s(t)              t(t) = R~(t)^T (p_s(t) - p~(t))

and one offset per sensor (supp. Eq. 1-3)::

    t = mean_t t(t)                                            (Eq. 1)
    U S V^T = SVD(sum_t R(t)),   R = U diag(1, 1, sign det(U V^T)) V^T   (Eq. 2, 3)

plus the multivariate normal ``phi(t) = N(t, cov_t t(t))`` of supp. Sec. 2.2 that
:meth:`wearpose.sensors.EMOffsets.draw` samples from for per-sequence augmentation.

EM measurements relative to the source (DESIGN: EM canonical form) are compared with the site
frames expressed in the source site's frame; the source's rotation cancels in ``R~^T R_s``, so
the offsets are the same as in the world frame.
"""

from __future__ import annotations

import torch

from wearpose.calibration._common import F64, CalibrationError, chordal_mean, t64
from wearpose.calibration.result import CalibrationResult
from wearpose.geometry import geodesic_angle


def per_frame_offsets(sensor_R: torch.Tensor, sensor_p: torch.Tensor, site_R: torch.Tensor, site_p: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """Solve EM-POSE Eq. 4 for the offset at every frame.

    Args:
        sensor_R: ``(T, S, 3, 3)`` measured sensor orientations (sensor -> frame F).
        sensor_p: ``(T, S, 3)`` measured sensor positions in F, m.
        site_R: ``(T, S, 3, 3)`` skin-site frames (site -> F) of the reference pose.
        site_p: ``(T, S, 3)`` site vertex positions in F, m.

    Returns:
        ``(R(t) (T, S, 3, 3), t(t) (T, S, 3))``: rotation sensor -> site frame and translation in
        the site frame, m (F cancels: any common frame works).
    """
    sR, sp, kR, kp = t64(sensor_R), t64(sensor_p), t64(site_R), t64(site_p)
    kRT = kR.transpose(-1, -2)
    return kRT @ sR, (kRT @ (sp - kp).unsqueeze(-1)).squeeze(-1)


def fit_offsets(R_t: torch.Tensor, t_t: torch.Tensor, valid: torch.Tensor | None = None,
                names: tuple[str, ...] | None = None) -> CalibrationResult:
    """Per-sensor offsets from per-frame offsets (EM-POSE supp. Eq. 1-3 and Sec. 2.2).

    Args:
        R_t: ``(T, S, 3, 3)`` per-frame rotation offsets (sensor -> site).
        t_t: ``(T, S, 3)`` per-frame translation offsets (site frame, m).
        valid: ``(T, S)`` bool, frames to use (dropped EM frames are excluded; NaN frames are
            excluded automatically).
        names: ``S`` sensor names (default ``s0..``).

    Returns:
        ``empose-offsets`` :class:`CalibrationResult`: ``rotation`` = ``R`` (Eq. 2-3),
        ``translation`` = ``t`` (Eq. 1), ``translation_cov`` = covariance of ``t(t)`` (m^2,
        the fitted ``phi(t)`` of supp. Sec. 2.2); ``quality`` has per-sensor spread (median
        distance of the per-frame offsets from the mean, mm and degrees) and frame counts.
    """
    R_t, t_t = t64(R_t), t64(t_t)
    T, S = R_t.shape[:2]
    ok = torch.isfinite(R_t).all(-1).all(-1) & torch.isfinite(t_t).all(-1)
    if valid is not None:
        ok = ok & torch.as_tensor(valid, dtype=torch.bool).reshape(T, S)
    names = tuple(names) if names is not None else tuple(f"s{i}" for i in range(S))
    n = ok.sum(0)
    few = [names[j] for j in range(S) if int(n[j]) < 2]
    if few:
        raise CalibrationError(f"empose offsets: sensor(s) {few} have fewer than 2 valid frames in the calibration sequence")
    w = ok.to(F64)
    Rz = torch.where(ok[..., None, None], R_t, torch.zeros((), dtype=F64))
    tz = torch.where(ok[..., None], t_t, torch.zeros((), dtype=F64))
    R = chordal_mean(Rz, w)  # Eq. 2-3
    t = tz.sum(0) / n[:, None]  # Eq. 1
    d = torch.where(ok[..., None], t_t - t, torch.zeros((), dtype=F64))
    cov = torch.einsum("tsi,tsj->sij", d, d) / (n[:, None, None] - 1).to(F64)  # unbiased, supp. 2.2
    ang = geodesic_angle(R.expand_as(R_t).reshape(-1, 3, 3), torch.where(ok[..., None, None], R_t, R.expand_as(R_t)).reshape(-1, 3, 3)).reshape(T, S)
    dist = d.norm(dim=-1)
    q = {"frames": n.tolist(),
         "median_translation_spread_mm": [float(dist[ok[:, j], j].median() * 1e3) for j in range(S)],
         "median_rotation_spread_deg": [float(torch.rad2deg(ang[ok[:, j], j].median())) for j in range(S)]}
    return CalibrationResult("empose-offsets", names, rotation=R, translation=t, translation_cov=cov, quality=q,
                             params={"equations": "EM-POSE supp. Eq. 1-3, Sec. 2.2"})


def empose_offsets(sensor_R: torch.Tensor, sensor_p: torch.Tensor, motion, body, sites: list[str] | tuple[str, ...], *,
                   source_site: str | None = None, valid: torch.Tensor | None = None,
                   names: tuple[str, ...] | None = None, source_offset=None) -> CalibrationResult:
    """Subject offsets from measured EM poses and the reference body motion of a calibration sequence.

    Args:
        sensor_R: ``(T, S, 3, 3)`` measured orientations, relative to the EM source (or world
            when ``source_site`` is None), frame-aligned with ``motion``.
        sensor_p: ``(T, S, 3)`` measured positions, m, same frame.
        motion: :class:`wearpose.motion.MotionSequence` of ``T`` frames (the reference poses and
            the subject's betas).
        body: :class:`wearpose.body.BodyModel` defining the sites.
        sites: ``S`` site names the sensors are worn at.
        source_site: site carrying the EM source (measurements are relative to it), or ``None``
            when the measurements are in the world frame (EM-POSE's released data).
        valid: ``(T, S)`` bool validity.
        names: sensor names for the result (default: ``sites``).
        source_offset: optional :class:`wearpose.sensors.EMOffsets` (1 sensor) mounting the
            source on its site, as given to the simulator.

    Returns:
        ``empose-offsets`` :class:`CalibrationResult` (see :func:`fit_offsets`).
    """
    # start-up: wearpose.sensors adds ~110 ms to import wearpose.calibration
    from wearpose.sensors import apply_offsets, relative_to_source

    sR, sp = t64(sensor_R), t64(sensor_p)
    if sR.dim() != 4 or sR.shape[-2:] != (3, 3) or sp.shape != sR.shape[:-1]:
        raise CalibrationError(f"empose offsets: expected sensor_R (T, S, 3, 3) and sensor_p (T, S, 3), got {tuple(sR.shape)} and {tuple(sp.shape)}")
    T, S = sR.shape[:2]
    if motion.num_frames != T:
        raise CalibrationError(f"empose offsets: {T} sensor frames but the reference motion has {motion.num_frames}; "
                               "align them first (same rate and start)")
    if len(sites) != S:
        raise CalibrationError(f"empose offsets: {S} sensors but {len(sites)} site names")
    wanted = list(dict.fromkeys(list(sites) + ([source_site] if source_site else [])))
    so = body.sites(motion.pose, motion.betas, motion.trans, wanted)
    col = {n: i for i, n in enumerate(wanted)}
    idx = [col[s] for s in sites]
    kR, kp = so.rotations[:, idx].to(F64), so.positions[:, idx].to(F64)
    if source_site:
        srcR, srcp = so.rotations[:, col[source_site]].to(F64), so.positions[:, col[source_site]].to(F64)
        if source_offset is not None:
            r, p = apply_offsets(srcR[:, None], srcp[:, None], source_offset)
            srcR, srcp = r[:, 0], p[:, 0]
        kR, kp = relative_to_source(kR, kp, srcR, srcp)
    R_t, t_t = per_frame_offsets(sR, sp, kR, kp)
    res = fit_offsets(R_t, t_t, valid, tuple(names) if names is not None else tuple(sites))
    res.params.update({"sites": list(sites), "source_site": source_site, "frames": T, "fps": float(motion.fps)})
    return res
