"""Movella (Xsens) DOT CSV exports -> :class:`~wearpose.recording.Recording`.

Layout relied on (the Movella DOT app's and SDK's export, Movella DOT User Manual XD0502P,
"Data export" and "Output data"; the column names as in exported files seen in public code):

- optional metadata lines before the header (``Device tag: ...``, ``Firmware Version: ...``,
  ``Filter profile: ...``, ``DeviceTag:,3``), then one header line starting ``PacketCounter``
  and one row per sample; trailing commas and empty cells occur;
- ``PacketCounter``: the sample counter; ``SampleTimeFine``: the sensor's clock, microseconds,
  unsigned 32 bit (wraps after 2^32 us, about 71.6 min: unwrapped here);
- ``Quat_W, Quat_X, Quat_Y, Quat_Z``: orientation, sensor -> local Earth frame East-North-Up
  (Z up), real part first;
- ``FreeAcc_X/Y/Z``: free acceleration, m/s^2, in that Earth frame, gravity removed;
- ``Acc_X/Y/Z``: the calibrated accelerometer reading, m/s^2, sensor frame (gravity included);
- ``Gyr_X/Y/Z``: angular velocity, deg/s, sensor frame; ``Mag_X/Y/Z``: magnetic field, sensor
  frame, arbitrary units; ``Euler_X/Y/Z`` (deg), ``dq_*``, ``dv[*]``, ``Status``: not imported.

One CSV per sensor; a folder of them (one export session) is one recording. Each sensor keeps its
own clock and rate; sensors whose first samples lie within 1 s share one clock (synchronised DOTs
do), otherwise each starts at 0 (:mod:`wearpose.recording.devicelog`). A lost sample (a gap in
``SampleTimeFine``) or a row with an empty cell is a masked slot, never filled. The conventions
are declared (``world_up="z_up"``, free acceleration in the world frame, or the sensor-frame
reading with gravity when only ``Acc`` is exported, ``gyro_unit="deg/s"``) and converted once by
:meth:`Recording.to_canonical`.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.errors import InputFileError
from wearpose.recording.devicelog import clock_note, device_row, sample_grid, sensor_key, shared_clock, site_or_none
from wearpose.recording.types import Recording, SensorInfo, SensorStream, _Problem, quaternions_to_matrices

_EXPECTED = ("a Movella DOT CSV export: optional 'key: value' lines, a header 'PacketCounter,SampleTimeFine,...' "
             "with Quat_W..Quat_Z and FreeAcc_X..Z (or Acc_X..Z) columns, one row per sample")
_GROUPS: dict[str, tuple[str, ...]] = {
    "quat": ("Quat_W", "Quat_X", "Quat_Y", "Quat_Z"),
    "free": ("FreeAcc_X", "FreeAcc_Y", "FreeAcc_Z"),
    "acc": ("Acc_X", "Acc_Y", "Acc_Z"),
    "gyr": ("Gyr_X", "Gyr_Y", "Gyr_Z"),
    "mag": ("Mag_X", "Mag_Y", "Mag_Z"),
}
_WRAP_US = 2.0 ** 32


def _read_csv(path: Path) -> tuple[dict[str, str], list[str], list[list[str]], int]:
    """``(metadata, header, rows, line number of the header)``."""
    try:
        lines = path.read_text(encoding="utf-8-sig", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, f"not a readable text file ({exc})", _EXPECTED) from None
    head = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith("PacketCounter")), None)
    if head is None:
        raise InputFileError(path, "no header line starting with 'PacketCounter'", _EXPECTED, field="header")
    meta: dict[str, str] = {}
    for ln in lines[:head]:
        m = re.match(r"\s*([^:,]+?)\s*:\s*,?\s*(.*?)\s*,*\s*$", ln)
        if m:
            meta[m.group(1).strip().lower()] = m.group(2)
    table = list(csv.reader(lines[head:]))
    header = [h.strip() for h in table[0]]
    while header and header[-1] == "":  # trailing commas
        header.pop()
    return meta, header, [r for r in table[1:] if any(c.strip() for c in r)], head + 1


def _column(path: Path, header: list[str], rows: list[list[str]], name: str, head_line: int) -> np.ndarray:
    j = header.index(name)
    out = np.full(len(rows), np.nan)
    for i, r in enumerate(rows):
        cell = r[j].strip() if j < len(r) else ""
        if cell:
            try:
                out[i] = float(cell)
            except ValueError:
                raise InputFileError(path, f"line {head_line + 1 + i} holds {cell[:30]!r}", "a number (or an empty cell for a lost value)",
                                     field=name) from None
    return out


def _device(path: Path, t0_us: float | None) -> tuple[SensorStream, dict[str, Any]]:
    meta, header, rows, head_line = _read_csv(path)
    if "SampleTimeFine" not in header:
        raise InputFileError(path, f"no SampleTimeFine column (columns: {', '.join(header)})",
                             "the sensor clock column SampleTimeFine (microseconds): export it with the data", field="header")
    missing = [c for c in _GROUPS["quat"] if c not in header]
    if missing:
        has_euler = "Euler_X" in header
        raise InputFileError(path, f"no {', '.join(missing)} column{'s' if len(missing) > 1 else ''}"
                             + (" (only Euler angles)" if has_euler else ""),
                             "quaternion orientation: export with the 'Quaternion' (or 'Orientation (Quaternion)') "
                             "output selected; Euler angles are not read (their sequence is ambiguous)", field="header")
    acc_group = "free" if all(c in header for c in _GROUPS["free"]) else "acc" if all(c in header for c in _GROUPS["acc"]) else None
    if acc_group is None:
        raise InputFileError(path, "no FreeAcc_X..Z or Acc_X..Z columns", "free acceleration (FreeAcc_*) or the accelerometer "
                             "reading (Acc_*): export one of them", field="header")
    stamps = _column(path, header, rows, "SampleTimeFine", head_line)
    have_t = np.isfinite(stamps)
    # A row without its time cannot be placed on the clock: counted in the report, not guessed.
    rows = [r for r, ok in zip(rows, have_t) if ok]
    stamps = stamps[have_t]
    wraps = np.concatenate([[0], np.cumsum(np.diff(stamps) < -_WRAP_US / 2)])
    stamps = stamps + wraps * _WRAP_US
    t0 = stamps[0] if t0_us is None else t0_us
    slot, ts, rate = sample_grid(stamps, path, "SampleTimeFine", t0, 1e-6, row_offset=head_line + 1)
    K = len(ts)
    got = {g: np.stack([_column(path, header, rows, c, head_line) for c in cols], 1)
           for g, cols in _GROUPS.items() if all(c in header for c in cols)}
    use = ["quat", acc_group] + [g for g in ("gyr", "mag") if g in got]
    ok_rows = np.all([np.isfinite(got[g]).all(1) for g in use], axis=0)
    valid = np.zeros(K, bool)
    valid[slot] = ok_rows
    full = {}
    for g in use:
        a = np.full((K, got[g].shape[1]), np.nan)
        a[slot[ok_rows]] = got[g][ok_rows]
        full[g] = a
    tag = meta.get("device tag") or meta.get("devicetag") or path.stem
    name = sensor_key(tag)
    info = SensorInfo(name, "imu", site=site_or_none(name), rate=rate, acc_unit="m/s2",
                      acc_frame="world" if acc_group == "free" else "sensor",
                      acc_gravity="removed" if acc_group == "free" else "included", world_up="z_up", gyro_unit="deg/s",
                      mag_unit="a.u.")
    try:
        R = quaternions_to_matrices(full["quat"], "Quat_W..Quat_Z", valid)
    except _Problem as p:
        raise InputFileError(path, p.problem, p.expected, field=p.field) from None
    ch = {"orientation": R.astype(np.float32), "acceleration": full[acc_group].astype(np.float32)}
    if "gyr" in full:
        ch["angular_velocity"] = full["gyr"].astype(np.float32)
    if "mag" in full:
        ch["magnetic_field"] = full["mag"].astype(np.float32)
    try:
        stream = SensorStream(info, ts, valid, **ch)
    except Exception as exc:  # noqa: BLE001 - ShapeError from validation, named on the file
        raise InputFileError(path, f"sensor {name!r}: {exc}", "valid sensor data") from None
    found = device_row(stream, tag, len(slot), f"SampleTimeFine {int(stamps[0])} us", file=path.name,
                       empty_cell_rows=int((~ok_rows).sum()), rows_without_time=int((~have_t).sum()), clock_wraps=int(wraps[-1]),
                       acceleration_columns="FreeAcc_*" if acc_group == "free" else "Acc_*",
                       firmware=meta.get("firmware version"), filter_profile=meta.get("filter profile"))
    return stream, found


def _first_stamp_us(path: Path) -> float:
    meta, header, rows, head_line = _read_csv(path)
    if "SampleTimeFine" not in header or not rows:
        return 0.0  # the full read of this file names the problem
    t = _column(path, header, rows[:50], "SampleTimeFine", head_line)
    t = t[np.isfinite(t)]
    return float(t[0]) if t.size else 0.0


def movella_files(path: Path) -> list[Path]:
    """The CSV exports of one session: ``path`` itself, or the ``*.csv`` files in the folder."""
    return [path] if path.is_file() else sorted(p for p in path.glob("*.csv") if p.is_file())


def from_movella_dot(path: str | Path) -> Recording:
    """A Movella DOT CSV export, or a folder of them (one file per sensor) -> a recording of
    kind-``imu`` sensors (layout and conventions in the module doc). A sensor is named after its
    ``Device tag`` line (else the file name) and gets that name as its site when it is a known
    body site (``left_shin``), else no site.

    Raises:
        InputFileError: no CSV, no header, missing quaternion or acceleration columns, a time
            that goes back (the file, the column, the fix).
    """
    root = Path(path)
    files = movella_files(root) if root.exists() else []
    if not files:
        raise InputFileError(root, "no Movella DOT CSV files", "a .csv export or a folder of them (one per sensor)")
    starts = [_first_stamp_us(f) for f in files]
    shared = shared_clock([s * 1e-6 for s in starts])
    streams, found = zip(*(_device(f, min(starts) if shared else None) for f in files))
    names = [s.info.name for s in streams]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputFileError(root, f"two files are both sensor {dup}", "one device tag per sensor (rename the tag in the "
                             "Movella DOT app, or the files when they carry no 'Device tag' line)")
    meta = {"source": "Movella DOT export", "path": str(root), "device": "Movella DOT",
            "import": {"devices": list(found), "clock": clock_note(shared)}}
    return Recording(list(streams), meta=meta)
