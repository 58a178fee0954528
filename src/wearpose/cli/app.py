"""Typer application. Subcommands print human output by default and JSON with ``--json``."""

from __future__ import annotations

import faulthandler
import json
import os
import signal
import sys
from pathlib import Path
from typing import Any, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from wearpose.errors import WearposeError
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from wearpose.weights import list_weights
import warnings

app = typer.Typer(
    name="wearpose",
    help="Full-body, SMPL-compatible motion from a few body-worn sensors.\n\n"
    "Example: wearpose info --json",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
data_app = typer.Typer(help="Prepare and inspect the motion corpus.\n\nExample: wearpose data prepare && wearpose data info",
                       no_args_is_help=True)
app.add_typer(data_app, name="data")
console = Console(stderr=False)
err_console = Console(stderr=True)


def _emit(obj: dict[str, Any], as_json: bool, render: Any) -> None:
    if as_json:
        sys.stdout.write(json.dumps(obj, indent=2, default=str) + "\n")
    else:
        render(obj)


def _kv_table(title: str, rows: dict[str, Any]) -> Table:
    """A two-column key/value table; long values (paths, names) fold onto more lines, never cut."""
    t = Table(title=title, show_header=False)
    t.add_column("key", overflow="fold")
    t.add_column("value", overflow="fold")
    for k, v in rows.items():
        t.add_row(escape(str(k)), escape(str(v)))
    return t


def body_info(source: Optional[str] = None) -> dict[str, Any]:
    """Facts about a body asset (what ``wearpose info`` prints)."""
    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help

    body = BodyModel(source)
    out = body()
    verts = out.vertices
    return {
        "asset_id": body.asset_id,
        "source": body.meta.get("source", ""),
        "licence": body.meta.get("licence", ""),
        "vertices": body.num_vertices,
        "faces": int(body.faces.shape[0]),
        "joints": 24,
        "shape_dims": body.num_betas,
        "pose_correctives": body.has_posedirs,
        "rest_height_m": round(float(verts[:, 1].max() - verts[:, 1].min()), 4),
        "sensor_sites": list(body.site_names),
    }


def corpus_info(cache: Optional[Path] = None) -> dict[str, Any]:
    """Summary of the prepared corpus, or why there is none."""
    from wearpose.motion import CorpusStore, cache_dir  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    try:
        return {"prepared": True, **CorpusStore(cache_dir(cache)).summary()}
    except (WearposeError, FileNotFoundError) as exc:
        return {"prepared": False, "reason": f"{exc} (run: wearpose data prepare)"}


@app.command()
def info(
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl ($WEARPOSE_SMPL_MODEL) or a file path."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts."),
) -> None:
    """Report the body asset in use and the prepared corpus.

    Example: wearpose info --json
    """
    result: dict[str, Any] = {"body": body_info(body), "corpus": corpus_info()}

    def render(r: dict[str, Any]) -> None:
        console.print(_kv_table("body asset", r["body"]))
        console.print(_kv_table("corpus", r["corpus"]))

    _emit(result, as_json, render)


def _corpus_line(c: dict[str, Any] | None) -> str:
    """One line for a store's corpus record (:meth:`wearpose.motion.CorpusStore.provenance`)."""
    if not c:
        return "not recorded (prepared by an older wearpose)"
    if c.get("kind") == "manifest":
        return f"{c['name']} ({c['path']}), manifest sha1 {c['manifest_sha1'][:12]}"
    return f"your folders {', '.join(c.get('paths', []))}; split {c.get('split')}" + (f", source {c['source']}" if c.get("source") else "")


