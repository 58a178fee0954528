"""``wearpose recording import``: turn public real-sensor dataset files (DIP-IMU, TotalCapture,
EM-POSE) and device files (x-IMU3 logs, Xsens MVNX, Movella DOT exports, any CSV with a column
map) into wearpose Recording ``.npz`` files.

Thin: collects files, calls the converters of :mod:`wearpose.recording.converters` and
:func:`wearpose.recording.save_recording`, and prints a per-file report (frames, sensors, rate,
valid share). A file a converter refuses is reported with the converter's one-line error and the
others are converted (exit code 1 if any failed), like ``wearpose data prepare``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich.markup import escape
from rich.table import Table

from wearpose.cli.app import _emit, app, console, err_console, error_text
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from wearpose.errors import InputFileError
from wearpose.errors import WearposeError

recording_app = typer.Typer(help="Import real sensor recordings: public datasets (DIP-IMU, TotalCapture, EM-POSE) "
                                 "and device files (x-IMU3 logs, Xsens MVNX, Movella DOT CSV, any CSV with a column map).\n\n"
                                 "Example: wearpose recording import dip-imu DIP_IMU/s_09 --out recordings/",
                            no_args_is_help=True)
app.add_typer(recording_app, name="recording")

#: FORMAT -> (file-name suffixes searched in folders, what a file looks like).
FORMATS: dict[str, tuple[tuple[str, ...], str]] = {
    "dip-imu": ((".pkl",), "DIP-IMU .pkl (imu_ori, imu_acc, gt)"),
    "totalcapture": ((".sensors",), "TotalCapture *_Xsens.sensors / *_Xsens_AuxFields.sensors"),
    "empose": (("_clean.npz",), "EM-POSE *_clean.npz"),
    # a log folder, not a file: one sub-folder per device (Inertial.csv, Quaternion.csv, Command.json)
    "ximu3": ((), "x-IMU3 log folder (device sub-folders with Inertial.csv, Quaternion.csv)"),
    "mvnx": ((".mvnx",), "Xsens MVNX (.mvnx)"),
    # a CSV file, or a folder of one session's CSVs (one per sensor) -> one recording
    "movella-dot": ((), "Movella DOT CSV export (a .csv or a folder of them, one per sensor)"),
    "csv": ((".csv",), "CSV with a --map column map"),
}
#: Formats whose import runs the convention checks (what load_recording would refuse is
#: refused at import, naming the declaration to fix, and nothing is written).
CHECKED_FORMATS = ("mvnx", "movella-dot", "csv")


def _parse_sensors(fmt: str, sensors: str | None) -> Any:
    """``--sensors`` as the converter takes it: 'six'/'all'/indices (DIP-IMU, EM-POSE) or
    TotalCapture sensor names. Checked once, before any file is read."""
    if sensors is None:
        return None
    items = [s.strip() for s in sensors.split(",") if s.strip()]
    if fmt == "totalcapture":
        if not items:
            raise typer.BadParameter("empty list; expected TotalCapture sensor names, e.g. Head,Pelvis", param_hint="--sensors")
        return items
    if sensors.strip() in ("six", "all"):
        return sensors.strip()
    n = 17 if fmt == "dip-imu" else 12
    try:
        idx = [int(s) for s in items]
    except ValueError:
        idx = []
    if not idx or any(not 0 <= i < n for i in idx):
        raise typer.BadParameter(f"{sensors!r}; expected 'six', 'all' or comma-separated indices in [0, {n})",
                                 param_hint="--sensors")
    return idx


def _converter(fmt: str, sensors: Any, fps: float | None, ground_truth: bool,
               column_map: Path | None = None) -> Callable[[Path], Any]:
    """One-argument converter with the options bound (options left unset keep the converter's default)."""
    # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help
    from wearpose.recording import (
        from_csv, from_dip_imu, from_empose, from_movella_dot, from_mvnx, from_totalcapture, from_ximu3, load_column_map,
    )

    if (column_map is not None) != (fmt == "csv"):
        raise typer.BadParameter("csv needs --map FILE (the YAML column map, docs/devices.md); other formats take none",
                                 param_hint="--map")
    if fmt in ("ximu3", "mvnx", "movella-dot", "csv"):
        if sensors is not None or fps is not None:
            raise typer.BadParameter(f"{fmt} takes every device at its own rate and every sensor; leave out --sensors and --fps",
                                     param_hint="--sensors/--fps")
        if fmt == "csv":
            load_column_map(column_map)  # checked once, before any file: InputFileError naming the map's key
            return lambda p: from_csv(p, column_map)
        if fmt == "mvnx":
            return lambda p: from_mvnx(p, with_ground_truth=ground_truth)
        return {"ximu3": from_ximu3, "movella-dot": from_movella_dot}[fmt]
    kw: dict[str, Any] = {}
    if sensors is not None:
        kw["sensors"] = sensors
    if fps is not None:
        kw["fps"] = fps
    if fmt != "totalcapture":
        kw["with_ground_truth"] = ground_truth
    fn = {"dip-imu": from_dip_imu, "totalcapture": from_totalcapture, "empose": from_empose}[fmt]
    return lambda p: fn(p, **kw)


def _collect(fmt: str, paths: list[Path]) -> list[tuple[Path, Path]]:
    """``(input file, output path relative to --out)``: files as given, folders searched
    recursively for the format's files (their layout kept, e.g. ``s_09/01.npz``)."""
    if fmt == "ximu3":
        return _collect_logs(paths)
    if fmt == "movella-dot":
        return _collect_sessions(paths)
    suffixes = FORMATS[fmt][0]
    found: list[tuple[Path, Path]] = []
    for p in paths:
        if p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file() and f.name.endswith(suffixes))
            found += [(f, f.relative_to(p).with_suffix(".npz")) for f in files]
        else:
            found.append((p, Path(p.name).with_suffix(".npz")))
    seen: set[Path] = set()
    out: list[tuple[Path, Path]] = []
    for f, rel in found:
        if rel in seen:  # e.g. DIP-IMU's s_09/01.pkl and s_10/01.pkl given as files: keep the subject
            rel = rel.with_name(f"{f.parent.name}_{rel.name}")
        seen.add(rel)
        out.append((f, rel))
    return out


