"""What every device-file importer shares: the device's own sample grid (a lost sample is a
masked slot, never filled), the clock rule for several devices, names and body sites, and the
per-device report each import puts in ``meta["import"]["devices"]``.

Used by :func:`wearpose.recording.from_ximu3`, :func:`~wearpose.recording.from_mvnx`,
:func:`~wearpose.recording.from_movella_dot` and :func:`~wearpose.recording.from_csv`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.errors import InputFileError
from wearpose.recording.types import SensorStream, known_sites

#: Devices whose first samples lie further apart than this (seconds) do not share a clock.
SHARED_CLOCK_S = 1.0


def sample_grid(stamps: np.ndarray, path: Path, field: str, t0: float, to_s: float = 1.0,
                row_offset: int = 2) -> tuple[np.ndarray, np.ndarray, float]:
    """Slots on a device's nominal sample grid.

    Args:
        stamps: ``(N,)`` the device's sample times in file units (``to_s`` seconds each).
        path, field: the file and its time column, named in errors.
        t0: the clock's zero, file units (the earliest first sample of a shared clock, or
            this device's own first sample).
        to_s: seconds per file unit (1e-6 for microseconds).
        row_offset: file line of ``stamps[0]`` (errors name the line).

    Returns:
        ``(slot (N,) int: each sample's slot, timestamps (K,) s: one per slot, rate Hz)``. The
        period is the median step; a sample keeps its own stamp, a lost sample (a gap of more
        than half a period beyond the next slot) gets a slot at its nominal time, masked by the
        caller.

    Raises:
        InputFileError: a stamp not after the one before, or two samples in one period.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.size < 2:
        raise InputFileError(path, f"{stamps.size} sample(s)", "at least 2 samples (a rate needs two)", field=field)
    dt = np.diff(stamps)
    if not np.all(np.isfinite(stamps)):
        i = int(np.flatnonzero(~np.isfinite(stamps))[0]) + row_offset
        raise InputFileError(path, f"the time on line {i} is not a number", "a time on every row", field=field)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + row_offset + 1
        raise InputFileError(path, f"the timestamp on line {i} is not after the one before",
                             "increasing timestamps (one row per sample, in time order)", field=field)
    period = float(np.median(dt))
    slot = np.round((stamps - stamps[0]) / period).astype(np.int64)
    if np.any(np.diff(slot) < 1):
        i = int(np.flatnonzero(np.diff(slot) < 1)[0]) + row_offset + 1
        raise InputFileError(path, f"two samples fall in one sample period (line {i})",
                             "one sample per period of the device's rate", field=field)
    ts = (stamps[0] - t0 + np.arange(slot[-1] + 1) * period) * to_s
    ts[slot] = (stamps - t0) * to_s
    return slot, ts, 1.0 / (period * to_s)


def shared_clock(starts_s: list[float]) -> bool:
    """Whether devices whose first samples are at ``starts_s`` (seconds, each device's own
    stamp) are taken to share one clock (:data:`SHARED_CLOCK_S`)."""
    return max(starts_s) - min(starts_s) <= SHARED_CLOCK_S


def clock_note(shared: bool) -> str:
    return ("shared device clock, t = 0 at the earliest first sample" if shared else
            "device clocks differ: each device's t = 0 at its own first sample")


def sensor_key(name: str) -> str:
    """A device or segment name as a sensor name: ``"Left Lower Leg"`` / ``"LeftLowerLeg"`` ->
    ``left_lower_leg`` (at most 64 characters of ``[a-z0-9_]``)."""
    s = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name.strip())
    s = re.sub(r"[^a-z0-9]+", "_", s.lower()).strip("_")
    return (s or "sensor")[:64]


def site_or_none(name: str) -> str | None:
    """``name`` when it is a known body site (:func:`wearpose.recording.types.known_sites`)."""
    return name if name in known_sites() else None


def device_row(stream: SensorStream, device: str, samples: int, clock_start: str, **extra: Any) -> dict[str, Any]:
    """The import report of one device (JSON): name, samples in the file, slots on its grid,
    ``lost`` (slots with no sample), ``masked`` (every invalid slot: lost or unusable values),
    rate, the units and frames declared, and where its clock started."""
    info = stream.info
    channels = stream.channels()
    units: dict[str, str] = {}
    if "acceleration" in channels:
        units["acceleration"] = f"{info.acc_unit}, {info.acc_frame} frame, gravity {info.acc_gravity}"
    if "angular_velocity" in channels:
        units["angular_velocity"] = f"{info.gyro_unit}, sensor frame"
    if "magnetic_field" in channels:
        units["magnetic_field"] = f"{info.mag_unit}, sensor frame"
    if "position" in channels:
        units["position"] = info.position_unit
    if "orientation" in channels or "position" in channels:
        units["world"] = info.world_up
    slots = stream.num_frames
    return {"device": device, "sensor": info.name, "site": info.site, "samples": int(samples), "slots": int(slots),
            "lost": int(slots - samples), "masked": int((~stream.valid).sum()), "rate_hz": round(float(info.rate), 4),
            "units": units, "clock_start": clock_start, **extra}
