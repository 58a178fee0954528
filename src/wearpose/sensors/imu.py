"""IMU simulator: orientation, free acceleration and gyro from a sensor site's trajectory.

Inputs are the site's orientation ``R_WS(t)`` (sensor frame -> world) and position ``p(t)`` in the
Y-up world, sampled at ``fps``. Outputs follow the canonical inertial form of DESIGN.md:

- ``orientation``: ``R_WS`` ``(T, ..., 3, 3)``;
- ``acceleration``: free acceleration in the **world** frame, gravity removed, m/s^2;
- ``angular_velocity``: in the **sensor** frame, rad/s;
- optionally ``specific_force``: what an accelerometer measures, in the sensor frame, gravity
  included, ``f_S = R_WS^T (a_W - g)`` with ``g = (0, -9.81, 0)`` (so a sensor at rest reads
  ``+9.81`` along the world up axis expressed in its frame).

**Acceleration** (TransPose/PIP synthesis). PIP synthesises its AMASS IMU data "as proposed by
Yi et al." (TransPose; PIP supplementary, "Datasets"). TransPose's ``preprocess.py``
(``process_amass(smooth_n=4)`` -> ``_syn_acc``) takes the second central difference of the
sensor vertex over a widened stencil, ``n = smooth_n = 4`` frames at 60 Hz::

    a(t) = (p(t - n) + p(t + n) - 2 p(t)) / (n dt)^2          for n <= t < T - n
    a(t) = (p(t - 1) + p(t + 1) - 2 p(t)) / dt^2              for the frames next to the ends
    a(0) = a(T - 1) = 0                                         (TransPose zero-pads)

(source: code search "TransPose _syn_acc smooth_n" -> ``Xinyu-Yi/TransPose`` ``preprocess.py``,
commit 2ff1d143; its constant 3600 is ``fps^2`` at 60 Hz. Derived projects such as MobilePoser
copy it with ``fps`` as a parameter.) :func:`wearpose.sensors.simulate` keeps the same *time*
window at other rates (``n = round(4 rate / 60)``). The
widened stencil is a low-pass: a sinusoid of angular frequency ``w`` is scaled by
``2 (1 - cos(w n dt)) / (w n dt)^2`` (0.985 at 1 Hz, 0.94 at 2 Hz with n=4 at 60 Hz).

Ends: frames ``1..n-1`` and ``T-n..T-2`` use the unsmoothed central difference as TransPose does.
The two extreme frames are handled by ``ends``:

- ``"one_sided"`` (default): second-order one-sided difference
  ``a(0) = (2 p0 - 5 p1 + 4 p2 - p3) / dt^2`` (mirrored at the end); every frame valid.
- ``"mask"``: the extreme frames are marked invalid (``valid=False``) and set to 0.
- ``"zero"``: TransPose's zero padding, frames left valid (the same numbers as its synthesis).

**Gyro** from orientation increments. ``log(R_t^T R_{t+1}) * fps`` is the body-frame angular
velocity at the *midpoint* ``t + 1/2`` (exact for a constant body rate). Two conventions:

- ``"central"`` (default): the sample at ``t`` is the mean of the two midpoint rates around it,
  ``w_t = (w_{t-1/2} + w_{t+1/2}) / 2`` (second-order accurate, exact for constant rate);
  the ends are linearly extrapolated from the two nearest midpoint rates.
  :func:`integrate_gyro` inverts it (trapezoid + 4-point correction).
- ``"forward"``: ``w_t = w_{t+1/2}`` (last frame repeats); integrates exactly with
  ``R_{t+1} = R_t exp(w_t dt)`` (what a causal strapdown integrator does).

**Noise** (:class:`ImuNoise`): per axis, in the sensor frame, for gyro and accelerometer:
white noise (density, per sample ``sigma = density * sqrt(fps)``), a constant turn-on bias drawn
once per sequence, and a bias random walk (``b_{k+1} = b_k + N(0, rw^2 dt)``); plus white
orientation noise (a random rotation vector applied in the sensor frame). The noisy free
acceleration is formed as a device does it: ``a = R_meas f_meas + g``, so orientation error
leaks gravity into it. Default magnitudes are typical MEMS figures (Xsens-MTw class), an
assumption, not taken from the four papers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from wearpose.errors import ShapeError
from wearpose.geometry import GRAVITY, axis_angle_to_matrix, matrix_to_axis_angle

ACC_ENDS = ("one_sided", "mask", "zero")
GYRO_CONVENTIONS = ("central", "forward")


def _gravity(dtype: torch.dtype, device: torch.device | None = None) -> torch.Tensor:
    return torch.tensor(GRAVITY, dtype=dtype, device=device)


def synthetic_acceleration(p: torch.Tensor, fps: float, smooth_n: int = 4, ends: str = "one_sided"
                           ) -> tuple[torch.Tensor, torch.Tensor]:
    """Free acceleration of a point by second central differences (TransPose/PIP synthesis).

    Args:
        p: ``(T, ..., 3)`` positions, metres, world frame; time first.
        fps: sample rate, Hz.
        smooth_n: stencil half-width ``n`` (TransPose/PIP: 4 at 60 Hz; 1 = no smoothing).
        ends: ``"one_sided"`` | ``"mask"`` | ``"zero"`` (module doc).

    Returns:
        ``(a, valid)``: ``a`` ``(T, ..., 3)`` m/s^2 in the world frame (gravity not included),
        ``valid`` ``(T,)`` bool.
    """
    if p.shape[-1] != 3 or p.dim() < 2:
        raise ShapeError(f"synthetic_acceleration: p must be (T, ..., 3), got {tuple(p.shape)}")
    if ends not in ACC_ENDS:
        raise ShapeError(f"synthetic_acceleration: ends must be one of {ACC_ENDS}, got {ends!r}")
    n = int(smooth_n)
    if n < 1:
        raise ShapeError(f"synthetic_acceleration: smooth_n must be >= 1, got {smooth_n}")
    T = p.shape[0]
    x = p.to(torch.float64)
    dt2 = 1.0 / float(fps) ** 2
    a = torch.zeros_like(x)
    valid = torch.ones(T, dtype=torch.bool, device=p.device)
    if T >= 3:
        a[1:-1] = (x[:-2] + x[2:] - 2 * x[1:-1]) / dt2
    if n > 1 and T > 2 * n:
        a[n:-n] = (x[:-2 * n] + x[2 * n:] - 2 * x[n:-n]) / (dt2 * n * n)
    if ends == "one_sided" and T >= 4:
        a[0] = (2 * x[0] - 5 * x[1] + 4 * x[2] - x[3]) / dt2
        a[-1] = (2 * x[-1] - 5 * x[-2] + 4 * x[-3] - x[-4]) / dt2
    elif ends == "one_sided" and T == 3:
        a[0] = a[-1] = a[1]
    elif ends == "mask" or T < 3:
        a[0] = 0
        a[-1] = 0
        valid[0] = False
        valid[-1] = False
    return a.to(p.dtype), valid


def _log_increments(R: torch.Tensor) -> torch.Tensor:
    """``log(R_t^T R_{t+1})`` for ``R`` ``(T, ..., 3, 3)`` -> ``(T-1, ..., 3)`` (radians)."""
    return matrix_to_axis_angle(R[:-1].transpose(-1, -2) @ R[1:])


def angular_velocity(R: torch.Tensor, fps: float, convention: str = "central") -> torch.Tensor:
    """Body-frame angular velocity from an orientation sequence.

    Args:
        R: ``(T, ..., 3, 3)`` ``R_WS`` (sensor -> world), time first, ``T >= 2``.
        fps: sample rate, Hz.
        convention: ``"central"`` or ``"forward"`` (module doc).

    Returns:
        ``(T, ..., 3)`` rad/s in the sensor frame.
    """
    if R.shape[-2:] != (3, 3) or R.dim() < 3:
        raise ShapeError(f"angular_velocity: R must be (T, ..., 3, 3), got {tuple(R.shape)}")
    if convention not in GYRO_CONVENTIONS:
        raise ShapeError(f"angular_velocity: convention must be one of {GYRO_CONVENTIONS}, got {convention!r}")
    T = R.shape[0]
    if T < 2:
        return torch.zeros(*R.shape[:-1], dtype=R.dtype, device=R.device)
    mid = _log_increments(R.to(torch.float64)) * float(fps)  # (T-1, ..., 3) at t + 1/2
    if convention == "forward":
        w = torch.cat([mid, mid[-1:]], dim=0)
    elif T == 2:
        w = torch.cat([mid, mid], dim=0)
    else:
        inner = 0.5 * (mid[:-1] + mid[1:])
        first = 1.5 * mid[0] - 0.5 * mid[1]
        last = 1.5 * mid[-1] - 0.5 * mid[-2]
        w = torch.cat([first[None], inner, last[None]], dim=0)
    return w.to(R.dtype)


def integrate_gyro(omega: torch.Tensor, R0: torch.Tensor, fps: float, convention: str = "central") -> torch.Tensor:
    """Strapdown integration of a body-frame gyro, the inverse of :func:`angular_velocity`.

    ``"central"``: ``R_{t+1} = R_t exp(dt m_{t+1/2})`` with the midpoint rate ``m`` recovered
    from the samples to fourth order (trapezoid plus a 4-point correction; non-causal by one
    sample, so this is an offline integrator);
    ``"forward"``: ``R_{t+1} = R_t exp(dt w_t)``.

    Args:
        omega: ``(T, ..., 3)`` rad/s, sensor frame.
        R0: ``(..., 3, 3)`` initial orientation ``R_WS(0)``.
        fps: Hz.

    Returns:
        ``(T, ..., 3, 3)`` orientations.
    """
    if convention not in GYRO_CONVENTIONS:
        raise ShapeError(f"integrate_gyro: convention must be one of {GYRO_CONVENTIONS}, got {convention!r}")
    w = omega.to(torch.float64)
    dt = 1.0 / float(fps)
    if convention == "central":
        # Recover the midpoint rate m_{t+1/2} (the exact log-increment / dt). The trapezoid
        # (w_t + w_{t+1}) / 2 equals m_{t+1/2} + (second difference of m) / 4; that error rotates
        # with the body and accumulates (2 deg over 10 s of fast arm motion), so it is removed
        # with the 4-point correction -(w_{t-1} - w_t - w_{t+1} + w_{t+2}) / 8, leaving a
        # fourth-difference residual (plain trapezoid at the first and last step).
        step = 0.5 * (w[:-1] + w[1:])
        if w.shape[0] >= 4:
            step[1:-1] = step[1:-1] - (w[:-3] - w[1:-2] - w[2:-1] + w[3:]) / 8.0
    else:
        step = w[:-1]
    incr = axis_angle_to_matrix(step * dt)  # (T-1, ..., 3, 3)
    out = [R0.to(torch.float64)]
    for k in range(incr.shape[0]):
        out.append(out[-1] @ incr[k])
    return torch.stack(out, dim=0).to(omega.dtype)


def specific_force(R: torch.Tensor, a_free: torch.Tensor) -> torch.Tensor:
    """Accelerometer reading ``f_S = R_WS^T (a_W - g)`` ``(..., 3)`` from free acceleration ``a_W``."""
    g = _gravity(a_free.dtype, a_free.device)
    return (R.transpose(-1, -2) @ (a_free - g).unsqueeze(-1)).squeeze(-1)


def free_acceleration(R: torch.Tensor, f: torch.Tensor) -> torch.Tensor:
    """Free acceleration ``a_W = R_WS f_S + g`` ``(..., 3)`` from a specific force reading."""
    g = _gravity(f.dtype, f.device)
    return (R @ f.unsqueeze(-1)).squeeze(-1) + g


@dataclass(frozen=True)
class ImuNoise:
    """IMU error model (per axis, sensor frame). Defaults: typical MEMS (Xsens-MTw class).

    Attributes:
        gyro_white: gyro noise density, rad/s/sqrt(Hz) (0.01 deg/s/sqrt(Hz)).
        gyro_bias: std of the constant turn-on gyro bias, rad/s (0.2 deg/s).
        gyro_bias_walk: gyro bias random walk, rad/s/sqrt(s).
        acc_white: accelerometer noise density, m/s^2/sqrt(Hz) (~150 ug/sqrt(Hz)).
        acc_bias: std of the constant accelerometer bias, m/s^2.
        acc_bias_walk: accelerometer bias random walk, m/s^2/sqrt(s).
        orientation_white: std per axis of white orientation noise, rad (0.5 deg) -- the
            device's own fusion error; drift and magnetic errors are the MIMU simulator's.
    """

    gyro_white: float = math.radians(0.01)
    gyro_bias: float = math.radians(0.2)
    gyro_bias_walk: float = 1e-4
    acc_white: float = 1.5e-3
    acc_bias: float = 0.05
    acc_bias_walk: float = 1e-4
    orientation_white: float = math.radians(0.5)

    @staticmethod
    def none() -> ImuNoise:
        """All terms zero (ideal sensor)."""
        return ImuNoise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def scaled(self, k: float) -> ImuNoise:
        """Every term multiplied by ``k``."""
        return replace(self, **{f: getattr(self, f) * k for f in self.__dataclass_fields__})

    @staticmethod
    def ximu3() -> ImuNoise:
        """Fitted to the real x-IMU3 lower-body log's two foot sensors standing still on the floor
        (first 1.0 s, 49 samples each; :func:`fit_static_noise`, re-fitted by the tests from
        ../shared/real-sensors): gyro 0.022 deg/s/sqrt(Hz) and 0.026 deg/s bias (defaults 0.01
        and 0.2), accelerometer 204 ug/sqrt(Hz) and 0.016 m/s^2 (defaults 153 and 0.05). The
        AHRS orientation is steadier still (0.03 deg) than the default's 0.5 deg assumes in
        motion: that term keeps the default. Bias walks are not observable in 1 s: defaults."""
        d = ImuNoise()
        return ImuNoise(gyro_white=XIMU3_FIT["gyro_white"], gyro_bias=XIMU3_FIT["gyro_bias"],
                        gyro_bias_walk=d.gyro_bias_walk, acc_white=XIMU3_FIT["acc_white"],
                        acc_bias=XIMU3_FIT["acc_bias"], acc_bias_walk=d.acc_bias_walk,
                        orientation_white=d.orientation_white)


#: ``fit_static_noise`` of the x-IMU3 log's feet (rad/s/sqrt(Hz), rad/s, m/s^2/sqrt(Hz), m/s^2,
#: rad); ``tests/sensors/test_noise_fit.py`` checks these against a fresh fit of the real files.
XIMU3_FIT: dict[str, float] = {"gyro_white": 3.85e-4, "gyro_bias": 4.56e-4, "acc_white": 2.00e-3, "acc_bias": 1.65e-2,
                               "orientation_white": 5.17e-4}


def fit_static_noise(sensors: list[tuple[np.ndarray, np.ndarray, np.ndarray]], fps: float) -> dict[str, float]:
    """White noise and bias of IMUs held still, in :class:`ImuNoise`'s terms.

    Args:
        sensors: per sensor ``(gyro (N, 3) rad/s, acc (N, 3) m/s^2, orientation (N, 3, 3))``
            over a still stretch: sensor-frame angular velocity and specific force (gravity
            included), ``R_WS``; valid samples only.
        fps: Hz.

    Returns:
        ``gyro_white`` (per-axis std / sqrt(fps)), ``gyro_bias`` (RMS of the per-axis means: the
        true rate is 0), ``acc_white``, ``acc_bias`` (RMS of ``|mean f| - 9.81``: only the part
        along gravity is observable still), ``orientation_white`` (RMS angle from the mean
        orientation / sqrt(3): per axis, rad), ``samples`` (the fewest of any sensor).
    """
    # start-up: scipy.spatial.transform adds ~290 ms to import wearpose.sensors
    from scipy.spatial.transform import Rotation

    if not sensors or min(len(g) for g, _, _ in sensors) < 3:
        raise ShapeError("fit_static_noise: expected at least 3 still samples of at least one sensor")
    gw, gb, aw, ab, ow = [], [], [], [], []
    for g, a, R in sensors:
        gw.append(g.std(0, ddof=1))
        gb.append(g.mean(0))
        aw.append(a.std(0, ddof=1))
        ab.append(np.linalg.norm(a.mean(0)) - float(np.linalg.norm(GRAVITY)))
        rots = Rotation.from_matrix(R)
        ow.append((rots.mean().inv() * rots).magnitude())
    rms = lambda x: float(np.sqrt(np.mean(np.square(np.concatenate([np.ravel(v) for v in x])))))  # noqa: E731
    return {"gyro_white": rms(gw) / math.sqrt(fps), "gyro_bias": rms(gb), "acc_white": rms(aw) / math.sqrt(fps),
            "acc_bias": rms(ab), "orientation_white": rms(ow) / math.sqrt(3.0),
            "samples": int(min(len(g) for g, _, _ in sensors))}


def _randn(shape: tuple[int, ...], g: torch.Generator | None, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    return torch.randn(shape, generator=g, dtype=dtype)


def bias_process(T: int, shape: tuple[int, ...], fps: float, bias: float, walk: float, white: float,
                 generator: torch.Generator | None) -> torch.Tensor:
    """Additive sensor error ``(T, *shape)``: constant bias + bias random walk + white noise.

    Args:
        T: samples; shape: trailing shape (e.g. ``(K, 3)``); fps: Hz.
        bias: std of the constant bias; walk: random-walk density (units/sqrt(s));
        white: white-noise density (units*sqrt(s)), per-sample std ``white * sqrt(fps)``.
    """
    out = torch.zeros((T, *shape), dtype=torch.float64)
    if bias > 0:
        out += bias * _randn(shape, generator)
    if walk > 0 and T > 1:
        steps = walk * math.sqrt(1.0 / fps) * _randn((T - 1, *shape), generator)
        out[1:] += torch.cumsum(steps, dim=0)
    if white > 0:
        out += white * math.sqrt(fps) * _randn((T, *shape), generator)
    return out


def simulate_imu(R: torch.Tensor, p: torch.Tensor, fps: float, *, noise: ImuNoise | None = None,
                 smooth_n: int = 4, ends: str = "one_sided", gyro_convention: str = "central",
                 generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
    """Simulate IMUs at sites with orientation ``R`` and position ``p``.

    Args:
        R: ``(T, K, 3, 3)`` site orientation ``R_WS`` (or ``(T, 3, 3)`` for one sensor).
        p: ``(T, K, 3)`` site position, m, world (or ``(T, 3)``).
        fps: Hz.
        noise: :class:`ImuNoise` (``None`` = ideal).
        smooth_n, ends: acceleration synthesis (:func:`synthetic_acceleration`).
        gyro_convention: :func:`angular_velocity`.
        generator: random source for the noise.

    Returns:
        dict with ``orientation`` ``(T, K, 3, 3)``, ``acceleration`` ``(T, K, 3)`` (free, world,
        m/s^2), ``angular_velocity`` ``(T, K, 3)`` (sensor frame, rad/s), ``specific_force``
        ``(T, K, 3)`` (sensor frame, gravity included, m/s^2), ``valid`` ``(T,)`` bool.
    """
    if R.shape[:-2] != p.shape[:-1]:
        raise ShapeError(f"simulate_imu: R {tuple(R.shape)} and p {tuple(p.shape)} disagree")
    dtype = R.dtype
    R64, p64 = R.to(torch.float64), p.to(torch.float64)
    a, valid = synthetic_acceleration(p64, fps, smooth_n, ends)
    w = angular_velocity(R64, fps, gyro_convention)
    f = specific_force(R64, a)
    R_meas = R64
    if noise is not None:
        T, shape = R.shape[0], tuple(R.shape[1:-2])
        w = w + bias_process(T, (*shape, 3), fps, noise.gyro_bias, noise.gyro_bias_walk, noise.gyro_white, generator)
        f = f + bias_process(T, (*shape, 3), fps, noise.acc_bias, noise.acc_bias_walk, noise.acc_white, generator)
        if noise.orientation_white > 0:
            R_meas = R64 @ axis_angle_to_matrix(noise.orientation_white * _randn((T, *shape, 3), generator))
    a_out = free_acceleration(R_meas, f)
    if not bool(valid.all()):
        a_out[~valid] = 0
    return {"orientation": R_meas.to(dtype), "acceleration": a_out.to(dtype), "angular_velocity": w.to(dtype),
            "specific_force": f.to(dtype), "valid": valid}