def _collect_logs(paths: list[Path]) -> list[tuple[Path, Path]]:
    """x-IMU3 log folders (a folder with device sub-folders holding Inertial.csv) as given or
    below the given folders, each -> ``<log folder name>.npz``."""
    def is_log(d: Path) -> bool:
        return d.is_dir() and any((c / "Inertial.csv").is_file() for c in d.iterdir() if c.is_dir())

    logs: list[Path] = []
    for p in paths:
        logs += [p] if is_log(p) else sorted(d for d in p.rglob("*") if is_log(d))
    return [(d, Path(d.name).with_suffix(".npz")) for d in logs]


def _collect_sessions(paths: list[Path]) -> list[tuple[Path, Path]]:
    """Movella DOT exports: a CSV given as a file is one recording (``<stem>.npz``); a folder
    holding CSVs is one session (``<folder>.npz``), and so is every folder below it that holds some."""
    out: list[tuple[Path, Path]] = []
    for p in paths:
        if p.is_file():
            out.append((p, Path(p.name).with_suffix(".npz")))
            continue
        for d in [p] + sorted(x for x in p.rglob("*") if x.is_dir()):
            if any(f.suffix.lower() == ".csv" for f in d.iterdir() if f.is_file()):
                out.append((d, Path(d.name).with_suffix(".npz")))
    return out


def _summary(rec: Any) -> dict[str, Any]:
    """Frames, sensors, rate and valid share of one converted recording."""
    import numpy as np  # start-up: numpy adds ~81 ms to wearpose --help

    valid = np.concatenate([s.valid for s in rec.sensors]) if rec.sensors else np.zeros(0, bool)
    rates = sorted({float(s.info.rate) for s in rec.sensors if s.info.rate})
    return {"frames": max((s.num_frames for s in rec.sensors), default=0), "sensors": len(rec.sensors),
            "sensor_names": list(rec.names), "kinds": sorted(set(rec.kinds)),
            "rate_hz": rates[0] if len(rates) == 1 else rates,
            "valid_pct": round(100.0 * float(valid.mean()), 2) if valid.size else 0.0,
            "ground_truth": rec.ground_truth is not None,
            **({"devices": rec.meta["import"]["devices"]} if "devices" in (rec.meta or {}).get("import", {}) else {}),
            "import_notes": [f"{k.replace('_', ' ')}: {'; '.join(v) if isinstance(v, list) else v}"
                             for k, v in (rec.meta or {}).get("import", {}).items()
                             if k in ("clock", "ground_truth", "rewritten") and v]}


