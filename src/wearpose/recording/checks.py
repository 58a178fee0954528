"""Plausibility checks: does the data look like the units and conventions its file declares?

The most common failure reported by users of peer systems (TransPose, PIP, DIP issue trackers)
is data in the wrong unit or convention: positions in millimetres, acceleration in g, gyro in
deg/s, quaternions in (x, y, z, w) order, timestamps in milliseconds, gravity left in. These
checks look at the data itself and name the convention it *seems* to use, with the one fix (a
declaration in ``SensorInfo``, or a rewrite where no declaration exists). They run on every
:func:`wearpose.recording.load_recording`.

Each check returns :class:`ConventionIssue` objects rather than raising, so callers can decide
(the file reader raises the first one as an ``InputFileError``).

What each check compares (thresholds below, measured figures in ``docs/formats.md``):

- timestamps: median step vs the declared rate;
- positions: magnitude (|p| <= 20 m on a body);
- acceleration, where the sensor rests: magnitude (1 g, 0 once gravity is removed) and, with an
  orientation, direction (world up);
- angular velocity, where orientation exists too: the gyro integrated over
  :data:`GYRO_SPAN_S` against the orientation change over the same span. Their directions agree
  for the right quaternion order, their magnitudes are equal for the right unit (57.3 times
  larger: deg/s read as rad/s);
- quaternion order (w, x, y, z) vs (x, y, z, w), from physics rather than from the numbers'
  look (sensor frames are arbitrary, so "|w| is large" is not a rule real sensors keep):
  the gyro (above), gravity (a sensor-frame accelerometer reading rotated to the world points
  up on average), and for position + orientation sensors (EM, VIO) a rigid lever (the sensor's
  position changes, within half a second, like ``R(t) r`` for one fixed offset ``r``), pooled
  over the recording's sensors because one sensor's lever is weak evidence.

Every check looks at a bounded, evenly spread subset of windows (``*_MAX_WINDOWS``), so a
1-hour recording is checked in about the time of a 1-minute one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from wearpose.geometry import matrix_to_axis_angle, matrix_to_quat, quat_to_matrix
from wearpose.recording.types import G, SensorStream

#: A human can't be more than this far (in metres) from an EM source / tracking origin.
MAX_POSITION_M = 20.0
#: Declared rate vs rate implied by the median timestamp step: allowed relative mismatch.
RATE_TOLERANCE = 0.25
#: A "static" window: acceleration vector varies by less than this (relative to its magnitude).
STATIC_REL_SPREAD = 0.05
STATIC_WINDOW_S = 0.25
MIN_STATIC_FRAMES = 10
#: At most this many rest windows are examined, evenly spread (a 1-hour 60 Hz stream has 28 800).
STATIC_MAX_WINDOWS = 5000

#: Span (s) over which the integrated gyro is compared with the orientation change: long enough
#: for the turn to exceed orientation noise (0.5-1 deg per frame for MEMS fusion), short enough
#: that summing body rates still equals the rotation (the axis barely changes).
GYRO_SPAN_S = 0.1
#: Only spans where the orientation turns at least this much (rad) are compared: below it a
#: MEMS fusion's orientation noise, not motion, decides the direction of the change.
GYRO_MIN_TURN_RAD = 0.15
#: ... and at most this much (rad): near pi the axis of a rotation is ill-defined.
GYRO_MAX_TURN_RAD = math.pi - 0.3
#: Fewer moving spans than this: no judgement (the sensor barely moved).
GYRO_MIN_WINDOWS = 10
#: Spans considered (evenly spread over the recording) and, of the moving ones, compared at
#: most: bounds the work on long recordings (1000 spans decide as well as all of them).
GYRO_MAX_CANDIDATES = 20000
GYRO_MAX_WINDOWS = 1000
#: Gyro and orientation "agree" when the median angle between integrated gyro and orientation
#: change is at most this (deg); measured on simulated kits: <= 17 deg (noise-free and default
#: IMU noise), up to 52 deg for MEMS-fusion orientation noise, which then stays undecided.
GYRO_AGREE_DEG = 20.0
#: Quaternion order from the gyro: the other order must fit better in at least this fraction of
#: the spans (correct simulated data: at most 0.27; (x, y, z, w) files: at least 0.82).
GYRO_ORDER_VOTE = 0.75
DEG_PER_RAD = 180.0 / math.pi
#: |integrated gyro| / |orientation change| within this factor of 57.3: the gyro is in deg/s.
GYRO_UNIT_FACTOR = 2.0
#: A body-worn MEMS gyro's full scale is at most about 2000 deg/s (35 rad/s): a rad/s reading
#: whose 99th percentile exceeds it cannot come from one (used where no orientation exists).
GYRO_FULL_SCALE_RAD_S = math.radians(2000.0)

#: Gravity cue: the mean sensor-frame accelerometer direction rotated to the world lies within
#: acos(0.9) = 26 deg of world up for the right order and beyond acos(0.7) = 46 deg for the other.
GRAVITY_ALIGNED_COS = 0.9
GRAVITY_MISALIGNED_COS = 0.7
GRAVITY_MAX_FRAMES = 20000
#: A sensor that never rests is judged from its average reading over at least this long (s):
#: free acceleration then averages to at most a few tenths of m/s^2 (velocity change / time).
MEAN_GRAVITY_MIN_S = 1.0
#: ... when that average points within acos(0.95) = 18 deg of world up. The average is a
#: trimmed mean: this fraction of the lowest and of the highest values of each axis is dropped.
MEAN_GRAVITY_COS = 0.95
MEAN_GRAVITY_TRIM = 0.1

#: Lever cue: window length (s), minimum RMS position change within a window after removing
#: its linear trend (m; EM noise is ~3 mm), windows compared at most.
LEVER_WINDOW_S = 0.5
LEVER_MIN_RMS_M = 0.005
LEVER_MAX_WINDOWS = 256
#: Pooled lever evidence (sum over sensors of log(unexplained variance as stored / with the
#: last component as w)) needed to call a file (x, y, z, w). Measured on 80 corpus clips per kit
#: and noise setting: correct em12/em6/miposer files pool to >= -0.09, (x, y, z, w) ones to a
#: median of -13 (em12), -5 (em6), -2.2 (miposer); docs/formats.md has the detection rates.
LEVER_POOLED_LOG_RATIO = 2.0

#: The one fix for (x, y, z, w) quaternions (the format has no declaration for the order).
QUAT_FIX = "unit quaternions in (w, x, y, z) order; rewrite them w-first: q[..., [3, 0, 1, 2]]"


@dataclass(frozen=True)
class ConventionIssue:
    """One suspected convention problem.

    Attributes:
        sensor: sensor name.
        field: the channel (``"timestamps"``, ``"position"``, ``"orientation"``,
            ``"acceleration"``, ``"angular_velocity"``).
        problem: what the data looks like.
        expected: what the declaration implies and the one fix.
    """

    sensor: str
    field: str
    problem: str
    expected: str


def check_stream(s: SensorStream) -> list[ConventionIssue]:
    """All convention issues of one stream (empty list: looks as declared).

    The quaternion order is judged from this stream alone (its lever evidence is not pooled
    with other sensors': :func:`check_recording` does that).
    """
    ev = {id(s): gyro_evidence(s)}
    return _stream_issues(s, _order_issues([s], ev).get(s.name), ev[id(s)])


def check_recording(streams: Sequence[SensorStream]) -> list[ConventionIssue]:
    """Convention issues of several streams (e.g. ``recording.sensors``), in stream order.

    Like :func:`check_stream` per stream, except that the quaternion order's lever evidence
    (position + orientation sensors) is pooled over all streams.
    """
    ev = {id(s): gyro_evidence(s) for s in streams}  # used by two checks: computed once
    order = _order_issues(list(streams), ev)
    out: list[ConventionIssue] = []
    for s in streams:
        out += _stream_issues(s, order.get(s.name), ev[id(s)])
    return out


def _stream_issues(s: SensorStream, order_issue: ConventionIssue | None,
                   ev: GyroEvidence | None) -> list[ConventionIssue]:
    # Order matters: the file reader reports the first field. Timestamps come first (every rate
    # and integral depends on them), the quaternion order before the acceleration (whose frame
    # checks rotate with the orientation).
    issues: list[ConventionIssue] = []
    issues += _check_rate(s)
    issues += _check_positions(s)
    if order_issue is not None:
        issues.append(order_issue)
    issues += _check_acceleration(s)
    issues += _check_gyro_unit(s, ev)
    return issues


def _check_rate(s: SensorStream) -> list[ConventionIssue]:
    if s.num_frames < 3:
        return []
    dt = float(np.median(np.diff(s.timestamps)))
    implied = 1.0 / dt
    declared = float(s.info.rate)
    if abs(implied - declared) <= RATE_TOLERANCE * declared:
        return []
    hint = ""
    for factor, unit in ((1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds")):
        if abs(implied * factor - declared) <= RATE_TOLERANCE * declared:
            hint = f"; timestamps look like {unit}: divide by {factor:g}"
            break
    return [ConventionIssue(s.name, "timestamps",
                            f"median step {dt:.6g} s implies {implied:.4g} Hz but rate declares {declared:g} Hz{hint}",
                            f"timestamps in seconds consistent with the declared rate (within {RATE_TOLERANCE:.0%}), or fix 'rate'")]


def _check_positions(s: SensorStream) -> list[ConventionIssue]:
    if s.position is None or s.info.position_unit != "m":
        return []
    p = s.position[s.valid]
    if p.size == 0:
        return []
    r = float(np.max(np.linalg.norm(p.astype(np.float64), axis=1)))
    if r <= MAX_POSITION_M:
        return []
    # 20 m in mm is 20000: beyond ~2000 "m" the data is almost surely millimetres.
    guess = "millimetres" if r > 100 * MAX_POSITION_M else "centimetres"
    return [ConventionIssue(s.name, "position",
                            f"|p| reaches {r:.4g} m, implausible for a body-worn sensor; looks like millimetres or "
                            f"centimetres (most likely {guess})",
                            "metres (|p| <= 20 m); declare position_unit 'mm' or 'cm' in the sensor info or convert")]


def static_frames(s: SensorStream) -> np.ndarray:
    """``(N,)`` bool: valid frames inside a window (:data:`STATIC_WINDOW_S`) where the
    acceleration vector is nearly constant -- the sensor is (close to) at rest, so the reading is
    gravity (if included) or zero (if removed).

    Windows of ``w`` frames start every ``w // 2`` frames (at most :data:`STATIC_MAX_WINDOWS`
    of them, evenly spread); a window counts when all its frames are valid and no reading is
    further than :data:`STATIC_REL_SPREAD` of the mean magnitude (or 1e-3 absolute) from the
    window's mean vector.
    """
    a = s.acceleration
    n = s.num_frames
    out = np.zeros(n, dtype=bool)
    if a is None or n < 3:
        return out
    dt = float(np.median(np.diff(s.timestamps)))
    w = max(3, int(round(STATIC_WINDOW_S / dt))) if dt > 0 else 3
    w = min(w, n)
    step = max(1, w // 2)
    starts = np.arange(0, n - w + 1, step)
    invalid = np.concatenate([[0], np.cumsum(~s.valid)])
    starts = _spread(starts[invalid[starts + w] == invalid[starts]], STATIC_MAX_WINDOWS)
    if starts.size == 0:
        return out
    # Windows holding an invalid (NaN) frame were dropped above; the view copies only the kept ones.
    seg = np.lib.stride_tricks.sliding_window_view(a, w, axis=0)[starts].transpose(0, 2, 1).astype(np.float64)  # (K, w, 3)
    dev = seg - seg.mean(axis=1, keepdims=True)
    spread = np.sqrt((dev * dev).sum(axis=2)).max(axis=1)  # (K,)
    mag = np.sqrt((seg * seg).sum(axis=2)).mean(axis=1)
    still = (spread <= STATIC_REL_SPREAD * np.maximum(mag, 1e-3)) | (spread < 1e-3)
    # Mark every frame of each still window: a difference array over window starts/ends.
    mark = np.zeros(n + 1, dtype=np.int64)
    np.add.at(mark, starts[still], 1)
    np.add.at(mark, starts[still] + w, -1)
    return np.cumsum(mark[:n]) > 0


def _up(world_up: str) -> np.ndarray:
    return np.array([0.0, 1.0, 0.0]) if world_up == "y_up" else np.array([0.0, 0.0, 1.0])


def _check_acceleration(s: SensorStream) -> list[ConventionIssue]:
    """Unit, gravity and frame of the acceleration, judged from the frames where the sensor rests.

    At rest an accelerometer reads gravity's reaction, +1 g *up*: 9.81 in m/s^2, 1.0 in g, about
    0 once gravity is removed; in the world frame it points along the world's up axis, in the
    sensor frame it does so only after rotating by ``R_WS``. Gravity is judged in the unit the
    data looks like: a reading of 1.0 declared m/s^2 is "in g" (one problem, one fix), not also
    "gravity removed".
    """
    if s.acceleration is None:
        return []
    st = static_frames(s)
    if st.sum() < MIN_STATIC_FRAMES:
        return _check_mean_gravity(s)  # never at rest: the recording's average reading instead
    f = s.acceleration[st].astype(np.float64)
    m = float(np.median(np.linalg.norm(f, axis=1)))
    info = s.info
    unit, grav = info.acc_unit, info.acc_gravity
    looks_ms2, looks_g = abs(m - G) <= 0.15 * G, abs(m - 1.0) <= 0.15
    issues = []
    if unit == "m/s2" and looks_g:
        issues.append(ConventionIssue(s.name, "acceleration", f"static magnitude {m:.3g} while declared m/s^2; looks like g",
                                      "m/s^2 by default; declare acc_unit 'g' in the sensor info"))
        unit = "g"  # judge gravity in the unit the data is in
    elif unit == "g" and looks_ms2:
        issues.append(ConventionIssue(s.name, "acceleration", f"static magnitude {m:.3g} while declared g; looks like m/s^2",
                                      "g as declared; declare acc_unit 'm/s2' in the sensor info"))
        unit = "m/s2"
    one_g = G if unit == "m/s2" else 1.0
    gravity_in = looks_ms2 or looks_g
    if grav == "removed" and gravity_in:
        issues.append(ConventionIssue(s.name, "acceleration",
                                      f"static magnitude {m:.3g} (about 1 g) while declared gravity-removed; looks like gravity is included",
                                      "free acceleration (about 0 at rest); declare acc_gravity 'included' in the sensor info"))
    elif grav == "included" and m < 0.3 * one_g:
        issues.append(ConventionIssue(s.name, "acceleration",
                                      f"static magnitude {m:.3g} {unit} while declared gravity-included; looks like gravity is removed",
                                      "an accelerometer reading (about 1 g at rest); declare acc_gravity 'removed' in the sensor info"))
    if gravity_in and s.orientation is not None:
        up = _up(info.world_up)
        d = f / np.linalg.norm(f, axis=1, keepdims=True)
        cos_world = float(np.median(d @ up))
        cos_sensor = float(np.median(np.einsum("nij,nj->ni", s.orientation[st].astype(np.float64), d) @ up))
        if info.acc_frame == "world" and cos_world < 0.9 and cos_sensor > 0.97:
            issues.append(ConventionIssue(s.name, "acceleration",
                                          f"at rest the reading points {np.degrees(np.arccos(np.clip(cos_world, -1, 1))):.0f} deg away from world up "
                                          "but along up once rotated by the orientation; looks like the sensor frame",
                                          "world-frame acceleration as declared, or declare acc_frame 'sensor'"))
        elif info.acc_frame == "sensor" and cos_sensor < 0.9 and cos_world > 0.97:
            issues.append(ConventionIssue(s.name, "acceleration",
                                          "at rest the reading points along world up without rotating by the orientation; looks like the world frame",
                                          "sensor-frame acceleration as declared, or declare acc_frame 'world'"))
        else:
            # Orientations (or world-frame readings) in the other up-axis convention: the reading
            # lines up with the *other* axis instead of the declared one.
            other_name = "z_up" if info.world_up == "y_up" else "y_up"
            other = _up(other_name)
            world_d = d if info.acc_frame == "world" else np.einsum("nij,nj->ni", s.orientation[st].astype(np.float64), d)
            cos_decl, cos_other = float(np.median(world_d @ up)), float(np.median(world_d @ other))
            if cos_decl < 0.9 and cos_other > 0.97:
                issues.append(ConventionIssue(s.name, "orientation",
                                              f"at rest gravity's reaction points along the {other_name.replace('_', '-')} axis of the world, "
                                              f"not along the declared {info.world_up.replace('_', '-')} axis; orientations look like a "
                                              f"{other_name.replace('_', '-')} world",
                                              f"orientations in a {info.world_up.replace('_', '-')} world, or declare world_up '{other_name}'"))
    return issues


def _check_mean_gravity(s: SensorStream) -> list[ConventionIssue]:
    """Unit and gravity of the acceleration of a sensor that never rests, from its average.

    Averaged over a recording, free acceleration is the velocity change divided by the duration
    (a few tenths of m/s^2 after :data:`MEAN_GRAVITY_MIN_S`; the average is trimmed,
    :data:`MEAN_GRAVITY_TRIM`, against glitches), so an accelerometer reading
    (gravity included) averages to gravity's reaction: 1 g pointing up in the world. Judged only
    when the average points up (:data:`MEAN_GRAVITY_COS`) and only for the mistakes free
    acceleration cannot imitate: a reading declared gravity-included that averages 1.0 "m/s^2"
    (in g) or 9.81 "g" (in m/s^2), and one declared gravity-removed that averages 1 g.
    """
    info = s.info
    if s.acceleration is None or (info.acc_frame == "sensor" and s.orientation is None):
        return []
    idx = _spread(np.flatnonzero(s.valid), GRAVITY_MAX_FRAMES)
    if idx.size < MIN_STATIC_FRAMES or s.timestamps[idx[-1]] - s.timestamps[idx[0]] < MEAN_GRAVITY_MIN_S:
        return []
    f = s.acceleration[idx].astype(np.float64)
    if info.acc_frame == "sensor":
        f = np.einsum("mij,mj->mi", s.orientation[idx].astype(np.float64), f)
    # A trimmed mean: one glitch frame (a simulated jump between a clip's first frames reads
    # 1000 m/s^2) must not decide the average of a few hundred.
    k = int(MEAN_GRAVITY_TRIM * f.shape[0])
    mean = np.sort(f, axis=0)[k:f.shape[0] - k].mean(axis=0)
    m = float(np.linalg.norm(mean))
    cos_up = float(mean @ _up(info.world_up)) / max(m, 1e-12)
    if cos_up < MEAN_GRAVITY_COS:
        return []
    looks_ms2, looks_g = abs(m - G) <= 0.15 * G, abs(m - 1.0) <= 0.15
    span = float(s.timestamps[idx[-1]] - s.timestamps[idx[0]])
    how = (f"the sensor never rests; averaged over {span:.3g} s the reading is {m:.3g} pointing "
           f"{math.degrees(math.acos(min(1.0, cos_up))):.0f} deg from world up (gravity's reaction, all an accelerometer "
           f"reading keeps on average)")
    if info.acc_gravity == "included":
        if info.acc_unit == "m/s2" and looks_g:
            return [ConventionIssue(s.name, "acceleration", f"{how} while declared m/s^2; looks like g",
                                    "m/s^2 by default; declare acc_unit 'g' in the sensor info")]
        if info.acc_unit == "g" and looks_ms2:
            return [ConventionIssue(s.name, "acceleration", f"{how} while declared g; looks like m/s^2",
                                    "g as declared; declare acc_unit 'm/s2' in the sensor info")]
    elif (looks_ms2 if info.acc_unit == "m/s2" else looks_g):
        return [ConventionIssue(s.name, "acceleration", f"{how} while declared gravity-removed; looks like gravity is included",
                                "free acceleration (about 0 on average); declare acc_gravity 'included' in the sensor info")]
    return []


# ----------------------------------------------------------------------------- rotations
def w_last_reading(R: np.ndarray) -> np.ndarray:
    """The rotations a file's quaternions stand for if they were written (x, y, z, w).

    Args:
        R: ``(M, 3, 3)`` rotations as read, i.e. from the stored numbers ``s`` taken as
            (w, x, y, z).

    Returns:
        ``(M, 3, 3)``: the rotations of ``s[..., [3, 0, 1, 2]]`` (the last number as w). The
        sign of ``s`` is lost in ``R`` but a quaternion and its negative are the same rotation.
    """
    q = matrix_to_quat(torch.from_numpy(np.ascontiguousarray(R, dtype=np.float64))).numpy()
    return quat_to_matrix(torch.from_numpy(np.ascontiguousarray(q[:, [3, 0, 1, 2]]))).numpy()


def _relative_rotvec(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """``(M, 3)`` rotation vectors of ``R0^T R1`` (the change in the sensor frame), rad."""
    return matrix_to_axis_angle(torch.from_numpy(np.einsum("mji,mjk->mik", R0, R1))).numpy()


def _spread(idx: np.ndarray, cap: int) -> np.ndarray:
    """At most ``cap`` entries of ``idx``, evenly spread (all of them when there are fewer)."""
    if idx.size <= cap:
        return idx
    # floor(i * size / cap) is strictly increasing for size > cap: distinct, in order.
    return idx[(np.arange(cap) * (idx.size / cap)).astype(np.int64)]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c = np.sum(a * b, axis=1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


# ----------------------------------------------------------------------------- gyro vs orientation
@dataclass(frozen=True)
class GyroEvidence:
    """Integrated gyro vs orientation change of one stream (:func:`gyro_evidence`).

    Attributes:
        windows: spans compared (orientation turned by at least :data:`GYRO_MIN_TURN_RAD`).
        span_s: length of each span, s.
        err_w_first: median angle (deg) between the integrated gyro and the orientation change
            with the quaternions read as stored, (w, x, y, z).
        err_w_last: the same with the quaternions read as (x, y, z, w).
        frac_w_last: fraction of spans where the (x, y, z, w) reading fits better.
        ratio: median ``|integrated gyro| / |orientation change|`` (gyro converted from its
            declared unit to rad/s): about 1 for the right unit, 57.3 for deg/s read as rad/s.
    """

    windows: int
    span_s: float
    err_w_first: float
    err_w_last: float
    frac_w_last: float
    ratio: float


def gyro_evidence(s: SensorStream) -> GyroEvidence | None:
    """Compare the gyro with the orientation of a stream that has both.

    Over spans of :data:`GYRO_SPAN_S` (all frames valid, orientation turning by at least
    :data:`GYRO_MIN_TURN_RAD`): the gyro ``w`` (sensor frame, declared unit converted to rad/s)
    integrated with the trapezoid rule, against the rotation vector of ``R_k^T R_{k+L}`` (the
    orientation change in the sensor frame). Both read the quaternions w-first and w-last (the
    magnitude of the change is the same in both readings: the dot product of two quaternions
    does not depend on the order of their components).

    Returns:
        :class:`GyroEvidence`, or ``None`` without both channels or with fewer than
        :data:`GYRO_MIN_WINDOWS` moving spans.
    """
    if s.orientation is None or s.angular_velocity is None or s.num_frames < 3:
        return None
    ts, valid = s.timestamps, s.valid
    n = s.num_frames
    dt = float(np.median(np.diff(ts)))
    if not dt > 0:
        return None
    L = max(1, int(round(GYRO_SPAN_S / dt)))
    if n <= L:
        return None
    invalid = np.concatenate([[0], np.cumsum(~valid)])
    k = np.arange(n - L)
    k = _spread(k[invalid[k + L + 1] == invalid[k]], GYRO_MAX_CANDIDATES)
    if k.size == 0:
        return None
    # The turn of each candidate span from the trace (cheap), before any log or quaternion work.
    R0, R1 = s.orientation[k].astype(np.float64), s.orientation[k + L].astype(np.float64)
    turn = np.arccos(np.clip((np.einsum("mij,mij->m", R0, R1) - 1.0) / 2.0, -1.0, 1.0))
    moving = _spread(np.flatnonzero((turn >= GYRO_MIN_TURN_RAD) & (turn <= GYRO_MAX_TURN_RAD)), GYRO_MAX_WINDOWS)
    if moving.size < GYRO_MIN_WINDOWS:
        return None
    k, R0, R1 = k[moving], R0[moving], R1[moving]
    # Trapezoid integral of the gyro over each span (all its frames are valid).
    span = k[:, None] + np.arange(L + 1)  # (M, L + 1)
    w = s.angular_velocity[span].astype(np.float64)
    if s.info.gyro_unit == "deg/s":
        w = w / DEG_PER_RAD
    g = np.einsum("ml,mlc->mc", np.diff(ts[span], axis=1), 0.5 * (w[:, 1:] + w[:, :-1]))
    d_first = _relative_rotvec(R0, R1)
    RB = w_last_reading(np.concatenate([R0, R1]))
    d_last = _relative_rotvec(RB[: k.size], RB[k.size:])
    e_first, e_last = _angle_deg(g, d_first), _angle_deg(g, d_last)
    ratio = np.linalg.norm(g, axis=1) / np.maximum(np.linalg.norm(d_first, axis=1), 1e-12)
    return GyroEvidence(int(k.size), L * dt, float(np.median(e_first)), float(np.median(e_last)),
                        float(np.mean(e_last < e_first)), float(np.median(ratio)))


def _check_gyro_unit(s: SensorStream, ev: GyroEvidence | None) -> list[ConventionIssue]:
    """Angular velocity in the declared unit?

    With orientation: the integrated gyro must turn as far as the orientation does (ratio 1);
    57.3 is deg/s declared (or defaulted to) rad/s, 1/57.3 the reverse. The magnitudes are only
    compared when their directions agree (in either quaternion order): then both describe the
    same rotation. Without orientation: a rad/s reading beyond a MEMS gyro's full scale.
    """
    if s.angular_velocity is None:
        return []
    unit = s.info.gyro_unit
    if ev is not None and ev.ratio > 0 and min(ev.err_w_first, ev.err_w_last) <= GYRO_AGREE_DEG:
        how = (f"over {ev.windows} spans of {ev.span_s:.3g} s the integrated angular velocity turns {ev.ratio:.3g} "
               f"times as far as the orientation (median)")
        if unit == "rad/s" and abs(math.log(ev.ratio / DEG_PER_RAD)) <= math.log(GYRO_UNIT_FACTOR):
            return [ConventionIssue(s.name, "angular_velocity", f"{how}; 57.3 is deg/s read as rad/s: looks like deg/s",
                                    "rad/s (the default); declare gyro_unit 'deg/s' in the sensor info")]
        if unit == "deg/s" and abs(math.log(ev.ratio * DEG_PER_RAD)) <= math.log(GYRO_UNIT_FACTOR):
            return [ConventionIssue(s.name, "angular_velocity", f"{how}; 1/57.3 is rad/s read as deg/s: looks like rad/s",
                                    "deg/s as declared; declare gyro_unit 'rad/s' in the sensor info")]
        return []
    if unit == "rad/s":
        v = s.angular_velocity[_spread(np.flatnonzero(s.valid), GRAVITY_MAX_FRAMES)]
        if v.shape[0] >= GYRO_MIN_WINDOWS:
            p99 = float(np.percentile(np.linalg.norm(v.astype(np.float64), axis=1), 99))
            if p99 > GYRO_FULL_SCALE_RAD_S:
                return [ConventionIssue(s.name, "angular_velocity",
                                        f"99th percentile of |angular velocity| is {p99:.4g} rad/s, beyond any body-worn "
                                        f"gyro's range ({GYRO_FULL_SCALE_RAD_S:.3g} rad/s = 2000 deg/s); looks like deg/s",
                                        "rad/s (the default); declare gyro_unit 'deg/s' in the sensor info")]
    return []


# ----------------------------------------------------------------------------- quaternion order
@dataclass(frozen=True)
class _OrderCue:
    """One cue's verdict on one stream: +1 as stored (w, x, y, z), -1 (x, y, z, w), 0 undecided."""

    verdict: int
    text: str


