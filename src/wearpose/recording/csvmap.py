"""Any CSV of sensor data with a YAML column map -> :class:`~wearpose.recording.Recording`.

The map says which columns hold what, in which unit and frame; the import *declares* those
conventions in each :class:`SensorInfo` (converted once by :meth:`Recording.to_canonical`) and
only rewrites what the recording format cannot declare: quaternions written w-last become
w-first, and orientations given world -> sensor are transposed (both recorded in
``meta["import"]``). A map (every key but ``sensors`` optional)::

    time: {column: t, unit: ms}        # s, ms, us or ns; or  rate: 100  (row k at k / rate s)
    delimiter: ","                     # default: sniffed from , ; tab
    world_up: z_up                     # y_up (default) or z_up, for every sensor
    sensors:
      left_wrist:                      # sensor name
        kind: imu                      # imu (default), mimu, em6dof, vio
        site: left_wrist               # a known body site, or leave out
        orientation: {columns: [qw, qx, qy, qz], order: wxyz, maps: sensor_to_world}
        acceleration: {columns: [ax, ay, az], unit: g, frame: sensor, gravity: included}
        angular_velocity: {columns: [gx, gy, gz], unit: deg/s}
        magnetic_field: {columns: [mx, my, mz], unit: uT}
        position: {columns: [x, y, z], unit: mm}
        valid: {column: ok}            # optional: rows where it is 0 are masked

``order``: ``wxyz`` (w first) or ``xyzw`` (w last); ``maps``: ``sensor_to_world`` (``R_WS``,
default) or ``world_to_sensor``; ``frame``: ``world`` or ``sensor``; ``gravity``: ``removed``
or ``included``; units as :class:`SensorInfo` takes them. An empty or ``nan`` cell masks that
sensor's row (a lost sample, never filled); other text is an error naming the row and column. A gap in the time column longer
than 1.5 periods holds lost samples: masked slots at their nominal times.
"""

from __future__ import annotations

import csv
import difflib
import io
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.errors import InputFileError
from wearpose.recording.devicelog import device_row, sample_grid
from wearpose.recording.types import KINDS, Recording, SensorInfo, SensorStream, _Problem, quaternions_to_matrices

TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
_CHANNEL_KEYS: dict[str, set[str]] = {
    "orientation": {"columns", "order", "maps"},
    "acceleration": {"columns", "unit", "frame", "gravity"},
    "angular_velocity": {"columns", "unit"},
    "magnetic_field": {"columns", "unit"},
    "position": {"columns", "unit"},
}
_SENSOR_KEYS = {"kind", "site", "rate", "world_up", "valid", *_CHANNEL_KEYS}
_TOP_KEYS = {"time", "rate", "delimiter", "world_up", "sensors"}
_MAP_FORM = "a YAML column map (docs/devices.md, 'Any CSV with a column map'): sensors: {name: {orientation: {columns: [...]}, ...}}"


class _MapError(Exception):
    def __init__(self, field: str, problem: str, expected: str):
        super().__init__(problem)
        self.field, self.problem, self.expected = field, problem, expected


def load_column_map(path: str | Path) -> dict[str, Any]:
    """Read and check a column map (the YAML above).

    Raises:
        InputFileError: naming the map file, the key (``sensors/left_wrist/acceleration/unit``),
            the problem and the allowed values.
    """
    import yaml  # start-up: yaml adds ~20 ms to import wearpose.recording

    path = Path(path)
    try:
        d = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, f"cannot be read ({exc})", _MAP_FORM) from None
    except yaml.YAMLError as exc:
        raise InputFileError(path, f"not valid YAML ({str(exc).splitlines()[0]})", _MAP_FORM) from None
    try:
        _check_map(d)
    except _MapError as e:
        raise InputFileError(path, e.problem, e.expected, field=e.field) from None
    return d