def import_recordings(fmt: str, files: list[tuple[Path, Path]], out: Path, convert: Callable[[Path], Any],
                      on_file: Callable[[Path], None] | None = None) -> dict[str, Any]:
    """Convert and save each file; a file that fails is recorded with its error line, the others go on."""
    from wearpose.recording import save_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    rows: list[dict[str, Any]] = []
    for f, rel in files:
        dest = out / rel
        try:
            if dest.resolve() == f.resolve():
                raise WearposeError(f"{f}: the output would overwrite the input file; choose another --out")
            rec = convert(f)
            if fmt in CHECKED_FORMATS:
                _check_conventions(f, rec)
            dest.parent.mkdir(parents=True, exist_ok=True)
            save_recording(rec, dest)
            rows.append({"file": str(f), "ok": True, "out": str(dest), **_summary(rec)})
        except (WearposeError, OSError) as exc:
            msg = error_text(exc)
            rows.append({"file": str(f), "ok": False, "error": msg if str(f) in msg else f"{f}: {msg}"})
        if on_file is not None:
            on_file(f)
    failed = sum(not r["ok"] for r in rows)
    return {"format": fmt, "out": str(out), "converted": len(rows) - failed, "failed": failed, "files": rows}


def _check_conventions(f: Path, rec: Any) -> None:
    """Refuse what :func:`wearpose.recording.load_recording` would refuse, before writing: the
    data does not look like its declared units or frames (every suspicion about the first field)."""
    from wearpose.recording import check_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    issues = check_recording(rec.sensors)
    if issues:
        first = issues[0]
        same = [i for i in issues if (i.sensor, i.field) == (first.sensor, first.field)]
        raise InputFileError(f, "convention check: " + "; ".join(i.problem for i in same),
                             "; ".join(i.expected for i in same) + " (for csv: in the column map)",
                             field=f"sensors/{first.sensor}/{first.field}")


def _report_table(res: dict[str, Any]) -> Table:
    t = Table(title=f"recording import ({res['format']}) -> {res['out']}: {res['converted']} converted, {res['failed']} failed")
    for c in ("file", "frames", "sensors", "rate (Hz)", "valid %", "ground truth", "status"):
        t.add_column(c, justify="right" if c in ("frames", "sensors", "rate (Hz)", "valid %") else "left", overflow="fold")
    for r in res["files"]:
        name = escape(Path(r["file"]).name)
        if not r["ok"]:
            t.add_row(name, "", "", "", "", "", "[red]failed[/]")
            continue
        rate = r["rate_hz"] if isinstance(r["rate_hz"], list) else [r["rate_hz"]]
        t.add_row(name, str(r["frames"]), str(r["sensors"]), "/".join(f"{x:g}" for x in rate), f"{r['valid_pct']:.1f}",
                  "yes" if r["ground_truth"] else "no", "[green]ok[/]")
    return t


def _short_units(units: dict[str, str]) -> str:
    """The declared units of one device in a few words: ``acc g sensor +grav, gyro deg/s, z_up``."""
    short = {"acceleration": "acc", "angular_velocity": "gyro", "magnetic_field": "mag", "position": "pos", "world": ""}
    parts = []
    for k, v in units.items():
        v = v.replace(" frame", "").replace("gravity included", "+grav").replace("gravity removed", "-grav")
        v = v.replace(", sensor", "") if k in ("angular_velocity", "magnetic_field") else v
        parts.append(f"{short.get(k, k)} {v.replace(',', '')}".strip())
    return ", ".join(parts) or "-"


def _device_table(row: dict[str, Any]) -> Table:
    """Per device of a device file: rate, samples, lost samples and every masked slot (masked,
    never filled), the units and frames declared, where its clock started."""
    t = Table(title=f"devices of {escape(Path(row['file']).name)}")
    for c in ("device", "rate (Hz)", "samples", "lost", "masked", "units declared", "clock start"):
        t.add_column(c, justify="right" if c in ("rate (Hz)", "samples", "lost", "masked") else "left", overflow="fold")
    for d in row["devices"]:
        units = _short_units(d.get("units", {}))
        clock = d.get("clock_start") or (f"{d['clock_start_us']} us" if "clock_start_us" in d else "-")
        t.add_row(escape(str(d["device"])), f"{d['rate_hz']:.2f}", str(d["samples"]), str(d["lost"]),
                  str(d.get("masked", d["lost"])), escape(units), escape(str(clock)))
    return t


