"""``wearpose bench``: measure a model on the machine at hand.

Thin: ``bench latency`` opens the model (:func:`wearpose.estimators.run.open_model`), gets a
recording (the user's, or a procedural clip simulated on the model's kit:
:func:`wearpose.recording.simulate_recording`) and times the online step
(:func:`wearpose.evaluate.latency.step_latency`) beside the machine reference
(:func:`wearpose.evaluate.latency.reference_timing`) and the load average, so figures from
different machines and runs can be compared.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Any, Optional

import typer
from rich.table import Table

from wearpose.cli.app import _emit, app, console, err_console
from wearpose.cli.models import parse_settings
from wearpose.errors import ConfigError

bench_app = typer.Typer(help="Measure a model on this machine (latency with the machine's reference timing).\n\n"
                             "Example: wearpose bench latency empose12_cpu --frames 300 --threads 1 --json",
                        no_args_is_help=True)
app.add_typer(bench_app, name="bench")

#: The procedural clip simulated when no ``--recording`` is given (no corpus needed).
DEFAULT_MOTION = "reach"


def _procedural_recording(kit: str, family: str, seed: int) -> Any:
    """Clip 0 of ``family`` in the evaluation seed namespace, after a 1 s calibration T-pose, worn
    by ``kit`` (default noise, a random subject's EM offsets)."""
    from wearpose.body import BodyModel  # start-up: wearpose.body loads torch, +1.6 s to wearpose --help
    from wearpose.motion.procedural import procedural_clip  # start-up: wearpose.motion.procedural loads torch, +1.7 s to wearpose --help
    from wearpose.recording import simulate_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    body = BodyModel()
    motion = procedural_clip(family, 0, body, seed=seed, namespace="eval")
    rec, _ = simulate_recording(motion, kit, body, seed=seed, tpose_s=1.0,
                                meta={"clip_id": motion.meta.get("clip")})
    return rec


def _render(res: dict[str, Any]) -> None:
    s, c = res["online_ms"], res["online_cpu_ms"]
    t = Table(title=f"{res['model']} online step, {res['frames']} frames at {res['rate_hz']:g} Hz "
                    f"({res['threads']} thread(s))")
    for col in ("", "median ms", "p99 ms", "max ms"):
        t.add_column(col, justify="right" if col else "left", overflow="fold")
    t.add_row("wall", f"{s['median_ms']:.2f}", f"{s['p99_ms']:.2f}", f"{s['max_ms']:.2f}")
    t.add_row("CPU", f"{c['median_ms']:.2f}", f"{c['p99_ms']:.2f}", f"{c['max_ms']:.2f}")
    for key, v in res["stages_ms"].items():
        t.add_row(f"  {key}", f"{v['median_ms']:.2f}", f"{v['p99_ms']:.2f}", f"{v['max_ms']:.2f}")
    if "baseline" in res:
        b, sp = res["baseline"], res["speedup"]
        t.add_row("baseline wall", *(f"{b['online_ms'][k]:.2f}" for k in ("median_ms", "p99_ms", "max_ms")))
        t.add_row("baseline CPU", *(f"{b['online_cpu_ms'][k]:.2f}" for k in ("median_ms", "p99_ms", "max_ms")))
        t.add_row("speed-up", f"{sp['median']:.2f}x", f"{sp['p99']:.2f}x", "")
    console.print(t)
    if "baseline" in res:
        notes = "".join(f"; {n}" for n in res["baseline"]["notes"])
        console.print(f"baseline {res['baseline']['commit'] or res['baseline']['src']}; output rotations differ by "
                      f"at most {res['max_abs_diff_local_rot']:.1e}{notes}")
    ok = "within" if res["p99_within_frame_period"] else "OVER"
    load = ", ".join(f"{x:.2f}" for x in res["machine"]["load_average"])
    console.print(f"p99 {ok} the frame period ({res['frame_period_ms']:.2f} ms); settings "
                  f"{json.dumps(res['settings'])}; recording {res['recording']}; machine reference "
                  f"{res['reference']['best_ms']:.1f} ms; load average {load}")


@bench_app.command("latency")
def latency_cmd(
    model: str = typer.Argument(..., help="Shipped weights (empose12_cpu, pip_cpu, ...), a checkpoint, or segments."),
    recording: Optional[Path] = typer.Option(None, help="A recording with the model's sensors (default: a procedural "
                                                        "clip simulated on the model's kit)."),
    motion: str = typer.Option(DEFAULT_MOTION, help="Procedural family simulated without --recording "
                                                    "(squat, kneel, pickup, sit, lie, crawl, reach)."),
    kit: Optional[str] = typer.Option(None, help="Kit to simulate for a weight-free model (segments)."),
    frames: int = typer.Option(300, min=1, help="Steps timed (after the warm-up)."),
    warmup: int = typer.Option(10, min=0, help="Steps run first and not timed (tracing, first allocations)."),
    threads: int = typer.Option(1, min=1, help="torch CPU threads."),
    seed: int = typer.Option(0, help="Seed of the procedural clip and its simulation."),
    settings: Optional[list[str]] = typer.Option(None, "--set", help="KEY=VALUE: change a cost setting the "
                                                 "estimator has (repeatable), e.g. --set online=stream, "
                                                 "--set window=130,30, --set mc_samples=0."),
    baseline: Optional[Path] = typer.Option(None, help="An older checkout's src/ folder (git worktree add /tmp/old "
                                                       "COMMIT): its code times the same model on the same frames, "
                                                       "interleaved; speed-ups and output difference reported."),
    budget_hz: Optional[float] = typer.Option(None, min=1e-3, help="Compare p99 with this rate's frame period "
                                                                  "(default: the model's rate)."),
    out: Optional[Path] = typer.Option(None, help="Write OUT.json and OUT.md (the table, settings, machine)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Time a model's online step (what the stream server runs per frame): median, p99 and max
    in ms, wall and CPU time, the same keys for every method, with the settings that change the
    cost (N, M, window), the machine reference timing and the load average.

    Example: wearpose bench latency empose12_cpu --frames 300 --threads 1 --json
    A recording of your own: wearpose bench latency pip_cpu --recording recs/imu6.npz
    BiRAE's streaming mode: wearpose bench latency birae6_cpu --set online=stream
    Against an older commit at 120 Hz: wearpose bench latency empose12_cpu --set iterations=4
    --baseline /tmp/old/src --budget-hz 120
    """
    import torch  # start-up: torch loads torch, +1.3 s to wearpose --help

    from wearpose.evaluate.latency import machine_info, open_baseline, reference_timing, step_latency  # start-up: wearpose.evaluate.latency loads torch, +1.7 s to wearpose --help
    from wearpose.estimators.run import open_model  # start-up: wearpose.estimators.run loads torch, +2.0 s to wearpose --help
    from wearpose.recording import load_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help

    torch.set_num_threads(threads)
    source = open_model(model)
    if recording is not None:
        rec, rec_name = load_recording(recording), str(recording)
    else:
        use_kit = source.kit or kit
        if not use_kit:
            raise ConfigError(f"--model {model!r} has no kit of its own: give --kit (the kit to simulate) or --recording")
        rec, rec_name = _procedural_recording(use_kit, motion, seed), f"procedural {motion} (eval seed {seed}), kit {use_kit}"
    machine = machine_info()
    pairs = parse_settings(settings)
    base = open_baseline(baseline, model) if baseline is not None else None
    res = step_latency(source, rec, frames=frames, warmup=warmup, path=recording or "<procedural>", settings=pairs,
                       baseline=base)
    if budget_hz is not None:
        res.update({"frame_period_ms": 1000.0 / budget_hz, "budget_hz": budget_hz,
                    "p99_within_frame_period": bool(res["online_ms"]["p99_ms"] <= 1000.0 / budget_hz)})
    machine_end = machine_info()
    res.update({"threads": threads, "recording": rec_name, "reference": reference_timing(),
                "machine": {**machine, "load_average_end": machine_end["load_average"]},
                "command": shlex.join(["wearpose", *sys.argv[1:]]) if sys.argv[0].endswith("wearpose") else None})
    if res["frames"] < frames:
        err_console.print(f"[yellow]note:[/] the recording gave {res['frames']} timed steps, not {frames}")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(json.dumps(res, indent=2, default=str) + "\n")
        out.with_suffix(".md").write_text(latency_markdown(res))
    _emit(res, as_json, _render)


def _baseline_rows(res: dict[str, Any]) -> list[str]:
    """Markdown rows of the baseline's timings and the speed-ups (none without a baseline)."""
    if "baseline" not in res:
        return []
    b, sp = res["baseline"], res["speedup"]
    row = lambda name, d: f"| {name} | {d['median_ms']:.2f} | {d['p99_ms']:.2f} | {d['max_ms']:.2f} |"  # noqa: E731
    return [row(f"baseline wall ({(b['commit'] or b['src'])[:7]})", b["online_ms"]),
            row(f"baseline CPU ({(b['commit'] or b['src'])[:7]})", b["online_cpu_ms"]),
            f"| speed-up (baseline / this) | {sp['median']:.2f}x | {sp['p99']:.2f}x | |", "",
            f"Baseline: `{b['src']}` at {b['commit']}, settings `{json.dumps(b['settings'])}`, stepped through the "
            f"same frames interleaved with this version (alternating which goes first); CPU median speed-up "
            f"{sp['cpu_median']:.2f}x; output rotations differ by at most {res['max_abs_diff_local_rot']:.1e}"
            + "".join(f"; {n}" for n in b["notes"]) + "."]


def latency_markdown(res: dict[str, Any]) -> str:
    """The result as a markdown table with its settings and machine (for benchmarks/results/)."""
    s, c = res["online_ms"], res["online_cpu_ms"]
    load = ", ".join(f"{x:.2f}" for x in res["machine"]["load_average"])
    return "\n".join([
        f"# {res['model']}: online step latency", "",
        f"`{res.get('command') or 'wearpose bench latency ' + res['model']}`", "",
        "| time | median ms | p99 ms | max ms |", "| --- | ---: | ---: | ---: |",
        f"| wall | {s['median_ms']:.2f} | {s['p99_ms']:.2f} | {s['max_ms']:.2f} |",
        f"| CPU | {c['median_ms']:.2f} | {c['p99_ms']:.2f} | {c['max_ms']:.2f} |",
        *[f"| stage {k} | {v['median_ms']:.2f} | {v['p99_ms']:.2f} | {v['max_ms']:.2f} |"
          for k, v in res["stages_ms"].items()],
        *_baseline_rows(res), "",
        f"{res['frames']} steps after {res['warmup']} warm-up steps at {res['rate_hz']:g} Hz (frame period "
        f"{res['frame_period_ms']:.2f} ms" + (f" of {res['budget_hz']:g} Hz" if res.get("budget_hz") else "")
        + f": p99 {'within' if res['p99_within_frame_period'] else 'over'}); "
        f"{res['threads']} thread(s); settings `{json.dumps(res['settings'])}`; recording: {res['recording']}.",
        f"Machine reference ({res['reference']['loop']}): {res['reference']['best_ms']:.1f} ms best; load average "
        f"{load} at the start, {', '.join(f'{x:.2f}' for x in res['machine']['load_average_end'])} at the end.", ""])
