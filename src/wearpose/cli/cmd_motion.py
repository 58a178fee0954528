"""``wearpose motion import``: bring your own BVH or ASF/AMC motion onto the SMPL body.

Thin: collects files, calls :func:`wearpose.motion.import_paths` and prints a per-file report
(skeleton map, units, up axis, rest pose, frames, fps, bone-direction check: mean and the worst
bone's maximum), the joint table of every skeleton that was matched automatically or by a joint
map, the per-bone check (worst first) of every file with a warning (of every file when there
are at most :data:`BONE_TABLES_UP_TO`), and the warnings.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer
from rich.markup import escape
from rich.table import Table

from wearpose.cli.app import _emit, app, console, err_console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from wearpose.errors import WearposeError

motion_app = typer.Typer(help="Import your own motion files (BVH, ASF/AMC) onto the SMPL body, or make\n"
                              "procedural clips of motion the corpus lacks.\n\n"
                              "Example: wearpose motion import mocap/ --out motion_npz/\n\n"
                              "Example: wearpose motion procedural squat --seed 0 --out squat.npz", no_args_is_help=True)
app.add_typer(motion_app, name="motion")


def _mapping_table(row: dict[str, Any]) -> Table:
    t = Table(title=f"joint map of {Path(row['file']).name}: {row['map_source']} (check it; override with --joint-map)")
    t.add_column("SMPL joint", overflow="fold")
    t.add_column("your joint", overflow="fold")
    t.add_column("how", overflow="fold")
    for smpl, joint, how in row["mapping"]:
        style = "dim" if joint == "-" else None
        t.add_row(smpl, joint if joint != "-" else "- (fill rule)", how, style=style)
    return t


#: Per-bone check tables are printed for every file up to this many files (beyond it: only for
#: files with a warning).
BONE_TABLES_UP_TO = 3


def _bone_table(row: dict[str, Any]) -> Table:
    be = row["bone_error_deg"]
    t = Table(title=f"bone check of {Path(row['file']).name}: angle between each mapped bone and the source's (deg), worst first")
    for c in ("SMPL bone", "your bone", "mean", "max", "at frame"):
        t.add_column(c, justify="right" if c in ("mean", "max", "at frame") else "left", overflow="fold")
    for r in be.get("ranked", []):
        style = "red" if r["max"] > be.get("warn_deg", float("inf")) else None
        t.add_row(r["bone"], r["source"], f"{r['mean']:.2f}", f"{r['max']:.2f}", str(r["max_frame"]), style=style)
    return t


def _report_table(res: dict[str, Any]) -> Table:
    t = Table(title=f"motion import -> {res['out']}: {res['converted']} converted, {res['failed']} failed")
    for c in ("file", "skeleton", "units", "up", "rest pose", "frames", "fps", "bone err mean (deg)", "worst bone max (deg)", "status"):
        # fold, not ellipsis: at 80 columns a file or skeleton name must stay readable whole
        t.add_column(c, justify="right" if c in ("frames", "fps", "bone err mean (deg)") else "left", overflow="fold")
    for r in res["files"]:
        name = Path(r["file"]).name
        if not r["ok"]:
            t.add_row(name, "", "", "", "", "", "", "", "", "[red]failed[/]")
            continue
        u, up, rp, be = r["units"], r["up"], r["rest_pose"], r["bone_error_deg"]
        units = f"{u['name']} ({'declared' if u['how'] == 'declared' else u['how'].split(' ')[0]})"
        rest = rp["kind"] + (f", max {rp['max_deg']:.0f} deg {rp['max_joint']}" if rp.get("max_joint") else "")
        worst = f"{be['worst_bone_max']:.1f} {be['worst_bone']}" if be.get("worst_bone") else "-"
        status = f"[yellow]ok, {len(r['warnings'])} warning(s)[/]" if r.get("warnings") else "[green]ok[/]"
        t.add_row(name, f"{r['skeleton']} ({r['map_source'].split(' ')[0]})", units,
                  f"{up['axis']} ({up['how'].split(' ')[0]})", rest, str(r["frames"]), f"{r['fps']:g}",
                  f"{be['mean']:.2f}", worst, status)
    return t


def _check_options(units: str | None, up: str | None, joint_map: Path | None) -> None:
    """Options that apply to every file are checked once, before any file is read (a typo in
    --units would otherwise fail every file with the same message)."""
    from wearpose.motion.importer import UP_AXES, parse_units  # start-up: wearpose.motion.importer loads torch, +1.7 s to wearpose --help
    from wearpose.motion.mapping import load_joint_map  # start-up: wearpose.motion.mapping loads torch, +1.7 s to wearpose --help

    if units is not None:
        try:
            parse_units(units)
        except WearposeError as exc:
            raise typer.BadParameter(str(exc), param_hint="--units") from None
    if up is not None and up.lower() not in UP_AXES:
        raise typer.BadParameter(f"{up!r}; expected one of {', '.join(UP_AXES)}", param_hint="--up")
    if joint_map is not None:
        load_joint_map(joint_map)  # InputFileError naming the map file, the key and the expected form


@motion_app.command("import")
def motion_import(
    paths: list[Path] = typer.Argument(..., help="Motion files (.bvh, .bvh.gz, .amc with its .asf beside it) or folders of them (searched recursively; formats may be mixed)."),
    out: Path = typer.Option(Path("motion_npz"), "--out", help="Output folder: one MotionSequence .npz per clip (folder layout kept)."),
    joint_map: Optional[Path] = typer.Option(None, "--joint-map", help="YAML joint map 'smpl_joint: your_joint' (plus optional units:, up:) overriding the automatic match."),
    units: Optional[str] = typer.Option(None, help="Length unit of the files: m, cm, mm, inch, acclaim (1/0.45 inch) or metres per unit (default: detected)."),
    up: Optional[str] = typer.Option(None, help="Up axis of the files: y, z, -y, -z, x, -x (default: detected)."),
    fps: Optional[float] = typer.Option(None, help="Frame rate of AMC files, which store none (default 120, CMU's rate)."),
    asf: Optional[Path] = typer.Option(None, "--asf", help="ASF skeleton for every AMC file (default: <clip>.asf, <subject>.asf or the only .asf beside each AMC); for folders holding several actors' ASF files."),
    body: Optional[str] = typer.Option(None, help="Body asset the motion will play on: default, smpl or a file path."),
    as_json: bool = typer.Option(False, "--json", help="Print the full per-file reports as JSON."),
) -> None:
    """Convert BVH and ASF/AMC files or folders to wearpose MotionSequence files on the SMPL body.

    For every file: the skeleton is matched to SMPL's 24 joints (built-in maps for CMU, Bandai,
    Mixamo, Rigify and our own exports, otherwise by joint names and tree position), its length
    unit and up axis are detected, a non-T bind pose is corrected per joint, and the bone
    directions of the result are compared with the source, bone by bone (mean and maximum angle
    over the clip, degrees, worst first; a warning names every bone off by more than 10 deg in
    some frame). A file that cannot be read is reported with the reason and the others are
    converted (exit code 1 if any failed). Check a result with `wearpose view OUT/clip.npz`.

    Example: wearpose motion import mocap/ take.bvh --out motion_npz/ --joint-map map.yaml

    Example: wearpose motion import amc_takes/ --asf amc_takes/actor2.asf --out motion_npz/
    """

    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help
    from wearpose.motion import collect_motion_files, import_paths  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    _check_options(units, up, joint_map)
    if asf is not None and not asf.is_file():
        raise typer.BadParameter(f"no such ASF file: {asf}", param_hint="--asf")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise typer.BadParameter(f"no such file or folder: {', '.join(missing)}", param_hint="PATHS")
    n = len(collect_motion_files(paths))
    if n == 0:
        where = ", ".join(map(str, paths))
        err_console.print(f"[red]error:[/] no motion files (.bvh, .bvh.gz, .amc, .amc.gz) in {escape(where)}")
        raise typer.Exit(code=1)
    rest = BodyModel(body).rest_joints().detach().double()
    columns = (TextColumn("[bold]importing motion"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("{task.description}"))
    with Progress(*columns, console=err_console, disable=as_json or n == 0, transient=True) as bar:
        task = bar.add_task("", total=n)
        res = import_paths(paths, out, rest, joint_map=joint_map, units=units, up=up, fps=fps, asf=asf,
                           on_file=lambda f, row: bar.update(task, advance=1, description=f.name))

    def render(r: dict[str, Any]) -> None:
        shown: set[tuple] = set()
        for row in r["files"]:
            if row["ok"] and not row["map_source"].startswith(("built-in", "exact")):
                key = tuple(tuple(x) for x in row["mapping"])
                if key not in shown:
                    shown.add(key)
                    console.print(_mapping_table(row))
            for note in row.get("map_notes", []) if row["ok"] else []:
                err_console.print(f"[yellow]note[/] {escape(Path(row['file']).name)}: {escape(str(note))}")
        console.print(_report_table(r))
        few = len(r["files"]) <= BONE_TABLES_UP_TO
        for row in r["files"]:
            if row["ok"] and row["bone_error_deg"].get("ranked") and (few or row.get("warnings")):
                console.print(_bone_table(row))
        for row in r["files"]:
            for w in row.get("warnings", []) if row["ok"] else []:
                err_console.print(f"[yellow]warning[/] {escape(Path(row['file']).name)}: {escape(str(w))}")
        for row in r["files"]:
            if not row["ok"]:
                err, f = str(row["error"]), str(row["file"])
                err_console.print(f"[red]failed[/] {escape(err if f in err else f'{f}: {err}')}")

    _emit(res, as_json, render)
    if res["failed"]:
        raise typer.Exit(code=1)


@motion_app.command("procedural")
def motion_procedural(
    family: str = typer.Argument(..., help="squat, kneel, pickup, sit, lie, crawl or reach (docs/procedural-motion.md)."),
    out: Path = typer.Option(..., "--out", help="Output MotionSequence .npz (a folder with --count > 1: one file per clip)."),
    seed: int = typer.Option(0, help="Base seed; with --index and --namespace it names the clip."),
    index: int = typer.Option(0, help="Index of the (first) clip in its namespace."),
    count: int = typer.Option(1, min=1, help="Number of clips, indices INDEX .. INDEX+COUNT-1."),
    namespace: str = typer.Option("train", help="Seed namespace: train, val, or eval (held-out evaluation sets)."),
    fps: float = typer.Option(60.0, help="Frame rate, Hz."),
    mean_body: bool = typer.Option(False, "--mean-body", help="Keep the mean body shape (betas 0) instead of drawing one."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    as_json: bool = typer.Option(False, "--json", help="Print the clips' facts as JSON."),
) -> None:
    """Make procedural clips of one motion family: keyframed postures on the body, placed on the
    floor (lowest vertex at y = 0, resting parts still), deterministic from the seed, index and
    namespace. Check a clip with `wearpose view OUT.npz`; simulate sensors on it with
    `wearpose simulate`.

    Example: wearpose motion procedural kneel --seed 0 --out kneel.npz

    Example: wearpose motion procedural lie --namespace eval --count 20 --out heldout/lie/
    """
    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help
    from wearpose.motion.procedural import procedural_clip, procedural_seed  # start-up: wearpose.motion.procedural loads torch, +1.7 s to wearpose --help

    procedural_seed(family, index, seed, namespace)  # ConfigError naming the family or namespace
    model = BodyModel(body)
    rows = []
    for i in range(index, index + count):
        seq = procedural_clip(family, i, model, seed=seed, namespace=namespace, fps=fps, body_shape=not mean_body)
        path = out if count == 1 else out / f"{family}_{namespace}_{i:04d}.npz"
        seq.save(path)
        rows.append({"file": str(path), "clip": seq.meta["clip"], "frames": seq.num_frames, "seconds": round(seq.duration, 2),
                     "phases": [sg[0] for sg in seq.meta["segments"]], "betas": [round(float(b), 3) for b in seq.betas],
                     "heading_deg": round(seq.meta["heading_deg"], 1)})

    def render(r: dict[str, Any]) -> None:
        t = Table(title=f"procedural {family} ({namespace}, seed {seed})")
        for c in ("file", "clip", "frames", "seconds", "phases"):
            t.add_column(c, overflow="fold")
        for row in r["clips"]:
            t.add_row(escape(row["file"]), row["clip"], str(row["frames"]), str(row["seconds"]), escape(", ".join(row["phases"])))
        console.print(t)

    _emit({"clips": rows}, as_json, render)