def _gyro_order_cue(ev: GyroEvidence | None) -> _OrderCue | None:
    if ev is None:
        return None
    text = (f"over {ev.windows} spans of {ev.span_s:.3g} s the orientation change differs from the integrated angular "
            f"velocity by a median {ev.err_w_first:.0f} deg read as stored (w, x, y, z) and by {ev.err_w_last:.0f} deg "
            f"read as (x, y, z, w)")
    if ev.frac_w_last >= GYRO_ORDER_VOTE and ev.err_w_last <= GYRO_AGREE_DEG:
        return _OrderCue(-1, text)
    if ev.frac_w_last <= 1.0 - GYRO_ORDER_VOTE and ev.err_w_first <= GYRO_AGREE_DEG:
        return _OrderCue(+1, text)
    return _OrderCue(0, text)


def _gravity_order_cue(s: SensorStream) -> _OrderCue | None:
    """A raw sensor-frame accelerometer reading, rotated to the world, points up on average
    (free acceleration averages out over a recording; gravity's reaction does not)."""
    info = s.info
    if (s.orientation is None or s.acceleration is None or info.acc_frame != "sensor"
            or info.acc_gravity != "included"):
        return None
    idx = _spread(np.flatnonzero(s.valid), GRAVITY_MAX_FRAMES)
    if idx.size < GYRO_MIN_WINDOWS:
        return None
    f = s.acceleration[idx].astype(np.float64)
    norm = np.linalg.norm(f, axis=1, keepdims=True)
    keep = norm[:, 0] > 0
    if keep.sum() < GYRO_MIN_WINDOWS:
        return None
    d = f[keep] / norm[keep]
    R = s.orientation[idx][keep].astype(np.float64)
    up = _up(info.world_up)
    cos = []
    for RR in (R, w_last_reading(R)):
        mean = np.einsum("mij,mj->i", RR, d) / d.shape[0]
        cos.append(float(mean @ up / max(np.linalg.norm(mean), 1e-12)))
    deg = [math.degrees(math.acos(min(1.0, max(-1.0, c)))) for c in cos]
    text = (f"the accelerometer reading rotated to the world points on average {deg[0]:.0f} deg from world up read "
            f"as stored (w, x, y, z) and {deg[1]:.0f} deg read as (x, y, z, w)")
    if cos[1] >= GRAVITY_ALIGNED_COS and cos[0] <= GRAVITY_MISALIGNED_COS:
        return _OrderCue(-1, text)
    if cos[0] >= GRAVITY_ALIGNED_COS and cos[1] <= GRAVITY_MISALIGNED_COS:
        return _OrderCue(+1, text)
    return _OrderCue(0, text)


