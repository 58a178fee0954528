"""MIMU (9-axis magnetic-inertial) simulator: fused orientation with yaw drift and magnetic
disturbances, plus the orientation representations of BiRAE and Zhou et al.

**Orientation errors** (BiRAE, Butt et al., Sec. IV-A and V-I). BiRAE augments ideal synthetic
orientations with "zero mean Gaussian white noise as well as random impulse noise" and, per
sequence, "a drift in yaw angle of 3D orientation (based on random small bias value integrated
over time)"; Sec. V-I adds "simulated yaw drift and strong magnetic interference" (after
[58], Butt et al. FUSION 2019). The paper gives no magnitudes; ours are assumptions, listed in
:class:`MimuNoise`. The model, per sensor::

    R_meas(t) = R_y(psi_drift(t) + psi_mag(t)) R_WS(t) exp([n(t)]x)

- ``psi_drift(t) = b (t0 + t) + integral of a bias random walk``, ``b ~ N(0, yaw_bias^2)`` (an
  integrated random bias, as in BiRAE); ``t0 ~ U(0, yaw_elapsed)`` is how long the filter has
  been running before the first frame (0 by default: drift starts at the recording's start;
  a short clip cut from a long session starts with the heading error accumulated so far);
- ``psi_mag(t)``: the heading error a magnetometer-aided filter converges to under a
  disturbance field ``d_W(t)``: the filter takes the horizontal measured field as north, so if
  the horizontal field turns by ``delta`` about up, the estimate turns by ``-delta``. Episodes
  start as a Poisson process and have a raised-cosine envelope of random duration and strength
  (a fraction of the horizontal earth field), a constant random horizontal direction;
- ``n(t)``: white orientation noise plus rare impulses (BiRAE's impulse noise).

Rotations about the world vertical (``R_y``, Y up) are what magnetometers and gyro bias
integrate into: pitch and roll stay observable from gravity. The magnetometer output is
consistent with the same disturbance: ``m_S = R_WS^T (m_W + d_W) + noise``, tesla.

**Representations** (BiRAE Appendix A, Eq. 3, 9): BiRAE writes rotation matrices in a Z-up world
(yaw about z, ZYX angles). With our Y-up frames we first permute the up axis to z
(``C R`` with ``C`` = :data:`wearpose.geometry.Y_UP_TO_Z_UP`), then the 6 parameters are
``(r11, r21, r31, r32, r33, r22)`` (first column, last row, plus ``r22`` to resolve the
singular case) and the yaw-free 3 parameters are ``(r31, r32, r33)`` -- the up axis seen in the
rotated frame, which no rotation about the vertical changes. Zhou's 6D is
:func:`wearpose.geometry.matrix_to_rot6d`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from wearpose.errors import ConfigError, ShapeError
from wearpose.geometry import (
    Y_UP_TO_Z_UP, axis_angle_to_matrix, best_yaw, matrix_to_quat, matrix_to_rot6d, rotation_y, vector_heading,
)
from wearpose.sensors.imu import ImuNoise, simulate_imu

#: Earth field in the world frame, tesla: 50 uT, inclination 60 deg (northern hemisphere:
#: pointing down), magnetic north along +Z (an arbitrary but fixed choice).
EARTH_FIELD: tuple[float, float, float] = (0.0, -50e-6 * math.sin(math.radians(60)), 50e-6 * math.cos(math.radians(60)))


@dataclass(frozen=True)
class MimuNoise:
    """MIMU error model (assumed magnitudes; BiRAE gives none).

    Attributes:
        orientation_white: per-axis std of white orientation noise, rad (1 deg).
        impulse_prob: probability per frame of an impulse.
        impulse_sigma: per-axis std of an impulse rotation, rad (5 deg).
        yaw_bias: std of the constant yaw-rate bias integrated into heading drift, rad/s
            (0.1 deg/s: 6 deg per minute).
        yaw_bias_walk: random walk of that bias, rad/s/sqrt(s).
        mag_rate: magnetic-disturbance episodes per second per sensor.
        mag_duration: (min, max) episode duration, s.
        mag_strength: (min, max) peak disturbance field as a fraction of the horizontal earth
            field (1.0 turns the heading by up to 90 deg).
        mag_white: magnetometer white noise per axis, tesla.
        yaw_elapsed: the drift's start lies up to this many seconds before the first frame
            (uniform, one draw per recording, common to its sensors); 0 = drift starts at 0.
        imu: gyro/accelerometer errors of the inertial part (:class:`ImuNoise`).
    """

    orientation_white: float = math.radians(1.0)
    impulse_prob: float = 0.002
    impulse_sigma: float = math.radians(5.0)
    yaw_bias: float = math.radians(0.1)
    yaw_bias_walk: float = math.radians(0.01)
    mag_rate: float = 1.0 / 30.0
    mag_duration: tuple[float, float] = (1.0, 5.0)
    mag_strength: tuple[float, float] = (0.2, 1.0)
    mag_white: float = 0.5e-6
    imu: ImuNoise = ImuNoise()
    yaw_elapsed: float = 0.0

    @staticmethod
    def none() -> MimuNoise:
        return MimuNoise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, (1.0, 1.0), (0.0, 0.0), 0.0, ImuNoise.none())


def yaw_drift(T: int, num_sensors: int, fps: float, bias: float, walk: float,
              generator: torch.Generator | None, elapsed: float = 0.0) -> torch.Tensor:
    """Heading drift ``(T, S)`` rad: integral of (constant random bias + bias random walk).

    ``elapsed`` > 0: the integration started ``t0 ~ U(0, elapsed)`` seconds before frame 0
    (one ``t0`` for all sensors), so frame 0 already carries ``b * t0``; drawn after the other
    terms, so ``elapsed = 0`` leaves every random stream unchanged."""
    dt = 1.0 / fps
    rate = bias * torch.randn(1, num_sensors, generator=generator, dtype=torch.float64).expand(T, num_sensors).clone()
    if walk > 0 and T > 1:
        steps = walk * math.sqrt(dt) * torch.randn(T - 1, num_sensors, generator=generator, dtype=torch.float64)
        rate[1:] += torch.cumsum(steps, 0)
    psi = torch.zeros(T, num_sensors, dtype=torch.float64)
    if T > 1:
        psi[1:] = torch.cumsum(rate[:-1] * dt, 0)
    if elapsed > 0 and T > 0:
        t0 = elapsed * float(torch.rand(1, generator=generator, dtype=torch.float64))
        psi = psi + rate[:1] * t0
    return psi


def magnetic_disturbance(T: int, num_sensors: int, fps: float, noise: MimuNoise,
                         generator: torch.Generator | None,
                         earth: tuple[float, float, float] = EARTH_FIELD) -> tuple[torch.Tensor, torch.Tensor]:
    """Disturbance episodes.

    Returns:
        ``(d_W (T, S, 3) tesla, world frame; psi_mag (T, S) rad heading error of the fused
        orientation)``.
    """
    d = torch.zeros(T, num_sensors, 3, dtype=torch.float64)
    m = torch.tensor(earth, dtype=torch.float64)
    h = float(torch.hypot(m[0], m[2]))
    if noise.mag_rate > 0 and T > 0 and noise.mag_strength[1] > 0:
        g = generator
        p_start = 1.0 - math.exp(-noise.mag_rate / fps)
        starts = torch.rand(T, num_sensors, generator=g, dtype=torch.float64) < p_start
        t = torch.arange(T, dtype=torch.float64) / fps
        for k, s in starts.nonzero().tolist():
            lo, hi = noise.mag_duration
            dur = lo + (hi - lo) * float(torch.rand(1, generator=g, dtype=torch.float64))
            amp = noise.mag_strength[0] + (noise.mag_strength[1] - noise.mag_strength[0]) * float(
                torch.rand(1, generator=g, dtype=torch.float64))
            ang = 2 * math.pi * float(torch.rand(1, generator=g, dtype=torch.float64))
            u = (t - t[k]) / dur
            env = torch.where((u >= 0) & (u <= 1), 0.5 * (1 - torch.cos(2 * math.pi * u)), torch.zeros_like(u))
            d[:, s, 0] += amp * h * math.sin(ang) * env
            d[:, s, 2] += amp * h * math.cos(ang) * env
    tot = m + d
    # Heading of the horizontal field about +Y; the filter's estimate turns by -delta.
    delta = vector_heading(tot) - vector_heading(m)
    delta = torch.remainder(delta + math.pi, 2 * math.pi) - math.pi
    return d, -delta


def simulate_mimu(R: torch.Tensor, p: torch.Tensor, fps: float, *, noise: MimuNoise | None = None,
                  smooth_n: int = 4, ends: str = "one_sided", generator: torch.Generator | None = None,
                  earth: tuple[float, float, float] = EARTH_FIELD, fusion: str | None = None) -> dict[str, torch.Tensor]:
    """Simulate MIMUs: fused orientation (drift, disturbance, noise), inertial channels, magnetometer.

    Args:
        R: ``(T, S, 3, 3)`` true ``R_WS``; p: ``(T, S, 3)`` positions, m (for the accelerometer).
        fps: Hz. noise: :class:`MimuNoise` (``None`` = ideal). smooth_n, ends: as
            :func:`wearpose.sensors.imu.synthetic_acceleration`.
        generator: random source. earth: earth field, tesla, world frame.
        fusion: ``None`` (default): the analytic error model above. ``"madgwick"``: run the
            Madgwick MARG filter (:func:`ahrs_fusion`) on the simulated noisy gyro,
            accelerometer and (disturbed) magnetometer instead; ``"madgwick_imu"``: the same
            without the magnetometer (6-axis, heading drifts with the gyro bias). The white /
            impulse orientation noise and the analytic yaw terms are not added then.

    Returns:
        dict: ``orientation`` ``(T, S, 3, 3)`` fused estimate, ``acceleration`` ``(T, S, 3)``
        free, world, m/s^2 (gravity removed with the fused orientation), ``angular_velocity``
        ``(T, S, 3)`` rad/s sensor frame, ``magnetic_field`` ``(T, S, 3)`` tesla sensor frame,
        ``specific_force``, ``valid`` ``(T,)``, and the error terms ``yaw_error`` ``(T, S)``
        rad and ``disturbance`` ``(T, S, 3)`` tesla (ground truth for evaluation).
    """
    if R.dim() != 4:
        raise ShapeError(f"simulate_mimu: R must be (T, S, 3, 3), got {tuple(R.shape)}")
    dtype = R.dtype
    T, S = R.shape[:2]
    R64 = R.to(torch.float64)
    # The inertial channels carry ImuNoise; the orientation error is this module's model, so the
    # IMU's own white orientation noise is switched off here.
    out = simulate_imu(R64, p.to(torch.float64), fps, noise=None if noise is None else replace(noise.imu, orientation_white=0.0),
                       smooth_n=smooth_n, ends=ends, generator=generator)
    f = out["specific_force"].to(torch.float64)
    m_W = torch.tensor(earth, dtype=torch.float64)
    if noise is None:
        psi = torch.zeros(T, S, dtype=torch.float64)
        d = torch.zeros(T, S, 3, dtype=torch.float64)
        R_meas = R64
        mag_noise = 0.0
    else:
        drift = yaw_drift(T, S, fps, noise.yaw_bias, noise.yaw_bias_walk, generator, noise.yaw_elapsed)
        d, psi_mag = magnetic_disturbance(T, S, fps, noise, generator, earth)
        psi = drift + psi_mag
        rv = noise.orientation_white * torch.randn(T, S, 3, generator=generator, dtype=torch.float64)
        if noise.impulse_prob > 0:
            hit = torch.rand(T, S, 1, generator=generator, dtype=torch.float64) < noise.impulse_prob
            rv = rv + hit * noise.impulse_sigma * torch.randn(T, S, 3, generator=generator, dtype=torch.float64)
        R_meas = rotation_y(psi) @ R64 @ axis_angle_to_matrix(rv)
        mag_noise = noise.mag_white * torch.randn(T, S, 3, generator=generator, dtype=torch.float64)
    mag = (R64.transpose(-1, -2) @ (m_W + d).unsqueeze(-1)).squeeze(-1) + mag_noise
    if fusion is not None:
        if fusion not in ("madgwick", "madgwick_imu"):
            raise ConfigError(f"simulate_mimu: fusion must be None, 'madgwick' or 'madgwick_imu', got {fusion!r}")
        w_meas = out["angular_velocity"].to(torch.float64)
        R_meas = torch.stack([ahrs_fusion(w_meas[:, k], f[:, k], mag[:, k] if fusion == "madgwick" else None, fps, R64[0, k])
                              for k in range(S)], dim=1)
        # heading error of the fused estimate about the vertical (diagnostic)
        E = R_meas @ R64.transpose(-1, -2)
        psi = best_yaw(E)
    g = torch.tensor((0.0, -9.81, 0.0), dtype=torch.float64)
    acc = (R_meas @ f.unsqueeze(-1)).squeeze(-1) + g
    valid = out["valid"]
    if not bool(valid.all()):
        acc[~valid] = 0
    return {"orientation": R_meas.to(dtype), "acceleration": acc.to(dtype),
            "angular_velocity": out["angular_velocity"].to(dtype), "specific_force": f.to(dtype),
            "magnetic_field": mag.to(dtype), "valid": valid, "yaw_error": psi.to(dtype), "disturbance": d.to(dtype)}


#: wearpose world (Y up, magnetic north +Z) -> the ``ahrs`` Madgwick earth frame (x north,
#: z up: x = our +Z, y = our +X, z = our +Y). Checked numerically: a static Madgwick MARG run
#: converges to ``q2R(Q) == C_EW @ R_WS``.
_C_EW = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)


def ahrs_fusion(gyr: torch.Tensor, acc: torch.Tensor, mag: torch.Tensor | None, fps: float, R0: torch.Tensor,
                method: str = "madgwick", gain: float | None = None) -> torch.Tensor:
    """Run a real AHRS filter (the ``ahrs`` package, Madgwick) on simulated MIMU channels.

    Optional dependency: ``ahrs==0.4.0`` (MIT). With ``mag`` it runs the MARG update (heading
    from the magnetometer, so magnetic disturbances turn the heading), without it the IMU
    update (heading integrates the gyro bias: yaw drift).

    Args:
        gyr: ``(T, 3)`` rad/s sensor frame. acc: ``(T, 3)`` specific force (gravity included),
            m/s^2, sensor frame. mag: ``(T, 3)`` tesla sensor frame, or None. fps: Hz.
        R0: ``(3, 3)`` initial orientation ``R_WS(0)`` (the filter starts converged).
        method: ``"madgwick"`` (the only one whose frame conventions are verified here).
        gain: filter gain (``ahrs`` default 0.033 IMU / 0.041 MARG).

    Returns:
        ``(T, 3, 3)`` fused ``R_WS`` in the wearpose world, float64.
    """
    try:
        # start-up: ahrs.common.orientation adds ~45 ms to import wearpose.sensors
        from ahrs.common.orientation import q2R
        from ahrs.filters import Madgwick  # start-up: ahrs.filters adds ~40 ms to import wearpose.sensors
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ConfigError("AHRS fusion needs the optional package ahrs==0.4.0 (pip install ahrs==0.4.0)") from exc
    if method != "madgwick":
        raise ConfigError(f"ahrs_fusion: method must be 'madgwick', got {method!r}")

    q0 = matrix_to_quat(_C_EW @ R0.to(torch.float64)).numpy()
    kw: dict = {"frequency": float(fps)}
    if gain is not None:
        kw["gain"] = gain
    # ahrs integrates gyr[t] over the step (t-1, t]; our samples are instantaneous (central
    # convention), so hand it the trapezoid mean of the two ends of each step.
    w = gyr.detach().to(torch.float64)
    w = torch.cat([w[:1], 0.5 * (w[:-1] + w[1:])], dim=0).numpy()
    a = acc.detach().to(torch.float64).numpy()
    m = None if mag is None else mag.detach().to(torch.float64).numpy() * 1e3  # mT, as ahrs documents
    # Step the filter ourselves: ahrs 0.4.0's batch MARG mode ignores q0 and starts from an
    # NED e-compass solution, inconsistent with the frame its updates use.
    f = Madgwick(**kw)
    Q = np.empty((a.shape[0], 4))
    Q[0] = q0 / np.linalg.norm(q0)
    for t in range(1, a.shape[0]):
        if m is None:
            Q[t] = f.updateIMU(Q[t - 1], gyr=w[t], acc=a[t])
        else:
            Q[t] = f.updateMARG(Q[t - 1], gyr=w[t], acc=a[t], mag=m[t])
    RE = torch.from_numpy(np.stack([q2R(q) for q in Q]))
    return _C_EW.T @ RE


# ------------------------------------------------------------------------------ representations
def _z_up(R: torch.Tensor, up_axis: int) -> torch.Tensor:
    if R.shape[-2:] != (3, 3):
        raise ShapeError(f"expected (..., 3, 3) rotations, got {tuple(R.shape)}")
    if up_axis == 2:
        return R
    if up_axis != 1:
        raise ShapeError(f"up_axis must be 1 (Y up, wearpose) or 2 (Z up), got {up_axis}")
    return Y_UP_TO_Z_UP.to(R) @ R


def birae_6param(R: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """BiRAE 6-parameter representation ``(..., 6)`` = ``(r11, r21, r31, r32, r33, r22)``.

    Args:
        R: ``(..., 3, 3)`` rotations mapping into a frame whose vertical axis is ``up_axis``
            (1: wearpose world / SMPL frames, Y up; 2: already Z up as in the paper).
    """
    Rz = _z_up(R, up_axis)
    return torch.stack([Rz[..., 0, 0], Rz[..., 1, 0], Rz[..., 2, 0], Rz[..., 2, 1], Rz[..., 2, 2], Rz[..., 1, 1]], dim=-1)


def birae_3param(R: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """BiRAE yaw-free 3-parameter representation ``(..., 3)`` = ``(r31, r32, r33)`` (pitch/roll only)."""
    Rz = _z_up(R, up_axis)
    return Rz[..., 2, :].clone()


def birae_6param_to_matrix(c: torch.Tensor, up_axis: int = 1) -> torch.Tensor:
    """Inverse of :func:`birae_6param` ``(..., 6) -> (..., 3, 3)``.

    Column 1 ``a = (r11, r21, r31)`` and row 3 ``(r31, r32, r33)`` are given; column 3 is
    ``a x column 2``, row 3 fixes ``r32, r33`` and ``r22`` is given, so column 2 is recovered
    as the unit vector orthogonal to ``a`` with components ``(r12, r22, r32)``, ``r12`` from
    ``a . col2 = 0`` (singular only when ``r11 = 0``; then the sign-free solution from the
    unit norm is used), and column 3 as ``a x col2``.
    """
    r11, r21, r31, r32, r33, r22 = c.unbind(-1)
    safe = r11.abs() > 1e-6
    r12_dot = -(r21 * r22 + r31 * r32) / torch.where(safe, r11, torch.ones_like(r11))
    r12_norm = torch.sqrt((1 - r22 ** 2 - r32 ** 2).clamp_min(0))
    r12 = torch.where(safe, r12_dot, r12_norm)
    a = torch.stack([r11, r21, r31], -1)
    b = torch.stack([r12, r22, r32], -1)
    a = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    b = b - (a * b).sum(-1, keepdim=True) * a
    b = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    Rz = torch.stack([a, b, torch.cross(a, b, dim=-1)], dim=-1)
    if up_axis == 2:
        return Rz
    return Y_UP_TO_Z_UP.to(Rz).transpose(-1, -2) @ Rz


def zhou_6d(R: torch.Tensor) -> torch.Tensor:
    """Zhou et al. 6D ``(..., 6)``: first two columns (:func:`wearpose.geometry.matrix_to_rot6d`)."""
    return matrix_to_rot6d(R)