def _unknown(d: dict[str, Any], allowed: set[str], where: str) -> None:
    bad = sorted(set(d) - allowed)
    if bad:
        near = difflib.get_close_matches(bad[0], sorted(allowed), n=1)
        raise _MapError(f"{where}{bad[0]}", f"unknown key {bad[0]!r}" + (f" (did you mean {near[0]!r}?)" if near else ""),
                        f"one of {', '.join(sorted(allowed))}")


def _choice(d: dict[str, Any], key: str, choices: tuple[str, ...], where: str) -> None:
    if key in d and d[key] not in choices:
        raise _MapError(f"{where}{key}", f"value {d[key]!r}", f"one of {', '.join(choices)}")


def _check_map(d: Any) -> None:
    if not isinstance(d, dict):
        raise _MapError("", f"the map is a {type(d).__name__}", _MAP_FORM)
    _unknown(d, _TOP_KEYS, "")
    if ("time" in d) == ("rate" in d):
        raise _MapError("time", "both time and rate" if "time" in d else "neither time nor rate",
                        "either time: {column: NAME, unit: s|ms|us|ns} or rate: HZ (rows one sample apart)")
    if "time" in d:
        t = d["time"]
        if not isinstance(t, dict) or not isinstance(t.get("column"), str):
            raise _MapError("time", f"value {t!r}", "{column: NAME, unit: s|ms|us|ns}")
        _unknown(t, {"column", "unit"}, "time/")
        _choice(t, "unit", tuple(TIME_UNITS), "time/")
    elif not (isinstance(d["rate"], (int, float)) and not isinstance(d["rate"], bool) and d["rate"] > 0):
        raise _MapError("rate", f"value {d['rate']!r}", "a positive rate in Hz")
    _choice(d, "world_up", ("y_up", "z_up"), "")
    sensors = d.get("sensors")
    if not isinstance(sensors, dict) or not sensors:
        raise _MapError("sensors", "missing or empty", "sensors: {name: {channel: {columns: [...]}}}")
    for name, s in sensors.items():
        where = f"sensors/{name}/"
        if not isinstance(s, dict):
            raise _MapError(where.rstrip("/"), f"value {s!r}", "a mapping of channels")
        _unknown(s, _SENSOR_KEYS, where)
        _choice(s, "kind", KINDS, where)
        _choice(s, "world_up", ("y_up", "z_up"), where)
        for ch, keys in _CHANNEL_KEYS.items():
            if ch not in s:
                continue
            c = s[ch]
            if not isinstance(c, dict):
                raise _MapError(f"{where}{ch}", f"value {c!r}", "{columns: [...], ...}")
            _unknown(c, keys, f"{where}{ch}/")
            n = 4 if ch == "orientation" else 3
            cols = c.get("columns")
            if not (isinstance(cols, list) and len(cols) == n and all(isinstance(x, str) for x in cols)):
                raise _MapError(f"{where}{ch}/columns", f"value {cols!r}", f"a list of {n} column names")
        o = s.get("orientation", {})
        _choice(o, "order", ("wxyz", "xyzw"), f"{where}orientation/")
        _choice(o, "maps", ("sensor_to_world", "world_to_sensor"), f"{where}orientation/")
        a = s.get("acceleration", {})
        _choice(a, "unit", ("m/s2", "g"), f"{where}acceleration/")
        _choice(a, "frame", ("world", "sensor"), f"{where}acceleration/")
        _choice(a, "gravity", ("removed", "included"), f"{where}acceleration/")
        _choice(s.get("angular_velocity", {}), "unit", ("rad/s", "deg/s"), f"{where}angular_velocity/")
        _choice(s.get("position", {}), "unit", ("m", "cm", "mm"), f"{where}position/")
        if "valid" in s and not (isinstance(s["valid"], dict) and isinstance(s["valid"].get("column"), str)):
            raise _MapError(f"{where}valid", f"value {s['valid']!r}", "{column: NAME} (0 = masked row)")


