"""Plausibility checks: does the data look like the units and conventions its file declares?

The most common failure reported by users of peer systems (TransPose, PIP, DIP issue trackers)
is data in the wrong unit or convention: positions in millimetres, acceleration in g, timestamps
in milliseconds, gravity left in. These checks look at the data itself and name the convention
it *seems* to use, so the user can declare it (``SensorInfo``) or convert it. They run on every
:func:`wearpose.recording.load_recording`.

Each check returns :class:`ConventionIssue` objects rather than raising, so callers can decide
(the file reader raises the first one as an ``InputFileError``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wearpose.recording.types import G, SensorStream

#: A human can't be more than this far (in metres) from an EM source / tracking origin.
MAX_POSITION_M = 20.0
#: Declared rate vs rate implied by the median timestamp step: allowed relative mismatch.
RATE_TOLERANCE = 0.25
#: A "static" window: acceleration vector varies by less than this (relative to its magnitude).
STATIC_REL_SPREAD = 0.05
STATIC_WINDOW_S = 0.25
MIN_STATIC_FRAMES = 10


@dataclass(frozen=True)
class ConventionIssue:
    """One suspected convention problem.

    Attributes:
        sensor: sensor name.
        field: the channel (``"position"``, ``"acceleration"``, ``"timestamps"``).
        problem: what the data looks like.
        expected: what the declaration implies / how to fix.
    """

    sensor: str
    field: str
    problem: str
    expected: str


def check_stream(s: SensorStream) -> list[ConventionIssue]:
    """All convention issues of one stream (empty list: looks as declared)."""
    issues: list[ConventionIssue] = []
    issues += _check_rate(s)
    issues += _check_positions(s)
    issues += _check_acceleration(s)
    return issues


def check_recording(streams: list[SensorStream]) -> list[ConventionIssue]:
    """:func:`check_stream` over several streams (e.g. ``recording.sensors``)."""
    out: list[ConventionIssue] = []
    for s in streams:
        out += check_stream(s)
    return out


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
    gravity (if included) or zero (if removed)."""
    a = s.acceleration
    n = s.num_frames
    out = np.zeros(n, dtype=bool)
    if a is None or n < 3:
        return out
    dt = float(np.median(np.diff(s.timestamps)))
    w = max(3, int(round(STATIC_WINDOW_S / dt))) if dt > 0 else 3
    w = min(w, n)
    a64 = a.astype(np.float64)
    mag = np.linalg.norm(a64, axis=1)
    for start in range(0, n - w + 1, max(1, w // 2)):
        sl = slice(start, start + w)
        if not s.valid[sl].all():
            continue
        seg = a64[sl]
        spread = float(np.max(np.linalg.norm(seg - seg.mean(axis=0), axis=1)))
        if spread <= STATIC_REL_SPREAD * max(float(np.mean(mag[sl])), 1e-3) or spread < 1e-3:
            out[sl] = True
    return out


def _check_acceleration(s: SensorStream) -> list[ConventionIssue]:
    """Unit, gravity and frame of the acceleration, judged from the frames where the sensor rests.

    At rest an accelerometer reads gravity's reaction, +1 g *up*: 9.81 in m/s^2, 1.0 in g, about
    0 once gravity is removed; in the world frame it points along the world's up axis, in the
    sensor frame it does so only after rotating by ``R_WS``.
    """
    if s.acceleration is None:
        return []
    st = static_frames(s)
    if st.sum() < MIN_STATIC_FRAMES:
        return []  # never at rest: nothing to compare against
    f = s.acceleration[st].astype(np.float64)
    m = float(np.median(np.linalg.norm(f, axis=1)))
    info = s.info
    unit, grav = info.acc_unit, info.acc_gravity
    looks_ms2, looks_g = abs(m - G) <= 0.15 * G, abs(m - 1.0) <= 0.15
    one_g = G if unit == "m/s2" else 1.0
    issues = []
    if unit == "m/s2" and looks_g:
        issues.append(ConventionIssue(s.name, "acceleration", f"static magnitude {m:.3g} while declared m/s^2; looks like g",
                                      "m/s^2; declare acc_unit 'g' in the sensor info or multiply by 9.81"))
    elif unit == "g" and looks_ms2:
        issues.append(ConventionIssue(s.name, "acceleration", f"static magnitude {m:.3g} while declared g; looks like m/s^2",
                                      "g as declared, or declare acc_unit 'm/s2'"))
    gravity_in = looks_ms2 or looks_g
    if grav == "removed" and gravity_in:
        issues.append(ConventionIssue(s.name, "acceleration",
                                      f"static magnitude {m:.3g} (about 1 g) while declared gravity-removed; looks like gravity is included",
                                      "free acceleration (about 0 at rest); declare acc_gravity 'included' or remove gravity"))
    elif grav == "included" and m < 0.3 * one_g:
        issues.append(ConventionIssue(s.name, "acceleration",
                                      f"static magnitude {m:.3g} {unit} while declared gravity-included; looks like gravity is removed",
                                      "an accelerometer reading (about 1 g at rest); declare acc_gravity 'removed'"))
    if gravity_in and s.orientation is not None:
        up = np.array([0.0, 1.0, 0.0]) if info.world_up == "y_up" else np.array([0.0, 0.0, 1.0])
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
            other = np.array([0.0, 0.0, 1.0]) if info.world_up == "y_up" else np.array([0.0, 1.0, 0.0])
            world_d = d if info.acc_frame == "world" else np.einsum("nij,nj->ni", s.orientation[st].astype(np.float64), d)
            cos_decl, cos_other = float(np.median(world_d @ up)), float(np.median(world_d @ other))
            if cos_decl < 0.9 and cos_other > 0.97:
                issues.append(ConventionIssue(s.name, "orientation",
                                              f"at rest gravity's reaction points along the {other_name.replace('_', '-')} axis of the world, "
                                              f"not along the declared {info.world_up.replace('_', '-')} axis; orientations look like a "
                                              f"{other_name.replace('_', '-')} world",
                                              f"orientations in a {info.world_up.replace('_', '-')} world, or declare world_up '{other_name}'"))
    return issues
