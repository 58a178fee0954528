"""``wearpose evaluate``: checkpoints on simulated held-out recordings, in the paper's metrics.

Thin: resolves the model arguments (``NAME=path``, a checkpoint path, or shipped weights such as
``empose12_cpu``), finds each model's protocol in its method's declaration
(:class:`wearpose.estimators.method.EstimatorEntry`), and runs it: a ``compare`` protocol
(the EM-POSE family: :func:`wearpose.estimators.empose.evaluate.evaluate_models`, one
simulation per clip shared by every model) or each model's own ``protocol``
(:func:`wearpose.evaluate.protocols.evaluate_model`: PIP, BiRAE, MI-Poser, IMUPoser, any
declared method). Prints the table and optionally writes markdown + JSON. An estimator
evaluated elsewhere says where (its declaration's ``evaluated_by``: the L-BFGS optimiser's
``benchmarks/empose_lbfgs.py``).
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

import typer
from rich.table import Table

from wearpose.cli.app import _emit, app, console, err_console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from wearpose.cli.models import check_pose_weights, parse_settings, with_settings
from wearpose.errors import ConfigError
from wearpose.weights import weight_path

if TYPE_CHECKING:
    from wearpose.estimators.method import EstimatorEntry
    from wearpose.estimators.run import ModelSource

def resolve_model(spec: str) -> tuple[str, Path]:
    """``NAME=TARGET`` or ``TARGET`` -> (display name, checkpoint path); TARGET is a file or the
    name of shipped weights (:func:`wearpose.weights.weight_path`). The default name is the
    weights' name, or the run directory of a ``.../<run>/best.pt`` path."""

    name, sep, target = spec.partition("=")
    if not sep:
        name, target = "", spec
    if not target or (sep and not name):
        raise typer.BadParameter(f"{spec!r}: expected NAME=PATH, PATH or a shipped weight name", param_hint="MODELS")
    path = Path(target)
    if not path.is_file():

        check_pose_weights(target, param_hint="MODELS")
        try:
            path = weight_path(target)
        except ConfigError as exc:
            raise typer.BadParameter(f"{target!r} is neither a checkpoint file nor shipped weights ({exc})",
                                     param_hint="MODELS") from None
        name = name or target
    return name or (path.parent.name if path.stem in ("best", "last") else path.stem), path


def _open(name: str, path: Path) -> ModelSource:
    """The model at ``path`` (its checkpoint read once, :func:`wearpose.estimators.run.open_model`),
    refused when `wearpose evaluate` has no protocol for its method."""
    from wearpose.estimators.run import open_model  # start-up: wearpose.estimators.run loads torch, +2.0 s to wearpose --help

    source = open_model(path)
    entry = _entry(source.method)
    if entry is None or not (entry.protocol or entry.compare):
        known = [n for n, e in _entries().items() if e.protocol or e.compare]
        hint = f"; evaluate it with `{entry.evaluated_by}`" if entry is not None and entry.evaluated_by else ""
        raise typer.BadParameter(f"{name} ({path}) is a {source.method!r} model: `wearpose evaluate` runs the "
                                 f"protocols of {', '.join(known)}{hint}", param_hint="MODELS")
    return source


def _entries() -> dict[str, EstimatorEntry]:
    """Every declared estimator's entry, by registry name."""
    from wearpose.estimators.registry import get_method, list_methods  # start-up: wearpose.estimators.registry adds ~25 ms to wearpose --help

    return {e.name: e for m in list_methods() for e in get_method(m).estimators}


def _entry(method: str) -> EstimatorEntry | None:
    return _entries().get(method)


def _with_settings(ckpts: dict[str, Path], settings: dict[str, str]) -> dict[str, Any]:
    """Every checkpoint loaded (:func:`~wearpose.estimators.empose.baselines.load_any`) with the
    ``--set`` settings applied (:func:`wearpose.evaluate.latency.apply_settings`)."""
    from wearpose.estimators.empose.baselines import load_any  # start-up: loads torch, +1.6 s to wearpose --help

    return {name: with_settings(load_any(path), settings, name) for name, path in ckpts.items()}