_POSITION_TO_M = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def lever_score(s: SensorStream) -> float | None:
    """How much better the stored quaternion order explains the stream's position changes.

    A body-worn sensor is carried by a segment turning about a joint: within a short window
    (:data:`LEVER_WINDOW_S`) its position changes like ``R(t) r`` for one offset ``r`` (sensor
    frame) plus the joint's own, smoother motion. Per window, the linear trend is removed from
    ``p`` and ``R``; ``r`` is fitted over all windows by least squares, once with the
    quaternions read as stored and once read (x, y, z, w).

    Returns:
        ``log(u_last / u_first)`` with ``u`` the unexplained fraction of the detrended position
        variance: > 0 the stored order fits better, < 0 the (x, y, z, w) reading does; ``None``
        without position and orientation or when the sensor barely moves
        (:data:`LEVER_MIN_RMS_M`).
    """
    if s.position is None or s.orientation is None or s.num_frames < 8:
        return None
    ts, valid = s.timestamps, s.valid
    dt = float(np.median(np.diff(ts)))
    if not dt > 0:
        return None
    W = max(4, int(round(LEVER_WINDOW_S / dt)))
    starts = np.arange(0, s.num_frames - W + 1, W)
    invalid = np.concatenate([[0], np.cumsum(~valid)])
    starts = _spread(starts[invalid[starts + W] == invalid[starts]], LEVER_MAX_WINDOWS)
    if starts.size < 2:
        return None
    idx = starts[:, None] + np.arange(W)  # (K, W)
    t = ts[idx] - ts[idx].mean(axis=1, keepdims=True)
    tt = (t * t).sum(axis=1)[:, None, None]

    def detrend(x: np.ndarray) -> np.ndarray:  # (K, W, c): remove each window's mean and slope
        x = x - x.mean(axis=1, keepdims=True)
        return x - t[..., None] * ((t[..., None] * x).sum(axis=1, keepdims=True) / np.maximum(tt, 1e-300))

    y = detrend(s.position[idx].astype(np.float64) * _POSITION_TO_M[s.info.position_unit])
    total = float((y * y).sum())
    if total / idx.size < LEVER_MIN_RMS_M ** 2:
        return None
    R = s.orientation[idx].astype(np.float64)  # (K, W, 3, 3)
    K = idx.shape[0]
    unexplained = []
    for RR in (R, w_last_reading(R.reshape(-1, 3, 3)).reshape(K, W, 3, 3)):
        M = detrend(RR.reshape(K, W, 9)).reshape(K, W, 3, 3)
        A = np.einsum("kwji,kwjl->il", M, M)
        b = np.einsum("kwji,kwj->i", M, y)
        r = np.linalg.lstsq(A, b, rcond=None)[0]
        unexplained.append(max(total - float(b @ r), 1e-6 * total) / total)
    return math.log(unexplained[1] / unexplained[0])