@data_app.command("prepare")
def data_prepare(
    folders: Optional[list[Path]] = typer.Argument(None, help="Corpus folder (with manifest.csv) or your own folders of BVH, ASF/AMC or AMASS files (any skeleton, see docs/motion-import.md); default $WEARPOSE_DATA or ../shared/data-v2 (corpus v2)."),
    cache: Optional[Path] = typer.Option(None, help="Output store; default $WEARPOSE_CACHE or ~/.cache/wearpose."),
    fps: Optional[float] = typer.Option(None, help="Resample every clip to this rate (default: keep each clip's rate)."),
    workers: Optional[int] = typer.Option(None, min=1, help="Worker processes (default: up to 2)."),
    limit: Optional[int] = typer.Option(None, min=1, help="Convert only the first N clips (quick check)."),
    per_split: Optional[int] = typer.Option(None, "--per-split", min=1, help="Convert only the first N clip ids of each split of each source: a small store with every split (quick start, tests)."),
    clip: Optional[list[str]] = typer.Option(None, "--clip", help="Convert only this clip id (repeatable; with --per-split: these as well)."),
    joint_map: Optional[Path] = typer.Option(None, "--joint-map", help="YAML joint map for the BVH/AMC of your own folders (see wearpose motion import)."),
    split: Optional[str] = typer.Option(None, help="Your own folders only: train, val or test puts every clip in that split (e.g. an external test set); hash (default) splits 80/10/10 by a hash of the subject folder."),
    source: Optional[str] = typer.Option(None, help="Your own folders only: the source name of every clip (default: the first folder level below each folder)."),
    asf: Optional[Path] = typer.Option(None, "--asf", help="Your own folders only: the ASF skeleton of every AMC file (folders holding several actors' ASF files)."),
    up: Optional[str] = typer.Option(None, help="Your own folders only: the up axis of every file: y, z, -y, -z, x, -x (default: detected per clip)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Convert the motion corpus (or your own folders of motion files) into the cached, indexed store
    (train/val/test by subject; your folders: subject = parent folder, split by a hash of it or
    --split). The store records which corpus (and manifest version) or folders it holds.

    Example: wearpose data prepare --fps 60    |    wearpose data prepare ~/mocap --cache ~/mocap_store

    Example: wearpose data prepare ~/lab_takes --split test --source lab --cache ~/lab_store
    """
    from wearpose.motion import cache_dir, data_dir, prepare_corpus  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    from wearpose.motion.store import SOURCE_NAME_RE, USER_SPLITS  # start-up: wearpose.motion.store loads torch, +1.8 s to wearpose --help

    if split is not None and split not in USER_SPLITS:
        raise typer.BadParameter(f"{split!r}; expected one of {', '.join(USER_SPLITS)}", param_hint="--split")
    if source is not None and not SOURCE_NAME_RE.match(source):
        raise typer.BadParameter(f"{source!r}; expected 1-64 characters of [A-Za-z0-9_.-] (it becomes a folder and the "
                                 "first part of clip ids)", param_hint="--source")
    src = [data_dir(f) for f in folders] if folders else data_dir()
    res = prepare_corpus(src, cache_dir(cache), fps=fps, progress=not as_json, workers=workers, limit=limit,
                         joint_map=joint_map, per_split=per_split, clips=tuple(clip or ()), split=split, source=source,
                         asf=asf, up=up)
    shown = {k: (round(v, 1) if k == "seconds" else v) for k, v in res.items() if k not in ("failures", "store")}
    shown["store"] = res["store"]["path"]
    shown["corpus"] = _corpus_line(res["store"]["corpus"])
    _emit(res, as_json, lambda r: console.print(_kv_table("prepared", shown))
          or [err_console.print(f"[red]failed[/] {escape(f'{k}: {v}')}") for k, v in r.get("failures", {}).items()])
    if res.get("failed") and not res.get("converted") and not res.get("skipped"):
        raise typer.Exit(code=1)  # nothing usable came out: a script must not go on with an empty store


@data_app.command("info")
def data_info(
    cache: Optional[Path] = typer.Option(None, help="Store to inspect; default $WEARPOSE_CACHE or ~/.cache/wearpose."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts."),
) -> None:
    """Summarise the prepared corpus: clips, subjects, minutes per split/source/licence.

    Example: wearpose data info --json
    """
    from wearpose.motion import CorpusStore, cache_dir  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    summary = CorpusStore(cache_dir(cache)).summary()
    shown = {k: v for k, v in summary.items() if k != "store"}
    shown.update(store=summary["store"]["path"], converter=summary["store"]["converter"],
                 corpus=_corpus_line(summary["store"]["corpus"]))
    _emit(summary, as_json, lambda r: console.print(_kv_table("corpus", shown)))


@data_app.command("procedural")
def data_procedural(
    out: Optional[Path] = typer.Option(None, help="Store folder (default: where `wearpose evaluate --protocol "
                                                  "unseen-motion` looks, <cache>/protocols/unseen-motion-n6-s0)."),
    per_family: int = typer.Option(6, "--per-family", min=1, help="Clips of each of the seven families."),
    seed: int = typer.Option(0, help="Base seed of the eval namespace's clips."),
    family: Optional[list[str]] = typer.Option(None, "--family", help="Only this family (repeatable; default all)."),
    shapes: bool = typer.Option(False, "--shapes", help="Draw a body shape per clip (default: the mean body, as "
                                                        "the corpus's test clips)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Build the held-out unseen-motion store: procedural clips of every family (squat, kneel,
    pickup, sit, lie, crawl, reach) from the eval seed namespace, never a training draw; source
    procedural, split test, class = family (docs/procedural-motion.md). Idempotent.

    Example: wearpose data procedural --per-family 3 --out stores/unseen3 && wearpose evaluate birae6_cpu --cache stores/unseen3
    """

    from wearpose.motion.procedural import FAMILIES  # start-up: wearpose.motion.procedural loads torch, +1.7 s to wearpose --help
    from wearpose.motion.procedural_store import build_procedural_store  # start-up: wearpose.motion.procedural_store loads torch, +1.8 s to wearpose --help

    columns = (TextColumn("[bold]procedural clips"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=err_console, transient=True, disable=as_json) as bar:
        task = bar.add_task("", total=None)
        res = build_procedural_store(out, per_family=per_family, seed=seed, families=tuple(family or FAMILIES),
                                     body_shape=shapes, progress=lambda d, t: bar.update(task, completed=d, total=t))
    _emit(res, as_json, lambda r: console.print(_kv_table("procedural store", {**r, "seconds": round(r["seconds"], 1)})))


@app.command()
def view(
    clip: str = typer.Argument(..., help="A clip id of the prepared store, or a .bvh/.bvh.gz/.npz (MotionSequence or AMASS) file."),
    out: Path = typer.Option(Path("out/view.html"), help="Output HTML file."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    start: float = typer.Option(0.0, help="Start time in seconds."),
    seconds: Optional[float] = typer.Option(20.0, help="Length to include in seconds (the page carries every frame)."),
    cache: Optional[Path] = typer.Option(None, help="Prepared store (for clip ids)."),
) -> None:
    """Write a self-contained HTML page that plays a clip on the body, with skeleton and sensor sites.

    Example: wearpose view cmu_daz/05/05_01 --out out/walk.html
    """
    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help
    from wearpose.motion import load_motion  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help
    from wearpose.viewer import write_html  # start-up: wearpose.viewer loads torch, +1.6 s to wearpose --help

    model = BodyModel(body)
    seq = load_motion(clip, cache=cache, rest_joints=model.rest_joints())
    a = int(round(start * seq.fps))
    b = seq.num_frames if seconds is None else min(seq.num_frames, a + int(round(seconds * seq.fps)))
    seq = seq.slice(a, b)
    path = write_html(out, model, seq.pose, seq.betas, seq.trans, seq.fps, title=f"wearpose: {clip}")
    console.print(f"wrote {path} ({seq.num_frames} frames at {seq.fps:g} fps); open it in a browser")


DEFAULT_DEMO_CLIP = "cmu_daz/05/05_01"  # a walk from the test split


@app.command()
def demo(
    clip: str = typer.Option(DEFAULT_DEMO_CLIP, help="Clip id, corpus path or motion file to run the demo on."),
    out: Optional[Path] = typer.Option(None, help="Output folder (HTML page, files, metrics JSON); default "
                                                  "out/demo-<kit> (out/demo-roundtrip), so demos of other kits "
                                                  "do not overwrite each other."),
    mode: str = typer.Option("auto", help="sensors (simulated sensors of --kit -> shipped estimator -> pose), "
                                          "roundtrip (file round trip of the motion), or auto (sensors when "
                                          "weights are shipped)."),
    kit: str = typer.Option("em12", help="Sensor kit of the sensors mode: em12, em6 (EM-POSE), imu6 (PIP), "
                                         "mimu6 (BiRAE), miposer (MI-Poser)."),
    body: Optional[str] = typer.Option(None, help="Body asset for the roundtrip mode: default, smpl or a file path."),
    seconds: float = typer.Option(10.0, min=0.5, help="Seconds of the clip used, from its start (a quick look: 2)."),
    as_json: bool = typer.Option(False, "--json", help="Print the metrics as JSON."),
) -> None:
    """Sensors -> pose on a held-out clip (or a motion file round trip), with metrics and a page.

    sensors: the clip is turned into simulated sensors of --kit (default noise, an unseen
    subject), the shipped estimator for that kit estimates the pose, and its metrics against the
    ground truth are printed; the page shows the estimate beside the ground truth.
    roundtrip: the clip is written as a wearpose MotionSequence and as AMASS npz, read back and
    compared with the original (all metrics ~0).

    Example: wearpose demo --kit em12 --clip bandai/bandai-B/dataset-2_walk_feminine_001
    """
    from wearpose.cli.demo import kit_demo, run_roundtrip_demo  # start-up: wearpose.cli.demo loads torch, +1.7 s to wearpose --help

    if mode not in ("auto", "sensors", "roundtrip"):
        raise typer.BadParameter(f"--mode must be auto, sensors or roundtrip, got {mode!r}")
    if mode == "auto":
        mode = "sensors" if (kit != "em12" or "empose12_cpu" in list_weights()) else "roundtrip"
    out = out or Path("out") / f"demo-{kit if mode == 'sensors' else 'roundtrip'}"
    result = (kit_demo(kit)(clip, out, max_seconds=seconds) if mode == "sensors"
              else run_roundtrip_demo(clip, out, body=body, max_seconds=seconds))
    result["mode"] = mode

    def render(r: dict[str, Any]) -> None:
        if r["mode"] == "sensors":
            t = Table(title=r.get("title", f"{r['clip']}: {kit}"))
            t.add_column("metric", overflow="fold")
            t.add_column("value", overflow="fold")
            for k, v in r["metrics"].items():
                t.add_row(k, f"{v:.2f}")
        else:
            t = Table(title=f"{r['clip']}: round trip vs original ({r['frames']} frames, {r['fps']:g} fps)")
            t.add_column("metric", overflow="fold")
            for name in r["metrics"]:
                t.add_column(name, overflow="fold")
            keys = sorted({k for m in r["metrics"].values() for k in m})
            for k in keys:
                t.add_row(k, *[f"{m.get(k, float('nan')):.3g}" for m in r["metrics"].values()])
        console.print(t)
        console.print(f"page: {r['html']}  (open in a browser)")

    _emit(result, as_json, render)


def error_text(exc: BaseException) -> str:
    """The one line ``main`` prints for a user mistake: a library error as written (it names the
    file, the field in [brackets], the problem and the expected form), or an operating-system
    error as 'path: reason' (a folder that does not exist, no permission, a full disk)."""
    if isinstance(exc, OSError) and exc.strerror:
        if isinstance(exc, (FileExistsError, NotADirectoryError)) and exc.filename and Path(exc.filename).is_file():
            return f"{exc.filename}: is a file, but the output path needs a folder there"
        where = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        return f"{where}: {exc.strerror}" if where else exc.strerror
    return str(exc)


def _show_warning(message: Any, category: Any, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
    """Library warnings as one 'warning:' line (not Python's 'path:line: UserWarning' form)."""
    err_console.print(f"[yellow]warning:[/] {escape(str(message))}")


def dump_stacks_on_sigusr1() -> None:
    """``kill -USR1 PID`` prints every thread's Python stack to stderr and the command runs on:
    a server or viewer that does not stop can say where it is (a README-order test failure
    asks it before killing it)."""
    # The process's own stderr (sys.__stderr__): sys.stderr may be replaced by a file object
    # without a descriptor (pytest's capture, an embedding host), which faulthandler cannot use.
    if hasattr(signal, "SIGUSR1") and sys.__stderr__ is not None:  # no SIGUSR1 on Windows
        faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)


def main() -> None:
    """Console entry point: turns library errors and file-system errors into one clear line and
    exit code 1 (no traceback; set WEARPOSE_DEBUG=1 to get one)."""

    dump_stacks_on_sigusr1()
    if not os.environ.get("WEARPOSE_DEBUG"):
        warnings.showwarning = _show_warning
    try:
        app()
    except (WearposeError, OSError) as exc:
        if os.environ.get("WEARPOSE_DEBUG"):
            raise
        # escape(): messages carry [field] names, which rich would otherwise eat as markup.
        err_console.print(f"[bold red]error:[/] {escape(error_text(exc))}")
        raise SystemExit(1) from None