def _store(cache: Path | None, protocol: str, source: str | None, per_family: int | None, split: str) -> Any:
    """The store the command evaluates on: ``--cache`` (or the prepared corpus) for ``corpus``,
    the built-in procedural store for ``unseen-motion``; restricted to ``--source``."""
    from wearpose.motion import CorpusStore  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

    if protocol not in ("corpus", "unseen-motion"):
        raise typer.BadParameter(f"expected corpus or unseen-motion, got {protocol!r}", param_hint="--protocol")
    if protocol == "corpus" and per_family is not None:
        raise typer.BadParameter("--per-family sizes the unseen-motion set; add --protocol unseen-motion",
                                 param_hint="--per-family")
    if protocol == "unseen-motion":
        if cache is not None:
            raise typer.BadParameter("--protocol unseen-motion uses its own procedural store; to evaluate on a store "
                                     "of yours (wearpose data procedural --out STORE) give only --cache STORE",
                                     param_hint="--cache")
        if split != "test":
            raise typer.BadParameter("the unseen-motion set is a test split only", param_hint="--split")
        from wearpose.evaluate.protocols import unseen_motion_store  # start-up: wearpose.evaluate.protocols loads torch, +1.8 s to wearpose --help

        err_console.print("unseen-motion store: building or checking (about 1.5 s per new clip)")
        store = unseen_motion_store(per_family)
    else:
        store = CorpusStore(cache)
    if source is not None:
        try:
            store = store.subset(source)
        except ConfigError as exc:
            raise typer.BadParameter(str(exc), param_hint="--source") from None
    return store


def _render_protocol(r: dict[str, Any]) -> None:
    first = next(iter(r["models"].values()))
    t = Table(title=f"{first['split']} split: {first['clips']} clips, {first['frames']} frames, kit {first['kit']}")
    t.add_column("metric", overflow="fold")
    for name in r["models"]:
        t.add_column(name, justify="right", overflow="fold")
    keys = list(dict.fromkeys(k for m in r["models"].values() for k in m["metrics"]))
    for k in keys:
        t.add_row(k, *(f"{m['metrics'][k]:.3g}" if k in m["metrics"] else "-" for m in r["models"].values()))
    console.print(t)
    console.print(f"protocol: {first['protocol']}; bodies {first.get('bodies', 'corpus')}", soft_wrap=False)
    _render_breakdown(r["models"])
    for p in r.get("written", []):
        console.print(f"wrote {p}")


def _render_breakdown(models: dict[str, Any]) -> None:
    """By source and by motion class: each group's clips and its first per-clip figure (the
    protocol's lead metric) per model; every figure is in the JSON and the markdown."""
    lead = next(iter(models.values()))
    first = lead.get("breakdown") or {}
    rows = next((row for b in first.values() for row in b.values()), {})
    metric = lead.get("lead") or next((k for k in rows if k not in ("clips", "frames")), None)
    if metric is None:
        return
    for kind in ("source", "class"):
        t = Table(title=f"by {kind}: {metric}")
        t.add_column(kind, overflow="fold")
        t.add_column("clips", justify="right", overflow="fold")
        for name in models:
            t.add_column(name, justify="right", overflow="fold")
        for g, row in first[kind].items():
            t.add_row(g, str(row["clips"]), *(f"{m['breakdown'][kind].get(g, {}).get(metric, float('nan')):.3g}"
                                              for m in models.values()))
        console.print(t)


def _render(r: dict[str, Any]) -> None:
    t = Table(title=f"{r['split']} split: {r['clips']} clips, {r['frames']} frames, kit {r['kit']}, "
                    f"offsets {r['offsets']}, noise {r['noise']}")
    for col in ("model", "MPJPE [mm]", "PA-MPJPE [mm]", "MPJAE [°]", "frames", "epoch", "time [s]"):
        t.add_column(col, justify="left" if col == "model" else "right", overflow="fold")
    for name, m in r["models"].items():
        t.add_row(name, f"{m['mpjpe_mm']:.1f} ± {m['mpjpe_std_mm']:.1f}", f"{m['pa_mpjpe_mm']:.1f} ± {m['pa_mpjpe_std_mm']:.1f}",
                  f"{m['mpjae_deg']:.1f} ± {m['mpjae_std_deg']:.1f}", str(m["frames"]), str(m.get("epoch")),
                  f"{m['seconds']:.1f}")
    console.print(t)
    console.print(f"{r['joints']} joints; mean ± std over frames with every sensor valid; {r['subjects']}; "
                  f"bodies {r.get('bodies', 'corpus')}.")
    for name, m in r["models"].items():
        if "height_error_median_cm" in m:  # the EM-POSE family's shape estimate
            console.print(f"{name}: body shape, median over clips: height error {m['height_error_median_cm']:.1f} cm "
                          f"({m['height_difference_median_cm']:+.1f} cm), zero-pose vertex error "
                          f"{m['zero_pose_vertex_error_median_mm']:.1f} mm")
        if "per_joint" in m:  # the error's constant part per clip (a skeleton, calibration or prior offset)
            j, row = max(m["per_joint"].items(), key=lambda kv: kv[1]["bias_mm"])
            console.print(f"{name}: {m['bias_share'] * 100:.0f} % of the squared joint error is constant over a "
                          f"clip; the largest constant part: {j} {row['bias_mm']:.1f} mm (per joint: --out)")
    _render_breakdown(r["models"])
    for p in r.get("written", []):
        console.print(f"wrote {p}")


