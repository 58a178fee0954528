"""Integer-factor decimation of a recording (e.g. 120 Hz sensors for weights trained at 30 Hz).

Why only integer factors: keeping every ``k``-th sample changes no value, so what an estimator
sees is still a measurement. Any other ratio needs interpolation (of orientations, of masked
frames...), which would invent data; wearpose refuses it with :class:`RecordingError` instead
of doing it silently (resample on the device side, or re-simulate at the rate).

How the validity mask is handled (explicitly, never filled): sample ``i * k`` of the input is
sample ``i`` of the output, *with its own* ``valid`` flag. A dropped frame that is kept stays
dropped (NaN, ``valid=False``); a dropped frame that is skipped disappears; a valid frame is never
replaced by a neighbour. No low-pass filter is applied (sensor channels are kept as measured;
``docs/formats.md`` says so): IMU accelerations synthesised the PIP/TransPose way are already
smoothed over 1/15 s, and EM poses are positions and rotations, not rates.
"""

from __future__ import annotations

import copy
from dataclasses import replace

from wearpose.recording.types import Recording, RecordingError, SensorStream

#: Two rates are "the same" / a ratio "is an integer" within this relative tolerance.
RATE_RTOL = 1e-3


def decimation_factor(rate_in: float, rate_out: float) -> int:
    """The integer ``k`` with ``rate_in = k * rate_out``.

    Raises:
        RecordingError: ``rate_out`` above ``rate_in`` (upsampling would interpolate) or a
            non-integer ratio, naming both rates and what to do instead.
    """
    if not (rate_in > 0 and rate_out > 0):
        raise RecordingError(f"rates must be > 0 Hz, got {rate_in!r} -> {rate_out!r}")
    ratio = float(rate_in) / float(rate_out)
    k = round(ratio)
    if k < 1 or abs(ratio - k) > RATE_RTOL * ratio:
        what = "upsampling" if ratio < 1 else f"a factor of {ratio:.4g}, not an integer"
        raise RecordingError(
            f"cannot resample {rate_in:g} Hz to {rate_out:g} Hz ({what}); wearpose only decimates by integer factors "
            "and never interpolates silently. Record or simulate at an integer multiple of the target rate "
            f"(e.g. `wearpose simulate --rate {rate_out:g}`), or resample on the device side")
    return int(k)


def _decimate_stream(s: SensorStream, k: int) -> SensorStream:
    ch = {name: (None if v is None else v[::k].copy()) for name, v in s.channels().items()}
    return SensorStream(replace(s.info, rate=float(s.info.rate) / k), s.timestamps[::k].copy(), s.valid[::k].copy(), **ch)


def decimate(recording: Recording, rate: float) -> Recording:
    """``recording`` with every sensor decimated to ``rate`` Hz (module doc).

    Args:
        recording: any recording; each sensor's nominal :attr:`SensorInfo.rate` must be an
            integer multiple of ``rate`` (sensors already at ``rate`` are kept as they are).
        rate: target rate, Hz.

    Returns:
        A new recording: sensor ``s`` keeps samples ``0, k_s, 2 k_s, ...`` (timestamps, values
        and ``valid`` flags as recorded) and declares ``rate``; ground truth, subject and other
        meta unchanged; ``meta["resampled"]`` lists ``{sensor: {"from_hz", "factor"}}`` for
        the sensors that changed.

    Raises:
        RecordingError: a sensor's rate is not an integer multiple of ``rate`` (names it).
    """
    out, changed = [], {}
    problems: dict[str, list[str]] = {}  # message -> sensors (12 sensors at one rate: one message)
    for s in recording.sensors:
        try:
            k = decimation_factor(float(s.info.rate), float(rate))
        except RecordingError as exc:
            problems.setdefault(str(exc), []).append(repr(s.name))
            continue
        out.append(copy.deepcopy(s) if k == 1 else _decimate_stream(s, k))
        if k > 1:
            changed[s.name] = {"from_hz": float(s.info.rate), "factor": k}
    if problems:
        raise RecordingError("; ".join(f"sensor{'s' if len(n) > 1 else ''} {', '.join(n)}: {msg}"
                                       for msg, n in problems.items()))
    meta = copy.deepcopy(recording.meta)
    if changed:
        meta["resampled"] = {**meta.get("resampled", {}), **changed}
    return Recording(out, recording.ground_truth, recording.ground_truth_start, copy.deepcopy(recording.subject), meta,
                     recording.origin)