def _table(path: Path, delimiter: str | None) -> tuple[list[str], list[list[str]]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(path, f"not a readable text file ({exc})", "a CSV text file with one header line") from None
    if delimiter is None:
        try:
            delimiter = csv.Sniffer().sniff(text.split("\n", 1)[0], delimiters=",;\t").delimiter
        except csv.Error:
            delimiter = ","
    rows = [r for r in csv.reader(io.StringIO(text), delimiter=delimiter) if any(c.strip() for c in r)]
    if len(rows) < 3:
        raise InputFileError(path, f"{max(len(rows) - 1, 0)} data row(s)", "a header line and at least 2 rows")
    return [h.strip() for h in rows[0]], rows[1:]


def _columns(path: Path, header: list[str], rows: list[list[str]], names: list[str], map_field: str) -> np.ndarray:
    """``(N, len(names))`` floats; empty and ``nan`` cells are NaN (masked by the caller)."""
    out = np.full((len(rows), len(names)), np.nan)
    for k, name in enumerate(names):
        if name not in header:
            near = difflib.get_close_matches(name, header, n=3)
            raise InputFileError(path, f"no column {name!r} (asked for by the map's {map_field})"
                                 + (f"; did you mean {', '.join(map(repr, near))}?" if near else ""),
                                 f"one of the file's columns: {', '.join(header)}", field="header")
        j = header.index(name)
        for i, r in enumerate(rows):
            cell = r[j].strip() if j < len(r) else ""
            if cell and cell.lower() != "nan":
                try:
                    out[i, k] = float(cell)
                except ValueError:
                    raise InputFileError(path, f"line {i + 2} holds {cell[:30]!r}",
                                         "a number, or an empty cell / nan for a lost value", field=name) from None
    return out


def from_csv(path: str | Path, column_map: str | Path | dict[str, Any]) -> Recording:
    """Read a CSV with a column map (the map's form in the module doc).

    Args:
        path: the CSV (one header line, one row per sample).
        column_map: the YAML file, or a map already loaded (:func:`load_column_map`).

    Returns:
        One sensor per map entry, its conventions declared, ``meta["import"]`` the report
        (devices, rate, lost and masked samples, what was rewritten).

    Raises:
        InputFileError: a map key (the map file and key) or a CSV column (the CSV file and
            column, with the columns it has) that does not fit.
    """
    path = Path(path)
    map_path = Path(column_map) if not isinstance(column_map, dict) else None
    m = load_column_map(column_map) if map_path is not None else column_map
    if map_path is None:
        try:
            _check_map(m)
        except _MapError as e:
            raise InputFileError("<column map>", e.problem, e.expected, field=e.field) from None
    if not path.is_file():
        raise InputFileError(path, "file not found", "a CSV file")
    header, rows = _table(path, m.get("delimiter"))
    if "time" in m:
        col, unit = m["time"]["column"], m["time"].get("unit", "s")
        stamps = _columns(path, header, rows, [col], "time/column")[:, 0]
        slot, ts, rate = sample_grid(stamps, path, col, stamps[0], TIME_UNITS[unit])
        clock = f"{col} = {stamps[0]:g} {unit} at t = 0"
    else:
        rate = float(m["rate"])
        slot, ts = np.arange(len(rows)), np.arange(len(rows)) / rate
        clock = f"no time column: row k at k / {rate:g} s (lost rows cannot be seen)"
    K = len(ts)
    streams, found, rewritten = [], [], []
    for name, s in m["sensors"].items():
        stream, row, notes = _sensor(path, map_path or Path("<column map>"), str(name), s, m, header, rows, slot, ts, rate)
        streams.append(stream)
        found.append({**row, "clock_start": clock})
        rewritten += notes
    meta = {"source": "CSV with a column map", "source_file": str(path),
            "import": {"devices": found, "clock": clock, "rows": len(rows), "slots": K, "rewritten": rewritten,
                       **({"column_map": str(map_path)} if map_path is not None else {})}}
    return Recording(streams, meta=meta)


def _sensor(path: Path, map_path: Path, name: str, s: dict[str, Any], m: dict[str, Any], header: list[str], rows: list[list[str]],
            slot: np.ndarray, ts: np.ndarray, rate: float) -> tuple[SensorStream, dict[str, Any], list[str]]:
    K, N = len(ts), len(rows)
    ok = np.ones(N, bool)
    raw: dict[str, np.ndarray] = {}
    for ch in _CHANNEL_KEYS:
        if ch in s:
            raw[ch] = _columns(path, header, rows, s[ch]["columns"], f"sensors/{name}/{ch}/columns")
            ok &= np.isfinite(raw[ch]).all(1)
    if not raw:
        raise InputFileError(map_path, f"sensor {name!r} maps no channel", "at least one of " + ", ".join(_CHANNEL_KEYS),
                             field=f"sensors/{name}")
    if "valid" in s:
        v = _columns(path, header, rows, [s["valid"]["column"]], f"sensors/{name}/valid/column")[:, 0]
        ok &= np.nan_to_num(v) != 0
    valid = np.zeros(K, bool)
    valid[slot] = ok
    notes = []
    full = {}
    for ch, a in raw.items():
        b = np.full((K, a.shape[1]), np.nan)
        b[slot[ok]] = a[ok]
        full[ch] = b
    ch_out: dict[str, np.ndarray] = {}
    if "orientation" in full:
        q = full["orientation"]
        o = s["orientation"]
        if o.get("order", "wxyz") == "xyzw":
            q = q[:, [3, 0, 1, 2]]
            notes.append(f"{name}: quaternions read w-last (map: order xyzw), stored w-first")
        try:
            R = quaternions_to_matrices(q, f"{', '.join(o['columns'])} (row = slot)", valid)
        except _Problem as p:
            raise InputFileError(path, f"sensor {name!r}: {p.problem}", p.expected + "; check the map's order (wxyz or xyzw)",
                                 field=p.field) from None
        if o.get("maps", "sensor_to_world") == "world_to_sensor":
            R = np.swapaxes(R, -1, -2)
            notes.append(f"{name}: orientations given world -> sensor (map: maps world_to_sensor), stored sensor -> world")
        ch_out["orientation"] = R
    for ch in ("acceleration", "angular_velocity", "magnetic_field", "position"):
        if ch in full:
            ch_out[ch] = full[ch]
    acc = s.get("acceleration", {})
    kind = s.get("kind", "imu" if {"orientation", "acceleration"} <= set(full) else
                 "mimu" if {"acceleration", "angular_velocity", "magnetic_field"} <= set(full) else
                 "em6dof" if {"position", "orientation"} <= set(full) else "imu")
    try:
        info = SensorInfo(name, kind, site=s.get("site"), rate=float(s.get("rate", rate)),
                          acc_unit=acc.get("unit", "m/s2"), acc_frame=acc.get("frame", "world"),
                          acc_gravity=acc.get("gravity", "removed"), world_up=s.get("world_up", m.get("world_up", "y_up")),
                          position_unit=s.get("position", {}).get("unit", "m"),
                          gyro_unit=s.get("angular_velocity", {}).get("unit", "rad/s"),
                          mag_unit=str(s.get("magnetic_field", {}).get("unit", "a.u.")))
        stream = SensorStream(info, ts, valid, **{k: v.astype(np.float32) for k, v in ch_out.items()})
    except Exception as exc:  # noqa: BLE001 - ShapeError from the recording's own checks
        raise InputFileError(map_path, f"sensor {name!r}: {exc}", "a kind whose channels the map gives "
                             "(docs/formats.md: imu needs orientation + acceleration)", field=f"sensors/{name}") from None
    return stream, device_row(stream, name, int(len(slot)), ""), notes