@app.command()
def evaluate(
    models: list[str] = typer.Argument(..., help="Models: NAME=PATH, a checkpoint path, or shipped weights "
                                                 "(empose12_cpu, pip_cpu, birae6_cpu, miposer_cpu, ...); "
                                                 "all of one method family and kit."),
    split: str = typer.Option("test", help="Corpus split: test (held-out numbers) or val."),
    clips: Optional[int] = typer.Option(None, "--clips", min=1, help="Only the first N clips of the split (sorted ids)."),
    offsets: str = typer.Option("random", help="Evaluation subjects: random (synthetic subjects from the training "
                                               "prior, unseen seeds) or unseen (a wider distribution, EM-POSE Table 4)."),
    spread: float = typer.Option(2.0, help="--offsets unseen: size factor on every offset parameter of the prior."),
    noise: str = typer.Option("default", help="EM error model of the simulation: default or none."),
    seed: int = typer.Option(0, help="Base seed of the evaluation subjects and noise."),
    threads: int = typer.Option(1, min=1, help="torch CPU threads."),
    out: Optional[Path] = typer.Option(None, help="Write OUT.md and OUT.json (table, models, setting)."),
    title: Optional[str] = typer.Option(None, help="Title of the markdown file."),
    note: Optional[str] = typer.Option(None, help="A sentence appended to the markdown."),
    frame_stride: int = typer.Option(1, "--frame-stride", min=1,
                                     help="Sparse-IMU protocols: score every N-th frame (the MI-Poser cards used 4)."),
    cache: Optional[Path] = typer.Option(None, help="Prepared corpus store to evaluate on (default: the store of "
                                                    "`wearpose data prepare`)."),
    protocol: str = typer.Option("corpus", help="Clips: corpus (the store's split: in-lab) or unseen-motion (the "
                                                "held-out procedural families, built once: docs/procedural-motion.md)."),
    source: Optional[str] = typer.Option(None, help="Only the clips of this source (lab): bandai, cmu_daz, cmu_asf "
                                                    "(unseen lab: a model trained on another lab's clips)."),
    per_family: Optional[int] = typer.Option(None, "--per-family", min=1,
                                             help="--protocol unseen-motion: clips per family (default 6)."),
    bodies: str = typer.Option("corpus", help="Wearers: corpus (each clip's own body, beta = 0) or heldout (a body "
                                              "per clip from the held-out shape stream, seeded per clip, the clip "
                                              "re-fitted to it; the same body for every model)."),
    settings: Optional[list[str]] = typer.Option(None, "--set", help="KEY=VALUE: an EM-POSE setting changed after "
                                                 "loading, for every model (repeatable), e.g. --set refine_steps=3 "
                                                 "(the refinement, every frame) (docs/empose.md)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (progress goes to stderr)."),
) -> None:
    """Evaluate checkpoints on simulated held-out recordings with the paper's metrics.

    EM-POSE models: every clip of the split is simulated once (kit noise, a synthetic subject's
    sensor offsets, seeds never used for training) and estimated by every model; MPJPE
    (root-aligned), PA-MPJPE and MPJAE on the 15 major joints over frames with every sensor
    valid, mean ± std. PIP, BiRAE, MI-Poser, IMUPoser: each model under its paper's protocol
    and metrics (PIP: SIP, angular, positional, mesh, jitter, translation; BiRAE: MPJAE groups
    and uncertainty coverage; MI-Poser/IMUPoser: upper-body MPJPE).

    Every result has per-source and per-motion-class breakdowns (JSON, markdown, a table of
    the lead metric here).

    Example: wearpose evaluate empose12_cpu BiRNN=runs/birnn12_cpu/best.pt --clips 20 --out results/em12
    Unseen subjects (EM-POSE Table 4): wearpose evaluate empose12_cpu --offsets unseen --spread 2
    Another method: wearpose evaluate pip_cpu --clips 2 --json
    Unseen motion: wearpose evaluate birae6_cpu --protocol unseen-motion --out results/unseen_birae6
    Unseen lab: wearpose evaluate empose12_cpu --source cmu_daz
    Held-out wearers: wearpose evaluate empose12_cpu --bodies heldout
    Refinement: wearpose evaluate empose12_cpu --set refine_steps=3
    """
    import torch  # start-up: torch loads torch, +1.3 s to wearpose --help

    from wearpose.estimators.empose.evaluate import SUBJECT_MODES, write_table  # start-up: wearpose.estimators.empose.evaluate loads torch, +1.6 s to wearpose --help

    if split not in ("test", "val", "train"):
        raise typer.BadParameter(f"expected test or val, got {split!r}", param_hint="--split")
    if offsets not in SUBJECT_MODES:
        raise typer.BadParameter(f"expected one of {', '.join(SUBJECT_MODES)}, got {offsets!r}", param_hint="--offsets")
    if noise not in ("default", "none"):
        raise typer.BadParameter(f"expected default or none, got {noise!r}", param_hint="--noise")
    if split == "train":
        err_console.print("[yellow]warning[/]: the train split measures fit, not held-out accuracy")
    from wearpose.estimators.bodies import BODIES  # start-up: wearpose.estimators.bodies loads torch, +1.7 s to wearpose --help

    if bodies not in BODIES:
        raise typer.BadParameter(f"expected {' or '.join(BODIES)}, got {bodies!r}", param_hint="--bodies")

    ckpts: dict[str, Path] = {}
    sources: dict[str, ModelSource] = {}
    for spec in models:
        name, path = resolve_model(spec)
        if name in ckpts:
            raise typer.BadParameter(f"two models named {name!r}; use NAME=PATH", param_hint="MODELS")
        sources[name], ckpts[name] = _open(name, path), path
    compare = {n: getattr(_entry(s.method), "compare", None) for n, s in sources.items()}
    compared = {n for n, c in compare.items() if c}
    if compared and (len(compared) < len(sources) or len(set(compare.values())) > 1):
        raise typer.BadParameter(f"EM-POSE models ({', '.join(sorted(compared))}) and others "
                                 f"({', '.join(sorted(set(sources) - compared))}) have different protocols; "
                                 "evaluate them in separate commands", param_hint="MODELS")
    if settings and not compared:
        raise typer.BadParameter("--set changes EM-POSE models here; the other methods' settings are timed with "
                                 "`wearpose bench latency --set`", param_hint="--set")
    models_in: dict[str, Any] = _with_settings(ckpts, parse_settings(settings)) if settings else dict(ckpts)
    store = _store(cache, protocol, source, per_family, split)
    if not store.clips(split=split):
        raise typer.BadParameter(f"corpus store {store.root}: the {split!r} split has no clips (nothing to "
                                 "evaluate); prepare a store with that split (wearpose data prepare --split) or "
                                 "choose another --split", param_hint="--split")
    torch.set_num_threads(threads)
    columns = (TextColumn("[bold]evaluating"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=err_console, transient=True) as bar:
        task = bar.add_task("", total=None)
        tick = lambda d, t: bar.update(task, completed=d, total=t)  # noqa: E731
        if compared:
            if frame_stride != 1:
                raise typer.BadParameter("the EM-POSE protocol scores every frame", param_hint="--frame-stride")
            from wearpose.evaluate.protocols import compare_models  # start-up: wearpose.evaluate.protocols loads torch, +1.8 s to wearpose --help

            res = compare_models(next(iter(compare.values())), models_in, split, clips, noise=noise, seed=seed,
                                 offsets=offsets, spread=spread, store=store, progress=tick, bodies=bodies)
            for n, m in res["models"].items():
                m["checkpoint"] = str(ckpts[n])
        else:
            from wearpose.evaluate.protocols import evaluate_model  # start-up: wearpose.evaluate.protocols loads torch, +1.8 s to wearpose --help

            res = {"split": split, "store": store.provenance(),
                   "models": {n: evaluate_model(src, split=split, clips=clips, seed=seed, noise=noise,
                                                store=store, progress=tick, frame_stride=frame_stride,
                                                bodies=bodies)
                              for n, src in sources.items()}}
            for n, r in res["models"].items():
                r["model"] = n
    command = "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    res.update(command=command, protocol_clips=protocol, source_filter=source, bodies=bodies)
    if out is not None and compared:
        extra = {"command": command, **({"note": note} if note else {})}
        from wearpose.evaluate.protocols import breakdown_sections  # start-up: wearpose.evaluate.protocols loads torch, +1.8 s to wearpose --help

        md, js = write_table(res, out, title=title or f"wearpose evaluate ({split} split, kit {res['kit']})",
                             produced_by=command, paper=None, extra=extra, appendix=breakdown_sections(res["models"]))
        res["written"] = [str(md), str(js)]
    elif out is not None:
        from wearpose.evaluate.protocols import write_result  # start-up: wearpose.evaluate.protocols loads torch, +1.8 s to wearpose --help

        md, js = write_result(res, out, title=title or f"wearpose evaluate ({split} split)", produced_by=command,
                              note=note)
        res["written"] = [str(md), str(js)]
    _emit(res, as_json, _render if compared else _render_protocol)