@recording_app.command("import")
def recording_import(
    fmt: str = typer.Argument(..., metavar="FORMAT", help="Source layout: dip-imu, totalcapture, empose, ximu3, mvnx, movella-dot or csv."),
    paths: list[Path] = typer.Argument(..., help="Dataset files or folders (searched recursively: *.pkl for dip-imu, *.sensors for totalcapture, *_clean.npz for empose, log folders for ximu3, *.mvnx for mvnx, *.csv for csv; movella-dot: a .csv, or a folder of one session's CSVs = one recording)."),
    out: Path = typer.Option(Path("recordings"), "--out", help="Output folder: one Recording .npz per input file (folder layout kept)."),
    sensors: Optional[str] = typer.Option(None, help="Sensors to keep. dip-imu: six (default), all or indices into the 17; "
                                                     "empose: all (default), six or indices into the 12; "
                                                     "totalcapture: comma-separated sensor names (default all), e.g. Head,Pelvis,L_LowArm."),
    fps: Optional[float] = typer.Option(None, help="Sample rate, Hz (default: the dataset's: DIP-IMU 60, TotalCapture 60, EM-POSE 30)."),
    ground_truth: bool = typer.Option(True, "--ground-truth/--no-ground-truth", help="Attach the dataset's SMPL reference (dip-imu, empose; mvnx: the segment kinematics)."),
    column_map: Optional[Path] = typer.Option(None, "--map", help="csv only: the YAML column map (names, units, quaternion order wxyz/xyzw, frames; docs/devices.md)."),
    as_json: bool = typer.Option(False, "--json", help="Print the per-file summary as JSON."),
) -> None:
    """Convert real sensor files of a public dataset to wearpose Recording .npz files.

    Each file is read by its converter (wearpose.recording.from_dip_imu / from_totalcapture /
    from_empose), which declares the dataset's units, frames, gravity and up axis (converted by
    Recording.to_canonical when used) and masks dropped frames without filling them. The report
    gives frames, sensors, rate and the share of valid sensor frames per file. A file that cannot
    be read is reported with the reason and the others are converted (exit code 1 if any failed).
    See docs/formats.md.

    Device files (ximu3, mvnx, movella-dot, csv) keep each device's own rate and clock; the
    report lists per device the rate, lost samples (masked), units declared and clock start,
    and mvnx, movella-dot and csv files are refused, naming the declaration to fix, when their
    data does not look like the declared units or frames (docs/devices.md).

    Example: wearpose recording import totalcapture TotalCapture/s1/ --out recordings/tc --sensors Head,Pelvis,L_LowArm,R_LowArm,L_LowLeg,R_LowLeg

    Example: wearpose recording import csv trial.csv --map columns.yaml --out recordings/
    """

    fmt = fmt.lower()
    if fmt not in FORMATS:
        raise typer.BadParameter(f"{fmt!r}; expected one of {', '.join(FORMATS)}", param_hint="FORMAT")
    parsed = _parse_sensors(fmt, sensors)
    if fps is not None and not fps > 0:
        raise typer.BadParameter(f"{fps}; expected a positive rate in Hz", param_hint="--fps")
    if out.suffix.lower() == ".npz" or out.is_file():
        # --out is a folder of one .npz per input file; a file name here used to become a folder of that name.
        raise typer.BadParameter(f"{out} is a file name, but --out is the folder that gets one Recording .npz per "
                                 f"input file; give a folder, e.g. --out {out.with_suffix('') if out.suffix else out.parent / 'recordings'}",
                                 param_hint="--out")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise typer.BadParameter(f"no such file or folder: {', '.join(missing)}", param_hint="PATHS")
    files = _collect(fmt, paths)
    if not files:
        err_console.print(f"[red]error:[/] no {escape(FORMATS[fmt][1])} files in {escape(', '.join(map(str, paths)))}")
        raise typer.Exit(code=1)
    if column_map is not None and not column_map.is_file():
        raise typer.BadParameter(f"no such file: {column_map}", param_hint="--map")
    convert = _converter(fmt, parsed, fps, ground_truth, column_map)
    columns = (TextColumn("[bold]importing recordings"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("{task.description}"))
    with Progress(*columns, console=err_console, disable=as_json, transient=True) as bar:
        task = bar.add_task("", total=len(files))
        res = import_recordings(fmt, files, out, convert,
                                on_file=lambda f: bar.update(task, advance=1, description=f.name))

    def render(r: dict[str, Any]) -> None:
        console.print(_report_table(r))
        for row in r["files"]:
            if row.get("devices"):
                console.print(_device_table(row))
                for note in row.get("import_notes", []):
                    console.print(f"  {escape(Path(row['file']).name)}: {escape(note)}")
        for row in r["files"]:
            if not row["ok"]:
                err_console.print(f"[red]failed[/] {escape(row['error'])}")

    _emit(res, as_json, render)
    if res["failed"]:
        raise typer.Exit(code=1)