def _order_issues(streams: list[SensorStream], ev: dict[int, GyroEvidence | None]) -> dict[str, ConventionIssue]:
    """Quaternion-order issues by sensor name.

    Per stream, the gyro and gravity cues are decisive on their own: a stream is called
    (x, y, z, w) when one says so and none says (w, x, y, z). Lever evidence is weak per sensor,
    so it is summed over the streams no decisive cue covers, and calls them (x, y, z, w) only
    when the sum reaches :data:`LEVER_POOLED_LOG_RATIO` and no stream of the recording is
    decisively (w, x, y, z) (a file's quaternions usually come from one writer).
    """
    decided: dict[str, int] = {}
    texts: dict[str, str] = {}
    for s in streams:
        if s.orientation is None:
            continue
        cues = [c for c in (_gyro_order_cue(ev[id(s)]), _gravity_order_cue(s)) if c is not None]
        votes = {c.verdict for c in cues}
        if -1 in votes and +1 not in votes:
            decided[s.name] = -1
            texts[s.name] = "; ".join(c.text for c in cues if c.verdict == -1)
        elif +1 in votes and -1 not in votes:
            decided[s.name] = +1
    levers = {s.name: sc for s in streams if s.name not in decided and (sc := lever_score(s)) is not None}
    pooled = sum(levers.values())
    if levers and pooled <= -LEVER_POOLED_LOG_RATIO and +1 not in decided.values():
        for name, sc in levers.items():
            if sc < 0:
                decided[name] = -1
                texts[name] = (f"a rigid lever on the orientation leaves {math.exp(-sc):.3g} times less of the position "
                               f"changes unexplained read as (x, y, z, w) than read as stored (w, x, y, z) (a factor "
                               f"e^{-pooled:.1f} pooled over {len(levers)} position sensor{'s' if len(levers) > 1 else ''}; "
                               f"e^{LEVER_POOLED_LOG_RATIO:g} decides)")
    wrong = [s.name for s in streams if decided.get(s.name) == -1]
    out = {}
    for name in wrong:
        others = [o for o in wrong if o != name]
        also = f"; so do the quaternions of {', '.join(others)}" if others else ""
        out[name] = ConventionIssue(name, "orientation", f"{texts[name]}: the quaternions look written (x, y, z, w){also}",
                                    QUAT_FIX)
    return out
