"""EM 6-DoF simulator (EM-POSE virtual sensors, range-dependent noise, dropped frames).

**Virtual sensor** (EM-POSE, Kaufmann et al. ICCV 2021, Sec. 5.2). The skin site gives the
vertex position ``p~_s`` and the frame ``R~_s`` built from the vertex normal and a fixed edge
(Eq. 3; :meth:`wearpose.body.BodyModel.sites` returns exactly this frame, columns
``(tangent, bitangent, normal)``). Per-sensor offsets ``o_s = [R | t]`` give the sensor (Eq. 4)::

    R_s^v = R~_s R          (rotation offset applied in the site frame)
    p_s^v = p~_s + R~_s t   (translation offset expressed in the site frame)

A subject's offsets ``O_p = {o_s}`` are an :class:`EMOffsets`. Offset augmentation (EM-POSE
supp. Sec. 2.2): "for every sensor and every participant we fit a multi-variate normal
distribution to t(t) ... we first draw a vector t ~ phi(t) which we then use as the
translational offset". :class:`EMOffsets` carries that distribution (mean ``t``, covariance
``t_cov``) and :meth:`EMOffsets.draw` draws one translation per sensor per sequence; the
rotation offset stays the subject's mean rotation (the paper jitters translations only).

**Source frame** (DESIGN: EM canonical form). Measurements are the sensor pose relative to the
source: ``p = R_src^T (p_s^v - p_src)``, ``R = R_src^T R_s^v``; the source is a site frame (the
lower back = ``pelvis`` for EM-POSE, the head for MI-Poser), optionally with its own mount
offset.

**Noise** (:class:`EMNoise`) grows with the source distance ``d = |p|`` and with the sensor's
motion relative to the source. As medians of the 3-D error (per-axis std = median / 1.538, the
Maxwell median)::

    m_p = sqrt( (s_p (d / d_ref)^k_p (1 + (d_min / d)^4))^2 + (tau_v |v|)^2 )
    m_r = sqrt( (s_r (d / d_ref)^k_r (1 + (d_min / d)^4))^2 + (tau_w |w|)^2 )

The power laws: a dipole field falls as ``d^-3`` (EM-POSE Eq. 1), so a constant voltage noise
gives a position error growing like ``d^3``-``d^4``; we take ``k_p = 3``, ``k_r = 2``. The motion
term follows EM-POSE Sec. 6.1: "Sensors that are far away from the source (i.e. wrist, shin) or
undergo faster motion (i.e. arms) experience the highest errors. In contrast, static or slow
moving sensors (i.e. head, shoulders) show errors below 0.25 cm or 1 degree" (Fig. 6, median
vs. optical, jumping jacks); far/fast sensors are "around or lower than 1 cm ... and 2-3
degrees". Defaults ``s_p = 3 mm``, ``s_r = 1.2 deg`` at ``d_ref = 0.8 m``, ``tau_v = 4 ms``,
``tau_w = 7 ms`` give: head (0.72 m, 0.3 m/s, 1 rad/s) 2.5 mm / 1.0 deg; a wrist at 1.0 m moving
1.5 m/s and 5 rad/s 8.4 mm / 2.7 deg; static at 0.6 m 1.3 mm / 0.7 deg -- consistent with MI-Poser
Table 1 open space (mean 0.72 cm, 1.27 deg within 1.5 m). ``d_min = 0.1 m`` is MI-Poser's
minimum working distance (Sec. 5.2.1: closer signals saturate and jitter). Errors are temporally
correlated (first-order Gauss-Markov, time constant ``tau``; real trackers Kalman-filter their
output, MI-Poser Sec. 4.1). The functional forms and ``tau``, ``tau_v``, ``tau_w`` are our
assumptions fitted to those quoted magnitudes, not published parameters.

**Dropped frames** (EM-POSE Sec. 6.2, supp. Sec. 9: "the EM sensors sometimes drop frames").
Per sensor, bursts start as a Poisson process (rate ``dropout_rate`` per second) and last a
geometric number of frames (mean ``dropout_mean_frames``); dropped frames get ``valid=False``
and their values are NaN (never invented). Rates are our assumption (the paper gives none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from wearpose.errors import ShapeError
from wearpose.geometry import axis_angle_to_matrix
from wearpose.sensors.imu import angular_velocity

#: Median of |x| for x ~ N(0, sigma^2 I_3) is MAXWELL_MEDIAN * sigma.
MAXWELL_MEDIAN = 1.5382


@dataclass
class EMOffsets:
    """Subject offsets ``O_p``: one ``o_s = [R | t]`` per EM sensor (EM-POSE Eq. 4).

    Attributes:
        R: ``(S, 3, 3)`` rotation offsets (sensor frame -> site frame).
        t: ``(S, 3)`` translation offsets in the site frame, m (mean of ``phi(t)``).
        t_cov: ``(S, 3, 3)`` covariance of the translation offset over time (supp. 2.2), m^2;
            ``None`` = no per-sequence jitter.
    """

    R: torch.Tensor
    t: torch.Tensor
    t_cov: torch.Tensor | None = None

    def __post_init__(self) -> None:
        self.R = torch.as_tensor(self.R, dtype=torch.float64)
        self.t = torch.as_tensor(self.t, dtype=torch.float64)
        S = self.R.shape[0]
        if self.R.shape != (S, 3, 3) or self.t.shape != (S, 3):
            raise ShapeError(f"EMOffsets: expected R (S, 3, 3) and t (S, 3), got {tuple(self.R.shape)} and {tuple(self.t.shape)}")
        if self.t_cov is not None:
            self.t_cov = torch.as_tensor(self.t_cov, dtype=torch.float64)
            if self.t_cov.shape != (S, 3, 3):
                raise ShapeError(f"EMOffsets.t_cov: expected ({S}, 3, 3), got {tuple(self.t_cov.shape)}")

    @property
    def num_sensors(self) -> int:
        return int(self.R.shape[0])

    @staticmethod
    def identity(num_sensors: int) -> EMOffsets:
        """``R = I``, ``t = 0``: the virtual sensor is the skin frame itself (EM-POSE "no [R|t]")."""
        return EMOffsets(torch.eye(3, dtype=torch.float64).expand(num_sensors, 3, 3).clone(),
                         torch.zeros(num_sensors, 3, dtype=torch.float64))

    def draw(self, generator: torch.Generator | None = None) -> EMOffsets:
        """One per-sequence draw ``t ~ N(t, t_cov)`` per sensor (EM-POSE supp. Sec. 2.2)."""
        if self.t_cov is None:
            return EMOffsets(self.R.clone(), self.t.clone())
        L = torch.linalg.cholesky(self.t_cov + 1e-12 * torch.eye(3, dtype=torch.float64))
        z = torch.randn(self.num_sensors, 3, 1, generator=generator, dtype=torch.float64)
        return EMOffsets(self.R.clone(), self.t + (L @ z).squeeze(-1))


def random_subject_offsets(num_sensors: int, generator: torch.Generator | None = None, *,
                           tilt_sigma: float = math.radians(8.0), spin_sigma: float = math.radians(20.0),
                           standoff: float = 0.015, slide_sigma: float = 0.01, standoff_sigma: float = 0.005,
                           jitter_sigma: float = 0.005) -> EMOffsets:
    """A synthetic subject ``O_p`` when no calibrated offsets are available (our prior).

    Rotation: a spin about the skin normal (std ``spin_sigma``) times a small tilt of the
    normal (std ``tilt_sigma`` per tangent axis). Translation (site frame): the sensor centre
    sits ``standoff`` above the skin (+ std ``standoff_sigma``) and slides tangentially by
    ``slide_sigma``. Per-sequence jitter ``t_cov = jitter_sigma^2 I``. EM-POSE estimates real
    ``O_p`` from a calibration sequence (supp. Sec. 1); these priors are assumptions sized to
    a strap-mounted sensor.
    """
    g = generator
    S = num_sensors
    rn = lambda *s: torch.randn(*s, generator=g, dtype=torch.float64)  # noqa: E731
    spin = torch.zeros(S, 3, dtype=torch.float64)
    spin[:, 2] = spin_sigma * rn(S)
    tilt = torch.zeros(S, 3, dtype=torch.float64)
    tilt[:, :2] = tilt_sigma * rn(S, 2)
    R = axis_angle_to_matrix(tilt) @ axis_angle_to_matrix(spin)
    t = torch.cat([slide_sigma * rn(S, 2), (standoff + standoff_sigma * rn(S, 1))], dim=1)
    cov = (jitter_sigma ** 2) * torch.eye(3, dtype=torch.float64).expand(S, 3, 3).clone()
    return EMOffsets(R, t, cov)


def apply_offsets(site_R: torch.Tensor, site_p: torch.Tensor, offsets: EMOffsets) -> tuple[torch.Tensor, torch.Tensor]:
    """EM-POSE Eq. 4: ``R^v = R~ R_off``, ``p^v = p~ + R~ t_off``.

    Args:
        site_R: ``(T, S, 3, 3)`` site frames ``R~_s`` (site -> world).
        site_p: ``(T, S, 3)`` site vertex positions ``p~_s``, m.
        offsets: ``S`` offsets.

    Returns:
        ``(R^v (T, S, 3, 3), p^v (T, S, 3))`` in the world frame.
    """
    if site_R.shape[-3] != offsets.num_sensors:
        raise ShapeError(f"apply_offsets: {site_R.shape[-3]} sites but {offsets.num_sensors} offsets")
    Roff = offsets.R.to(site_R)
    toff = offsets.t.to(site_R)
    return site_R @ Roff, site_p + (site_R @ toff.unsqueeze(-1)).squeeze(-1)


def relative_to_source(R: torch.Tensor, p: torch.Tensor, src_R: torch.Tensor, src_p: torch.Tensor
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """Sensor poses in the source frame: ``R_src^T R``, ``R_src^T (p - p_src)``.

    Args:
        R: ``(T, S, 3, 3)``; p: ``(T, S, 3)``; src_R: ``(T, 3, 3)``; src_p: ``(T, 3)`` (world).
    """
    RsT = src_R.transpose(-1, -2).unsqueeze(-3)
    return RsT @ R, (RsT @ (p - src_p.unsqueeze(-2)).unsqueeze(-1)).squeeze(-1)


@dataclass(frozen=True)
class EMNoise:
    """Range-dependent EM error model and dropped-frame bursts (module doc for the sources).

    Attributes:
        position_median: median 3-D position error of a static sensor at ``d_ref``, m.
        orientation_median: median rotation error of a static sensor at ``d_ref``, rad.
        speed_time: motion term of the position error: ``speed_time * |v|`` (``v`` the
            sensor's velocity relative to the source, m/s), s -- a latency-like error.
        rate_time: motion term of the orientation error: ``rate_time * |w|`` (``w`` the
            angular rate relative to the source, rad/s), s.
        d_ref: reference source distance, m.
        k_position, k_orientation: power-law exponents of the growth with distance.
        d_min: minimum working distance (near-field saturation), m.
        tau: correlation time of the error (first-order Gauss-Markov), s; 0 = white.
        dropout_rate: dropped-frame bursts per second per sensor.
        dropout_mean_frames: mean burst length, frames (geometric).
    """

    position_median: float = 0.003
    orientation_median: float = math.radians(1.2)
    d_ref: float = 0.8
    k_position: float = 3.0
    k_orientation: float = 2.0
    d_min: float = 0.1
    tau: float = 0.05
    dropout_rate: float = 0.05
    dropout_mean_frames: float = 6.0
    speed_time: float = 0.004
    rate_time: float = 0.007

    @staticmethod
    def none() -> EMNoise:
        """No measurement noise, no dropped frames."""
        return EMNoise(position_median=0.0, orientation_median=0.0, dropout_rate=0.0)

    def sigmas(self, d: torch.Tensor, speed: torch.Tensor | None = None, rate: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-axis std ``(sigma_p [m], sigma_r [rad])``.

        Args:
            d: source distance, m (any shape).
            speed: ``|v|`` relative to the source, m/s (same shape; ``None`` = static).
            rate: ``|w|`` relative to the source, rad/s (same shape; ``None`` = static).
        """
        d = d.clamp_min(1e-3)
        near = 1.0 + (self.d_min / d) ** 4
        mp = self.position_median * (d / self.d_ref) ** self.k_position * near
        mr = self.orientation_median * (d / self.d_ref) ** self.k_orientation * near
        if speed is not None:
            mp = torch.sqrt(mp ** 2 + (self.speed_time * speed) ** 2)
        if rate is not None:
            mr = torch.sqrt(mr ** 2 + (self.rate_time * rate) ** 2)
        return mp / MAXWELL_MEDIAN, mr / MAXWELL_MEDIAN

    def scaled(self, k: float) -> EMNoise:
        return replace(self, position_median=self.position_median * k, orientation_median=self.orientation_median * k,
                       speed_time=self.speed_time * k, rate_time=self.rate_time * k)


def gauss_markov(T: int, shape: tuple[int, ...], fps: float, tau: float, generator: torch.Generator | None) -> torch.Tensor:
    """Unit-variance first-order Gauss-Markov sequence ``(T, *shape)`` (white if ``tau <= 0``)."""
    z = torch.randn((T, *shape), generator=generator, dtype=torch.float64)
    if tau <= 0 or T < 2:
        return z
    rho = math.exp(-1.0 / (fps * tau))
    s = math.sqrt(1 - rho * rho)
    # y_k = rho y_{k-1} + s z_k with y_0 = z_0 (stationary start), as one IIR filter call. Every
    # recording with body sites imports wearpose.sensors (the known sites) without simulating:
    from scipy.signal import lfilter  # start-up: scipy.signal adds ~0.9 s to import wearpose.sensors

    zn = z.numpy()
    y, _ = lfilter([s], [1.0, -rho], zn, axis=0, zi=((1.0 - s) * zn[:1]))
    return torch.from_numpy(y)


def dropout_mask(T: int, num_sensors: int, fps: float, rate: float, mean_frames: float,
                 generator: torch.Generator | None) -> torch.Tensor:
    """``(T, S)`` bool validity with Poisson-started, geometric-length dropped-frame bursts."""
    valid = torch.ones(T, num_sensors, dtype=torch.bool)
    if rate <= 0 or T == 0:
        return valid
    p_start = 1.0 - math.exp(-rate / fps)
    starts = torch.rand(T, num_sensors, generator=generator, dtype=torch.float64) < p_start
    q = 1.0 / max(mean_frames, 1.0)  # geometric with mean 1/q frames
    u = torch.rand(T, num_sensors, generator=generator, dtype=torch.float64).clamp_min(1e-12)
    lengths = torch.ceil(torch.log(u) / math.log(1 - q) if q < 1 else torch.ones_like(u)).clamp_min(1).long()
    for t, s in starts.nonzero().tolist():
        valid[t:t + int(lengths[t, s]), s] = False
    return valid


def simulate_em(site_R: torch.Tensor, site_p: torch.Tensor, source_R: torch.Tensor, source_p: torch.Tensor,
                fps: float, *, offsets: EMOffsets | None = None, noise: EMNoise | None = None,
                source_offset: EMOffsets | None = None, fill: str = "nan",
                generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
    """Simulate EM 6-DoF sensors relative to a body-worn source.

    Args:
        site_R: ``(T, S, 3, 3)`` site frames (EM-POSE Eq. 3), world.
        site_p: ``(T, S, 3)`` site positions, m, world.
        source_R: ``(T, 3, 3)`` source site frame, world; source_p: ``(T, 3)``.
        fps: Hz (for the noise correlation and dropout rates).
        offsets: sensor offsets ``O_p`` (already drawn for this sequence; ``None`` = identity).
        noise: :class:`EMNoise` (``None`` = ideal).
        source_offset: optional mount offset of the source on its site (one ``[R | t]``).
        fill: value of dropped frames: ``"nan"`` (default) or ``"zero"`` (position 0,
            orientation identity); either way ``valid`` is False there.
        generator: random source.

    Returns:
        dict: ``position`` ``(T, S, 3)`` m and ``orientation`` ``(T, S, 3, 3)`` in the source
        frame; ``valid`` ``(T, S)`` bool; ``distance`` ``(T, S)`` true source distance, m;
        ``world_position``/``world_orientation``: the noise-free virtual sensors (Eq. 4), world.
    """
    if site_R.dim() != 4 or site_p.shape != site_R.shape[:-1]:
        raise ShapeError(f"simulate_em: expected site_R (T, S, 3, 3) and site_p (T, S, 3), got {tuple(site_R.shape)}, {tuple(site_p.shape)}")
    dtype = site_R.dtype
    T, S = site_R.shape[:2]
    R64, p64 = site_R.to(torch.float64), site_p.to(torch.float64)
    sR, sp = source_R.to(torch.float64), source_p.to(torch.float64)
    if offsets is None:
        offsets = EMOffsets.identity(S)
    Rv, pv = apply_offsets(R64, p64, offsets)
    if source_offset is not None:
        sRv, spv = apply_offsets(sR[:, None], sp[:, None], source_offset)
        sR, sp = sRv[:, 0], spv[:, 0]
    Rrel, prel = relative_to_source(Rv, pv, sR, sp)
    d = prel.norm(dim=-1)
    valid = torch.ones(T, S, dtype=torch.bool)
    if noise is not None:
        speed = rate = None
        if T >= 2 and (noise.speed_time > 0 or noise.rate_time > 0):
            # relative velocity / angular rate of the noise-free measurement (central differences)
            speed = torch.gradient(prel, spacing=1.0 / fps, dim=0)[0].norm(dim=-1)
            rate = angular_velocity(Rrel, fps).norm(dim=-1)
        sig_p, sig_r = noise.sigmas(d, speed, rate)
        if noise.position_median > 0:
            prel = prel + sig_p.unsqueeze(-1) * gauss_markov(T, (S, 3), fps, noise.tau, generator)
        if noise.orientation_median > 0:
            rv = sig_r.unsqueeze(-1) * gauss_markov(T, (S, 3), fps, noise.tau, generator)
            Rrel = Rrel @ axis_angle_to_matrix(rv)
        valid = dropout_mask(T, S, fps, noise.dropout_rate, noise.dropout_mean_frames, generator)
    if not bool(valid.all()):
        bad = ~valid
        if fill == "nan":
            prel[bad] = float("nan")
            Rrel[bad] = float("nan")
        else:
            prel[bad] = 0.0
            Rrel[bad] = torch.eye(3, dtype=torch.float64)
    return {"position": prel.to(dtype), "orientation": Rrel.to(dtype), "valid": valid, "distance": d.to(dtype),
            "world_position": pv.to(dtype), "world_orientation": Rv.to(dtype)}
