"""Metal interference mitigation (MIM, MI-Poser Sec. 3.2-3.3): detection and correction, online.

**Detection** (Sec. 3.2). Without interference the EM rotation a little later is predicted by
the gyro, ``Phi_EM(t + dt) ~ Phi_EM(t) + dPhi_IMU(t) dt``; the geodesic distance between the
measured and the predicted rotation is compared with a threshold ``e_th`` and the frame is
flagged ``I(t + dt) = 1`` above it. We take ``dt = span_frames`` frames (6 = 50 ms): a one-frame
test at 120 Hz only sees interference that changes faster than the threshold per 8 ms. The
gyro step uses the trapezoid of the previous and current samples.

Once flagged, the reference is a gyro chain started at the **anchor**: the trusted rotation
``anchor_frames`` frames before the detecting frame (the paper's "``Phi_EM(t)`` ... when there is
no interference"). Interference grows over several frames before it crosses the threshold, so
the previous frame is already distorted; a chain started there makes EM and chain agree one frame
later (the flag flickers) and bakes the distortion into the correction. The stretch stays flagged
until EM and chain agree within ``release_ratio * e_th`` (hysteresis). Optionally
(``pos_threshold_cm``) a position-consistency test also flags a frame: the EM position against
the accelerometer's prediction from the trusted filter state ``span_frames`` earlier. The
interference *level* is the larger normalised discrepancy, low-pass filtered (``level_tau_s``).

**Correction** (Sec. 3.3), only for short interference ("we apply this correction as long as
the detected interference is of short duration to avoid drift error"): up to
``max_correction_s`` (default 0.5 s, the N-BEATS horizon) of consecutive flagged frames.
Longer, the output falls back to the raw EM pose and ``degraded`` is raised ("informing users of
the reasons for degraded body tracking", Sec. 3.1); the frames stay degraded while a long gyro
chain and the EM rotation disagree by more than ``release_deg``, or until ``reanchor_s`` passes
(then the chain is re-anchored on EM, bounding its drift).

- rotation: the gyro chain from the anchor replaces the EM rotation;
- position, one of ``MIMConfig.position``:
  ``"none"`` (EM as measured), ``"hold"`` (last output position),
  ``"odometry"`` (Eq. 1: double integration of the IMU acceleration from the trusted EM position
  at the anchor with the velocity differenced over trusted EM positions),
  ``"nbeats"`` (Eq. 2: the N-BEATS forecast made from the 120 positions up to the anchor),
  ``"fusion-eq3"`` (Eq. 3 read literally: each frame the one-step N-BEATS forecast plus the
  double integral of the acceleration over that step, fed back as input for the next frame),
  ``"fusion"`` (our reading of Eq. 3's intent, ``docs/interference.md``: a [position, velocity]
  Kalman filter driven by the accelerometer and updated by trusted EM positions, restarted at a
  detection from its state ``position_anchor_frames`` back and propagated by the accelerometer,
  with the N-BEATS forecast as a pseudo-measurement whose std grows with the horizon).

All inputs are in the EM source frame: ``R_em`` sensor -> source, ``p_em`` m, ``gyro`` rad/s in
the sensor frame (angular velocity relative to the source), ``acc`` m/s^2 in the source frame
(relative linear acceleration, gravity removed).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import math

import numpy as np

from wearpose.errors import ConfigError, ShapeError
from wearpose.interference._so3 import angle_between, exp_so3
from wearpose.interference.nbeats import NumpyNBeats, load_forecaster
from wearpose.weights import weight_path

POSITION_METHODS = ("none", "hold", "odometry", "nbeats", "fusion", "fusion-eq3")


@dataclass(frozen=True)
class MIMConfig:
    """MIM settings (module doc).

    Attributes:
        threshold_deg: detection threshold ``e_th`` on the EM-vs-gyro rotation discrepancy, degrees.
        span_frames: ``Delta t`` of the test in frames: the reference is the trusted (or
            gyro-chained) rotation ``span_frames`` frames ago, carried forward by the gyro.
        release_ratio: hysteresis: a flagged stretch ends when the discrepancies against the
            gyro chain / the inertial prediction fall below ``release_ratio`` times the thresholds.
        pos_threshold_cm: position-consistency test (our addition, 0 = off = the paper's
            detector): EM position vs the position predicted from the trusted state
            ``span_frames`` frames ago by the accelerometer, cm.
        anchor_frames: the correction restarts from the trusted state this many frames before
            the detecting frame (1 = the previous frame): interference grows over a few frames
            before it crosses the threshold, so the last frames before a detection are already
            distorted.
        position_anchor_frames: the same for the position state (0 = ``anchor_frames``): a
            shorter look-back suits the position, whose inertial prediction drifts faster.
        max_correction_s: longest interference corrected, s (longer = degraded).
        rotation: correct rotation by gyro integration.
        position: position method, one of :data:`POSITION_METHODS`.
        forecaster: shipped weights name or checkpoint path of the N-BEATS forecaster
            (``"nbeats"``/``"fusion"``/``"fusion-eq3"``).
        velocity_frames: frames of trusted EM positions the odometry's initial velocity is
            differenced over (Eq. 1).
        level_tau_s: time constant of the interference level's low-pass, s.
        max_speed: corrected positions move at most this fast, m/s (hand speeds stay below).
        release_deg: a degraded stretch ends when EM is back within this angle of the gyro chain.
        reanchor_s: longest gyro chain kept while degraded, s (bounds its drift).
        em_sigma_m: std of a trusted EM position in the Kalman filter of ``"fusion"`` and of the
            position test, m.
        acc_sigma: std of the accelerometer error (white, per sample) in that filter, m/s^2.
        forecast_sigma_m: ``(first sample, horizon)`` std of the N-BEATS forecast as a
            pseudo-measurement in ``"fusion"``, m; grows quadratically in between.
    """

    threshold_deg: float = 5.0
    span_frames: int = 6
    release_ratio: float = 1.0
    pos_threshold_cm: float = 0.0
    anchor_frames: int = 36
    position_anchor_frames: int = 12
    max_correction_s: float = 0.5
    rotation: bool = True
    position: str = "fusion"
    forecaster: str = "nbeats_cpu"
    velocity_frames: int = 3
    level_tau_s: float = 0.1
    release_deg: float = 2.0
    max_speed: float = 6.0
    reanchor_s: float = 10.0
    em_sigma_m: float = 0.01
    acc_sigma: float = 0.1
    forecast_sigma_m: tuple[float, float] = (0.005, 0.12)

    def __post_init__(self) -> None:
        if self.position not in POSITION_METHODS:
            raise ConfigError(f"MIMConfig.position: {self.position!r} is not one of {POSITION_METHODS}")
        if self.threshold_deg <= 0 or self.max_correction_s < 0:
            raise ConfigError(f"MIMConfig: threshold_deg must be > 0 and max_correction_s >= 0, got "
                              f"{self.threshold_deg}, {self.max_correction_s}")
        if self.anchor_frames < 1 or self.position_anchor_frames < 0 or self.span_frames < 1 or self.pos_threshold_cm < 0 or not 0 < self.release_ratio <= 1:
            raise ConfigError(f"MIMConfig: anchor_frames >= 1, span_frames >= 1, pos_threshold_cm >= 0 and "
                              f"0 < release_ratio <= 1 expected, got {self.anchor_frames}, {self.span_frames}, "
                              f"{self.pos_threshold_cm}, {self.release_ratio}")


def load_numpy_forecaster(name_or_path: str | Path):
    """A :class:`~wearpose.interference.nbeats.NumpyNBeats` from shipped weights or a checkpoint path."""
    p = Path(name_or_path)
    if not p.suffix:
        p = weight_path(str(name_or_path))
    model, _ = load_forecaster(p)
    return NumpyNBeats(model)


_FORECASTERS: dict[str, Any] = {}


class _Kalman:
    """Constant-acceleration-input Kalman filter of one 3-D point: state ``x``, ``v`` (3,) and a
    symmetric 2 x 2 covariance shared by the three axes (same noise on each), kept as the three
    Python floats ``p00``, ``p01``, ``p11`` (a per-frame 2 x 2 numpy array cost more than its
    arithmetic; the same IEEE operations, so the same numbers). The accelerometer drives the
    prediction; trusted EM positions (and, in ``"fusion"``, N-BEATS forecasts) are measurements."""

    __slots__ = ("x", "v", "p00", "p01", "p11")

    def __init__(self, x: np.ndarray, v: np.ndarray, p00: float = 0.0, p01: float = 0.0, p11: float = 0.0):
        self.x, self.v = x, v
        self.p00, self.p01, self.p11 = float(p00), float(p01), float(p11)

    def copy(self) -> "_Kalman":
        return _Kalman(self.x.copy(), self.v.copy(), self.p00, self.p01, self.p11)

    def predict(self, a: np.ndarray, dt: float, q: float) -> None:
        self.x = self.x + self.v * dt + 0.5 * a * dt * dt
        self.v = self.v + a * dt
        p00, p01, p11 = self.p00, self.p01, self.p11
        self.p00 = p00 + 2 * dt * p01 + dt * dt * p11 + q * 0.25 * dt ** 4
        self.p01 = p01 + dt * p11 + q * 0.5 * dt ** 3
        self.p11 = p11 + q * dt * dt

    def update(self, z: np.ndarray, r: float) -> None:
        p00, p01, p11 = self.p00, self.p01, self.p11
        S = p00 + r
        k0, k1 = p00 / S, p01 / S
        e = z - self.x
        self.x = self.x + k0 * e
        self.v = self.v + k1 * e
        self.p00, self.p01, self.p11 = p00 - k0 * p00, p01 - k0 * p01, p11 - k1 * p01


class MIM:
    """Online MIM for one EM sensor (module doc): ``reset()``, then ``step(...)`` per frame."""

    def __init__(self, config: MIMConfig | None = None, forecaster: Any = None):
        self.config = config or MIMConfig()
        self._forecaster = forecaster
        if forecaster is None and self.config.position in ("nbeats", "fusion", "fusion-eq3"):
            key = str(self.config.forecaster)
            if key not in _FORECASTERS:
                _FORECASTERS[key] = load_numpy_forecaster(key)
            self._forecaster = _FORECASTERS[key]
        self.reset()

    @property
    def input_len(self) -> int:
        return int(self._forecaster.cfg.input_len) if self._forecaster is not None else 120

    def reset(self) -> None:
        """Forget all state (start of a recording)."""
        cfg = self.config
        self._B = max(cfg.span_frames, cfg.anchor_frames, cfg.velocity_frames + 1) + 2
        self._buf: deque = deque(maxlen=self._B)  # per frame: (R_ref, dR, kf, acc, p_em, trusted)
        self._hist: deque = deque(maxlen=self.input_len + self._B)  # output positions (trusted or corrected)
        self._gyro_prev: np.ndarray | None = None
        self._flag = False
        self._run = 0
        self._level = 0.0
        self._p_out: np.ndarray | None = None
        self._kf: _Kalman | None = None
        self._corr: _Kalman | None = None     # odometry / fusion state during a correction
        self._forecast: np.ndarray | None = None
        self._eq3_hist: list | None = None
        self._k = 0                            # samples since the anchor (forecast index)
        self._degraded = False
        self._R_long: np.ndarray | None = None
        self._t_degraded = 0.0
        # The trusted-position Kalman filter feeds only the position test and the "fusion"
        # correction; without them (the estimator's default: position "none", no position test)
        # it is not run at all (its state never reaches an output).
        self._use_kf = cfg.pos_threshold_cm > 0 or cfg.position == "fusion"
        self._th = float(np.radians(cfg.threshold_deg))
        self._release = float(np.radians(cfg.release_deg))
        self._blend: tuple[float, float] | None = None  # (dt, level low-pass factor) for the last dt

    # ----------------------------------------------------------------- position correction
    def _sigma_f(self, k: int) -> float:
        s0, s1 = self.config.forecast_sigma_m
        n = float(self._forecaster.cfg.output_len) if self._forecaster is not None else 60.0
        return s0 + (s1 - s0) * min(k / n, 1.0) ** 2

    def _history_until(self, back: int) -> np.ndarray | None:
        """Output positions up to ``back`` frames before the newest one (``input_len`` of them)."""
        h = list(self._hist)
        n = self.input_len
        end = len(h) - back
        if end < n:
            return None
        return np.asarray(h[end - n:end])

    def _start_correction(self, L: int, acc: np.ndarray, dt: float) -> None:
        """Onset: restart the position state from the anchor frame ``t - L`` and catch up to ``t``."""
        cfg = self.config
        buf = list(self._buf)
        anchor = buf[-L]
        accs = [b[3] for b in buf[-L + 1:]] + [acc] if L > 1 else [acc]
        m = cfg.position
        self._forecast = None
        self._k = 0
        q = cfg.acc_sigma ** 2
        if m in ("nbeats", "fusion", "fusion-eq3") and self._forecaster is not None:
            hist = self._history_until(L - 1)
            if hist is not None:
                self._forecast = self._forecaster(hist)
        if m == "odometry":
            # Eq. 1: trusted EM position at the anchor, velocity differenced over trusted EM positions
            ps = [b[4] for b in buf[:len(buf) - L + 1]][-(cfg.velocity_frames + 1):]
            v = (ps[-1] - ps[0]) / ((len(ps) - 1) * dt) if len(ps) > 1 else np.zeros(3)
            self._corr = _Kalman(anchor[4].copy(), v)
            for a in accs:
                self._corr.predict(a, dt, 0.0)
        elif m == "fusion":
            self._corr = anchor[2].copy()
            for a in accs:
                self._corr.predict(a, dt, q)
                self._k += 1
                self._pseudo()
        elif m == "fusion-eq3":
            if self._forecast is not None:
                h = list(self._history_until(L - 1))
                x = None
                for a in accs:
                    x = self._forecaster(np.asarray(h[-self.input_len:]))[0] + 0.5 * a * dt * dt
                    h.append(x)
                self._corr = _Kalman(x, np.zeros(3))
                self._eq3_hist = h
            else:
                self._corr = None
        self._k = len(accs)

    def _pseudo(self) -> None:
        """N-BEATS forecast of the current sample as a measurement (``"fusion"``)."""
        f = self._forecast
        if f is not None and 1 <= self._k <= f.shape[0]:
            self._corr.update(f[self._k - 1], self._sigma_f(self._k) ** 2)

    def _position(self, p_em: np.ndarray, acc: np.ndarray, dt: float, onset: bool) -> np.ndarray:
        m = self.config.position
        last = self._p_out if self._p_out is not None else p_em
        if m == "none":
            return p_em
        if m == "hold":
            return last
        if m == "nbeats":
            if onset:
                self._k -= 1  # the onset frame is sample k of the forecast
            self._k += 1
            if self._forecast is None:
                return last
            return self._forecast[min(self._k, self._forecast.shape[0]) - 1]
        if self._corr is None:
            return last
        if not onset:
            if m == "fusion-eq3":
                h = self._eq3_hist
                x = self._forecaster(np.asarray(h[-self.input_len:]))[0] + 0.5 * acc * dt * dt
                h.append(x)
                if len(h) > 2 * self.input_len:
                    del h[:-self.input_len]
                self._corr.x = x
            else:
                self._corr.predict(acc, dt, 0.0 if m == "odometry" else self.config.acc_sigma ** 2)
                self._k += 1
                if m == "fusion":
                    self._pseudo()
        return self._corr.x.copy()

    # ----------------------------------------------------------------- detection + state machine
    def step(self, R_em: Any, p_em: Any, gyro: Any, acc: Any, dt: float) -> dict[str, Any]:
        """One frame.

        Args:
            R_em: ``(3, 3)`` EM rotation (sensor -> source); p_em: ``(3,)`` m; gyro: ``(3,)`` rad/s
            (sensor frame); acc: ``(3,)`` m/s^2 (source frame); dt: s since the previous frame.

        Returns:
            dict: ``R`` (3, 3) and ``p`` (3,) corrected; ``interfered`` bool (the frame-level
            detection of Sec. 3.2; False while ``degraded``, which reports persistent interference);
            ``corrected`` bool (the output was corrected this frame); ``level`` float
            (discrepancy / threshold, low-passed); ``degraded`` bool; ``discrepancy`` rad (rotation).
        """
        R_em = np.asarray(R_em, dtype=np.float64)
        p_em = np.asarray(p_em, dtype=np.float64)
        gyro = np.asarray(gyro, dtype=np.float64)
        acc = np.asarray(acc, dtype=np.float64)
        if R_em.shape != (3, 3) or p_em.shape != (3,) or gyro.shape != (3,) or acc.shape != (3,):
            raise ShapeError(f"MIM.step: expected R (3, 3), p (3,), gyro (3,), acc (3,), got {R_em.shape}, "
                             f"{p_em.shape}, {gyro.shape}, {acc.shape}")
        cfg = self.config
        r_em = cfg.em_sigma_m ** 2
        q = cfg.acc_sigma ** 2
        use_kf = self._use_kf
        if self._gyro_prev is None:
            self._gyro_prev, self._p_out = gyro.copy(), p_em.copy()
            self._kf = _Kalman(p_em.copy(), np.zeros(3), r_em, 0.0, 1.0) if use_kf else None
            kf = self._kf.copy() if use_kf else None
            self._buf.append((R_em.copy(), np.eye(3), kf, acc.copy(), p_em.copy(), True))
            self._hist.append(p_em.copy())
            return {"R": R_em, "p": p_em, "interfered": False, "corrected": False, "level": 0.0,
                    "degraded": False, "discrepancy": 0.0}
        w = 0.5 * (self._gyro_prev + gyro)
        self._gyro_prev = gyro.copy()
        dR = exp_so3(w * dt)
        th = self._th
        pth = cfg.pos_threshold_cm / 100.0
        R_prev = self._buf[-1][0]
        if use_kf:
            self._kf.predict(acc, dt, q)
        corrected = False
        interfered = False
        trusted = False
        R_out, p_out = R_em, p_em
        R_ref = R_prev @ dR
        score = 0.0
        if self._degraded:
            # persistent interference: follow the long gyro chain until EM agrees with it again
            self._R_long = self._R_long @ dR
            self._t_degraded += dt
            d = angle_between(self._R_long, R_em)
            score = d / th
            if d < self._release or self._t_degraded > cfg.reanchor_s:
                self._degraded = False
                self._flag = False
                R_ref = R_em
                trusted = True
                if use_kf:
                    self._kf = _Kalman(p_em.copy(), np.zeros(3), r_em, 0.0, 1.0)
        elif self._flag:
            d = angle_between(R_ref, R_em)
            dp = float(np.linalg.norm(p_em - self._kf.x)) if pth > 0 else 0.0
            score = max(d / th, dp / pth if pth > 0 else 0.0)
            if d > cfg.release_ratio * th or (pth > 0 and dp > cfg.release_ratio * pth + 3.0 * math.sqrt(self._kf.p00)):
                interfered = True
            else:
                self._flag = False
                R_ref = R_em
                trusted = True
        else:
            k = min(cfg.span_frames, len(self._buf))
            buf = self._buf
            R_span = buf[-k][0]
            for j in range(len(buf) - k + 1, len(buf)):
                R_span = R_span @ buf[j][1]
            R_span = R_span @ dR
            d = angle_between(R_span, R_em)
            dp = 0.0
            if pth > 0:  # the position test: the trusted state span_frames ago, carried by the accelerometer
                kf = buf[-k][2].copy()
                for j in range(len(buf) - k + 1, len(buf)):
                    kf.predict(buf[j][3], dt, 0.0)
                kf.predict(acc, dt, 0.0)
                dp = float(np.linalg.norm(p_em - kf.x))
            score = max(d / th, dp / pth if pth > 0 else 0.0)
            if d > th or (pth > 0 and dp > pth):
                interfered = True
                self._flag = True
                self._run = 0
                # restart from the anchor frame: its reference rotation chained by the gyro since
                L = min(cfg.anchor_frames, len(self._buf))
                R_a = self._buf[-L][0]
                for j in range(len(self._buf) - L + 1, len(self._buf)):
                    R_a = R_a @ self._buf[j][1]
                R_ref = R_a @ dR
                L = min(cfg.position_anchor_frames or cfg.anchor_frames, len(self._buf))
                if use_kf:
                    self._kf = self._buf[-L][2].copy()
                    for j in range(len(self._buf) - L + 1, len(self._buf)):
                        self._kf.predict(self._buf[j][3], dt, q)
                    self._kf.predict(acc, dt, q)
                if cfg.position not in ("none", "hold"):
                    self._start_correction(L, acc, dt)
            else:
                R_ref = R_em
                trusted = True
        if interfered:
            self._run += 1
            if self._run * dt <= cfg.max_correction_s:
                corrected = True
                R_out = R_ref if cfg.rotation else R_em
                p_out = self._position(p_em, acc, dt, onset=self._run == 1)
                if cfg.position != "none" and self._p_out is not None:
                    # a hand moves at most max_speed: bounds a forecaster fed a distorted history
                    step = p_out - self._p_out
                    n = float(np.linalg.norm(step))
                    if n > cfg.max_speed * dt:
                        p_out = self._p_out + step * (cfg.max_speed * dt / n)
            else:  # too long for a correction: notify instead, watch for its end
                self._degraded = True
                self._flag = False
                interfered = False
                self._R_long = R_ref
                self._t_degraded = 0.0
        if trusted and use_kf:
            self._kf.update(p_em, r_em)
        if self._blend is None or self._blend[0] != dt:
            self._blend = (dt, float(1.0 - np.exp(-dt / max(cfg.level_tau_s, 1e-9))))
        self._level += self._blend[1] * (score - self._level)
        self._p_out = p_out
        self._buf.append((R_ref, dR, self._kf.copy() if use_kf else None, acc.copy(), p_em.copy(), trusted))
        self._hist.append(np.array(p_out, dtype=np.float64))
        return {"R": R_out, "p": p_out, "interfered": bool(interfered), "corrected": corrected,
                "level": float(self._level), "degraded": bool(self._degraded), "discrepancy": float(d)}

    def process(self, R: Any, p: Any, gyro: Any, acc: Any, fps: float) -> dict[str, np.ndarray]:
        """Offline convenience: run :meth:`step` over a sequence (resets first).

        Args:
            R: ``(T, 3, 3)``; p, gyro, acc: ``(T, 3)``; fps: Hz.

        Returns:
            dict of stacked arrays: ``R`` (T, 3, 3), ``p`` (T, 3), ``interfered``, ``corrected``,
            ``degraded`` (T,) bool, ``level``, ``discrepancy`` (T,) float.
        """
        R, p, gyro, acc = (np.asarray(x, dtype=np.float64) for x in (R, p, gyro, acc))
        T = R.shape[0]
        if R.shape != (T, 3, 3) or p.shape != (T, 3) or gyro.shape != (T, 3) or acc.shape != (T, 3):
            raise ShapeError(f"MIM.process: expected R (T, 3, 3), p/gyro/acc (T, 3), got {R.shape}, {p.shape}, "
                             f"{gyro.shape}, {acc.shape}")
        self.reset()
        dt = 1.0 / float(fps)
        out = {"R": np.empty((T, 3, 3)), "p": np.empty((T, 3)), "interfered": np.zeros(T, bool),
               "corrected": np.zeros(T, bool), "degraded": np.zeros(T, bool), "level": np.zeros(T),
               "discrepancy": np.zeros(T)}
        for t in range(T):
            o = self.step(R[t], p[t], gyro[t], acc[t], dt)
            for k in out:
                out[k][t] = o[k]
        return out


def detect(R: np.ndarray, gyro: np.ndarray, fps: float, threshold_deg: float,
           max_correction_s: float = 0.5, p: np.ndarray | None = None, acc: np.ndarray | None = None,
           **config: Any) -> tuple[np.ndarray, np.ndarray]:
    """Detection only (no correction) over a sequence: ``(detected (T,) bool, discrepancy (T,) rad)``.

    ``detected`` = interfered or degraded (persistent interference is detected interference too).
    The same state machine as :meth:`MIM.step` (gyro chain from the anchor), for threshold sweeps.
    ``p``/``acc`` (T, 3) are needed by the position test (``pos_threshold_cm > 0`` in ``config``,
    further :class:`MIMConfig` fields).
    """
    mim = MIM(MIMConfig(threshold_deg=threshold_deg, position="none", max_correction_s=max_correction_s, **config))
    T = R.shape[0]
    P = np.zeros((T, 3)) if p is None else np.asarray(p, dtype=np.float64)
    A = np.zeros((T, 3)) if acc is None else np.asarray(acc, dtype=np.float64)
    flags, disc = np.zeros(T, bool), np.zeros(T)
    dt = 1.0 / float(fps)
    for t in range(T):
        o = mim.step(R[t], P[t], gyro[t], A[t], dt)
        flags[t], disc[t] = o["interfered"] or o["degraded"], o["discrepancy"]
    return flags, disc
