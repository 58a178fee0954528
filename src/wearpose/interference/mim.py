"""Metal interference mitigation (MIM, MI-Poser Sec. 3.2-3.3): detection and correction, online.

**Detection** (Sec. 3.2). Without interference the EM rotation one frame later is predicted by
the gyro, ``Phi_EM(t + dt) ~ Phi_EM(t) + dPhi_IMU(t) dt``; the geodesic distance between the
measured and the predicted rotation is compared with a threshold ``e_th`` and the frame is
flagged ``I(t + dt) = 1`` above it. The prediction starts from the last *trusted* rotation: the
EM rotation while ``I = 0``, the gyro-propagated one while ``I = 1`` (the paper's
"``Phi_EM(t)`` ... when there is no interference"; propagating through a flagged stretch keeps
it flagged until EM and gyro agree again instead of re-trusting a distorted EM rotation after one
frame). The gyro step uses the trapezoid of the previous and current samples. The interference
*level* is the discrepancy over the threshold, low-pass filtered (time constant ``level_tau_s``).
The paper states the test for a generic ``dt``; we take ``dt = span_frames`` frames (6 = 50 ms by
default): a one-frame test at 120 Hz only sees interference that changes faster than the
threshold per 8 ms and misses a hand approaching metal slowly.

**Correction** (Sec. 3.3), only for short interference ("we apply this correction as long as
the detected interference is of short duration to avoid drift error"): up to
``max_correction_s`` (default 0.5 s, the N-BEATS horizon) of consecutive flagged frames.
Longer, the output falls back to the raw EM pose and ``degraded`` is raised ("informing users of
the reasons for degraded body tracking", Sec. 3.1); the frames stay flagged while a long gyro
chain (continued from the last trusted rotation) and the EM rotation disagree by more than
``release_deg``, or until ``reanchor_s`` passes (then the chain is re-anchored on EM, bounding
its drift).

- rotation: the gyro-propagated rotation replaces the EM rotation;
- position, one of ``MIMConfig.position``:
  ``"none"`` (EM as measured), ``"hold"`` (last trusted position),
  ``"odometry"`` (Eq. 1: double integration of the IMU acceleration from the last trusted position
  with the velocity from the last trusted EM positions),
  ``"nbeats"`` (Eq. 2: the N-BEATS forecast made at the onset from the last 120 positions),
  ``"fusion"`` (Eq. 3: each frame the one-step N-BEATS forecast from the last 120 (corrected)
  positions plus the double integral of the acceleration over that step, fed back as input for
  the next frame).

All inputs are in the EM source frame: ``R_em`` sensor -> source, ``p_em`` m, ``gyro`` rad/s in
the sensor frame (angular velocity relative to the source), ``acc`` m/s^2 in the source frame
(relative linear acceleration, gravity removed).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.errors import ConfigError, ShapeError
from wearpose.interference._so3 import angle_between, exp_so3

POSITION_METHODS = ("none", "hold", "odometry", "nbeats", "fusion")


@dataclass(frozen=True)
class MIMConfig:
    """MIM settings (module doc).

    Attributes:
        threshold_deg: detection threshold ``e_th`` on the EM-vs-gyro rotation discrepancy, degrees.
        span_frames: ``Delta t`` of the test in frames: the reference is the trusted (or
            gyro-chained) rotation ``span_frames`` frames ago, carried forward by the gyro.
        max_correction_s: longest interference corrected, s (longer = degraded).
        rotation: correct rotation by gyro integration.
        position: position method, one of :data:`POSITION_METHODS`.
        forecaster: shipped weights name or checkpoint path of the N-BEATS forecaster
            (``"nbeats"``/``"fusion"``).
        velocity_frames: frames of trusted EM positions the odometry's initial velocity is
            differenced over.
        level_tau_s: time constant of the interference level's low-pass, s.
        max_speed: corrected positions move at most this fast, m/s (hand speeds stay below).
        release_deg: a degraded stretch ends when EM is back within this angle of the gyro chain.
        reanchor_s: longest gyro chain kept while degraded, s (bounds its drift).
    """

    threshold_deg: float = 1.0
    span_frames: int = 6
    max_correction_s: float = 0.5
    rotation: bool = True
    position: str = "fusion"
    forecaster: str = "nbeats_cpu"
    velocity_frames: int = 3
    level_tau_s: float = 0.1
    release_deg: float = 2.0
    max_speed: float = 6.0
    reanchor_s: float = 10.0

    def __post_init__(self) -> None:
        if self.position not in POSITION_METHODS:
            raise ConfigError(f"MIMConfig.position: {self.position!r} is not one of {POSITION_METHODS}")
        if self.threshold_deg <= 0 or self.max_correction_s < 0:
            raise ConfigError(f"MIMConfig: threshold_deg must be > 0 and max_correction_s >= 0, got "
                              f"{self.threshold_deg}, {self.max_correction_s}")


def load_numpy_forecaster(name_or_path: str | Path):
    """A :class:`~wearpose.interference.nbeats.NumpyNBeats` from shipped weights or a checkpoint path."""
    from wearpose.interference.nbeats import NumpyNBeats, load_forecaster

    p = Path(name_or_path)
    if not p.suffix:
        from wearpose.weights import weight_path
        p = weight_path(str(name_or_path))
    model, _ = load_forecaster(p)
    return NumpyNBeats(model)


_FORECASTERS: dict[str, Any] = {}


class MIM:
    """Online MIM for one EM sensor (module doc): ``reset()``, then ``step(...)`` per frame."""

    def __init__(self, config: MIMConfig | None = None, forecaster: Any = None):
        self.config = config or MIMConfig()
        self._forecaster = forecaster
        if forecaster is None and self.config.position in ("nbeats", "fusion"):
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
        self._R_ref: np.ndarray | None = None
        self._gyro_prev: np.ndarray | None = None
        self._hist: deque = deque(maxlen=self.input_len)   # output positions (trusted or corrected)
        self._trusted: deque = deque(maxlen=max(2, self.config.velocity_frames + 1))
        self._run = 0
        self._level = 0.0
        self._p_out: np.ndarray | None = None
        self._v: np.ndarray | None = None
        self._forecast: np.ndarray | None = None
        self._k = 0
        self._degraded = False
        self._R_long: np.ndarray | None = None
        self._t_degraded = 0.0
        k = max(1, int(self.config.span_frames))
        self._refs: deque = deque(maxlen=k)   # reference rotations of the last k frames
        self._dRs: deque = deque(maxlen=k)    # gyro increments of the last k frames

    def _position(self, p_em: np.ndarray, acc: np.ndarray, dt: float, onset: bool) -> np.ndarray:
        m = self.config.position
        last = self._p_out if self._p_out is not None else p_em
        if m == "none":
            return p_em
        if m == "hold":
            return last
        if onset:
            self._forecast = None
        if m == "odometry":
            if onset or self._v is None:
                tr = list(self._trusted)
                k = len(tr) - 1
                self._v = (tr[-1] - tr[0]) / (k * dt) if k >= 1 else np.zeros(3)
            v_new = self._v + acc * dt
            x = last + 0.5 * (self._v + v_new) * dt
            self._v = v_new
            return x
        if len(self._hist) < self.input_len:  # not enough history for the forecaster yet
            return last
        if m == "nbeats":
            if onset or self._forecast is None:
                self._forecast = self._forecaster(np.asarray(self._hist))
                self._k = 0
            self._k += 1
            k = min(self._k, self._forecast.shape[0]) - 1
            return self._forecast[k]
        # fusion (Eq. 3): one-step forecast + the acceleration's double integral over that step
        f = self._forecaster(np.asarray(self._hist))
        return f[0] + 0.5 * acc * dt * dt

    def step(self, R_em: Any, p_em: Any, gyro: Any, acc: Any, dt: float) -> dict[str, Any]:
        """One frame.

        Args:
            R_em: ``(3, 3)`` EM rotation (sensor -> source); p_em: ``(3,)`` m; gyro: ``(3,)`` rad/s
            (sensor frame); acc: ``(3,)`` m/s^2 (source frame); dt: s since the previous frame.

        Returns:
            dict: ``R`` (3, 3) and ``p`` (3,) corrected; ``interfered`` bool (the frame-level
            detection of Sec. 3.2; False while ``degraded``, which reports persistent interference);
            ``corrected`` bool (the output was corrected this frame); ``level`` float
            (discrepancy / threshold, low-passed); ``degraded`` bool; ``discrepancy`` rad.
        """
        R_em = np.asarray(R_em, dtype=np.float64)
        p_em = np.asarray(p_em, dtype=np.float64)
        gyro = np.asarray(gyro, dtype=np.float64)
        acc = np.asarray(acc, dtype=np.float64)
        if R_em.shape != (3, 3) or p_em.shape != (3,) or gyro.shape != (3,) or acc.shape != (3,):
            raise ShapeError(f"MIM.step: expected R (3, 3), p (3,), gyro (3,), acc (3,), got {R_em.shape}, "
                             f"{p_em.shape}, {gyro.shape}, {acc.shape}")
        cfg = self.config
        if self._R_ref is None:
            self._R_ref, self._gyro_prev, self._p_out = R_em.copy(), gyro.copy(), p_em.copy()
            self._refs.append(self._R_ref)
            self._hist.append(p_em.copy())
            self._trusted.append(p_em.copy())
            return {"R": R_em, "p": p_em, "interfered": False, "corrected": False, "level": 0.0,
                    "degraded": False, "discrepancy": 0.0}
        w = 0.5 * (self._gyro_prev + gyro)
        self._gyro_prev = gyro.copy()
        dR = exp_so3(w * dt)
        th = np.radians(cfg.threshold_deg)
        corrected = False
        R_out, p_out = R_em, p_em
        if self._degraded:
            # persistent interference: follow the long gyro chain until EM agrees with it again
            self._R_long = self._R_long @ dR
            self._t_degraded += dt
            d = angle_between(self._R_long, R_em)
            if d < np.radians(cfg.release_deg) or self._t_degraded > cfg.reanchor_s:
                self._degraded = False
                self._R_ref = R_em
                self._run = 0
                self._refs.clear()
                self._dRs.clear()
            interfered = False  # a degraded stretch is reported by ``degraded``, not frame by frame
        else:
            R_pred = self._R_ref @ dR
            # detection over a span of k frames: trusted/chained rotation k frames ago + gyro since
            self._dRs.append(dR)
            R_span = self._refs[0] if len(self._refs) == self._refs.maxlen else self._R_ref
            if len(self._refs) == self._refs.maxlen:
                for m in self._dRs:
                    R_span = R_span @ m
            else:
                R_span = R_pred
            d = angle_between(R_span, R_em)
            interfered = d > th
            if not interfered:
                self._run = 0
                self._R_ref = R_em
                self._trusted.append(p_em.copy())
            else:
                self._run += 1
                self._R_ref = R_pred
                if self._run * dt <= cfg.max_correction_s:
                    corrected = True
                    R_out = R_pred if cfg.rotation else R_em
                    p_out = self._position(p_em, acc, dt, onset=self._run == 1)
                    if cfg.position != "none" and self._p_out is not None:
                        # a hand moves at most max_speed: bounds a forecaster fed a distorted history
                        step = p_out - self._p_out
                        n = float(np.linalg.norm(step))
                        if n > cfg.max_speed * dt:
                            p_out = self._p_out + step * (cfg.max_speed * dt / n)
                else:  # too long for a correction: notify instead, watch for its end
                    self._degraded = True
                    self._R_long = R_pred
                    self._t_degraded = 0.0
        self._refs.append(self._R_ref)
        a = 1.0 - np.exp(-dt / max(cfg.level_tau_s, 1e-9))
        self._level += a * (d / th - self._level)
        self._p_out = p_out
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
           max_correction_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Detection only (no correction) over a sequence: ``(interfered (T,) bool, discrepancy (T,) rad)``.

    The same state machine as :meth:`MIM.step` (gyro chain from the last trusted rotation), for
    threshold sweeps.
    """
    mim = MIM(MIMConfig(threshold_deg=threshold_deg, position="none", max_correction_s=max_correction_s))
    T = R.shape[0]
    p0, a0 = np.zeros(3), np.zeros(3)
    flags, disc = np.zeros(T, bool), np.zeros(T)
    dt = 1.0 / float(fps)
    for t in range(T):
        o = mim.step(R[t], p0, gyro[t], a0, dt)
        flags[t], disc[t] = o["interfered"], o["discrepancy"]
    return flags, disc
