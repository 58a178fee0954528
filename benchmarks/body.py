"""Body model throughput, start-up and corpus load time, optionally against an older checkout.

Run: ``python benchmarks/body.py [--baseline /tmp/old/src --baseline-commit <commit>] [--repeats N]
[--threads 1]`` (``git archive <commit> src | tar -x -C /tmp/old`` gives a baseline). Prints a table and writes
``benchmarks/results/body.json`` (+ ``body.md``). Measures (CPU, float32, no grad, one thread by
default), every path interleaved call by call with the baseline's, so load hits both alike:

- full-mesh forward with vertex normals, without normals, joints only (FK, no skinning) and the
  12 sensor sites (``BodyModel.sites``), at B = 1 and B = 1024: median seconds per call and
  and p99 seconds per call, frames/s, and new / baseline speed-ups;
- start-up: whole-process wall time of ``python -c "import torch"`` and ``"import
  wearpose.body"`` (this checkout and the baseline's), interleaved, median of ``--imports``;
- corpus: time to load every clip of the prepared store (``wearpose data prepare`` first).

Every result records the machine reference (:func:`wearpose.evaluate.latency.reference_timing`)
and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from wearpose.body import BodyModel
from wearpose.evaluate.latency import import_baseline, machine_info, reference_timing, time_calls
from wearpose.geometry import axis_angle_to_matrix

SITES_12 = ("head", "pelvis", "left_upper_arm", "right_upper_arm", "left_forearm", "right_forearm",
            "left_wrist", "right_wrist", "left_thigh", "right_thigh", "left_shin", "right_shin")
SRC = Path(__file__).resolve().parents[1] / "src"


def _paths(body: Any) -> dict[str, Any]:
    """name -> fn(pose, betas, trans); ``return_normals`` is passed explicitly (its default changed)."""
    return {
        "full mesh + normals": lambda p, b, t: body(p, b, t, return_normals=True),
        "full mesh, no normals": lambda p, b, t: body(p, b, t, return_normals=False),
        "12 sensor sites": lambda p, b, t: body.sites(p, b, t, SITES_12),
        "joints only": lambda p, b, t: body(p, b, t, return_vertices=False),
    }


def _commit() -> str | None:
    """This checkout's git commit (``None`` outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=SRC.parent, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return out.stdout.strip() or None


def _import_times(baseline: Path | None, repeats: int) -> dict[str, Any]:
    cmds = {"import torch": ("import torch", str(SRC)), "import wearpose.body": ("import wearpose.body", str(SRC))}
    if baseline is not None:
        cmds["import wearpose.body (baseline)"] = ("import wearpose.body", str(baseline))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    times: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(repeats):
        for k, (code, path) in cmds.items():
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", code], env={**env, "PYTHONPATH": path}, check=True)
            times[k].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) for k, v in times.items()}
    out: dict[str, Any] = {"median_s": med, "runs_s": times,
                           "body_over_torch": med["import wearpose.body"] / med["import torch"]}
    if baseline is not None:
        out["baseline_body_over_torch"] = med["import wearpose.body (baseline)"] / med["import torch"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", type=Path, default=None, help="an older checkout's src/ folder to compare with")
    ap.add_argument("--baseline-commit", default=None, help="the baseline's commit, recorded with the results")
    ap.add_argument("--repeats", type=int, default=20, help="calls per path at B = 1 (B = 1024: a fifth, >= 3)")
    ap.add_argument("--imports", type=int, default=5, help="fresh processes per import command")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--no-corpus", action="store_true", help="skip the corpus load timing")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "body.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    con = Console()
    ref0, machine0 = reference_timing(), machine_info()
    body = BodyModel()
    old = import_baseline(args.baseline, "wearpose.body").BodyModel() if args.baseline else None
    g = torch.Generator().manual_seed(0)
    rows: list[dict[str, Any]] = []
    with torch.no_grad():
        for B in (1, 1024):
            pose = axis_angle_to_matrix(torch.randn(B, 24, 3, generator=g) * 0.3)
            betas = torch.randn(B, 10, generator=g)
            trans = torch.randn(B, 3, generator=g)
            reps = args.repeats if B == 1 else max(3, args.repeats // 5)
            new_p = _paths(body)
            fns = {("new", k): (lambda f=f: f(pose, betas, trans)) for k, f in new_p.items()}
            if old is not None:
                for k, f in _paths(old).items():
                    fns[("baseline", k)] = lambda f=f: f(pose, betas, trans)
                a, b = body.sites(pose, betas, trans, SITES_12), old.sites(pose, betas, trans, SITES_12)
                site_diff = float(max((a.positions - b.positions).abs().max(), (a.rotations - b.rotations).abs().max()))
                va, vb = body(pose, betas, trans, return_normals=True), old(pose, betas, trans, return_normals=True)
                mesh_diff = float(max((va.vertices - vb.vertices).abs().max(), (va.normals - vb.normals).abs().max()))
            times = time_calls(fns, reps)
            for k in new_p:
                med = float(np.median(times[("new", k)]))
                row = {"path": k, "batch": B, "median_s": med, "p99_s": float(np.percentile(times[("new", k)], 99)),
                       "frames_per_s": B / med, "calls": reps}
                if old is not None:
                    bmed = float(np.median(times[("baseline", k)]))
                    row.update({"baseline_median_s": bmed, "baseline_p99_s": float(np.percentile(times[("baseline", k)], 99)),
                                "speedup_vs_baseline": bmed / med})
                    row["max_abs_diff_vs_baseline"] = site_diff if k == "12 sensor sites" else (
                        mesh_diff if k.startswith("full mesh + ") else None)
                rows.append(row)
    by = {(r["path"], r["batch"]): r for r in rows}
    ratios = {f"sites_over_full_mesh_normals_B{B}": by[("full mesh + normals", B)]["median_s"] / by[("12 sensor sites", B)]["median_s"]
              for B in (1, 1024)}
    ratios.update({f"sites_over_full_mesh_no_normals_B{B}": by[("full mesh, no normals", B)]["median_s"]
                   / by[("12 sensor sites", B)]["median_s"] for B in (1, 1024)})
    imports = _import_times(args.baseline, args.imports)
    corpus: dict[str, Any] | None = None
    if not args.no_corpus:
        try:
            from wearpose.motion import CorpusStore, cache_dir

            store = CorpusStore(cache_dir())
            ids = store.clips()
            t = time.perf_counter()
            frames = sum(store.load(i).num_frames for i in ids)
            dt = time.perf_counter() - t
            corpus = {"clips_loaded": len(ids), "frames": frames, "seconds": dt, "frames_per_s": frames / dt}
        except Exception as exc:  # the store is optional for this benchmark; say why it was skipped
            corpus = {"skipped": f"{type(exc).__name__}: {exc}"}

    table = Table(title=f"BodyModel forward on CPU ({args.threads} thread(s), {body.num_vertices} vertices)")
    for c in ("path", "batch", "median ms", "frames/s", "vs baseline"):
        table.add_column(c)
    for r in rows:
        table.add_row(r["path"], str(r["batch"]), f"{1000 * r['median_s']:.2f}", f"{r['frames_per_s']:,.0f}",
                      f"{r['speedup_vs_baseline']:.2f}x" if "speedup_vs_baseline" in r else "")
    con.print(table)
    con.print({"ratios": ratios, "imports_median_s": imports["median_s"], "body_over_torch": imports["body_over_torch"],
               "corpus_load": corpus})
    result = {
        "machine": machine0, "reference": ref0, "reference_end": reference_timing(), "machine_end": machine_info(),
        "threads": args.threads, "baseline": str(args.baseline) if args.baseline else None,
        "baseline_commit": args.baseline_commit, "commit": _commit(),
        "asset_id": body.asset_id, "vertices": body.num_vertices,
        "forward": rows, "ratios": ratios, "imports": imports, "corpus_load": corpus,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    md = [f"# BodyModel throughput ({args.threads} thread(s), {body.num_vertices} vertices, asset {body.asset_id})", "",
          f"Reference: {ref0['loop']} best {ref0['best_ms']:.1f} ms ({ref0['gflops']:.1f} GFLOP/s) at the start, "
          f"{result['reference_end']['best_ms']:.1f} ms at the end; load average {machine0['load_average']} -> "
          f"{result['machine_end']['load_average']}. Code: {result['commit'] or 'this checkout'}; baseline: "
          f"{result['baseline_commit'] or result['baseline'] or 'none'}. Calls interleaved with the baseline's.", "",
          "| path | batch | median ms | p99 ms | frames/s | baseline median ms | speed-up vs baseline |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    md += [f"| {r['path']} | {r['batch']} | {1000 * r['median_s']:.2f} | {1000 * r['p99_s']:.2f} | {r['frames_per_s']:,.0f} | "
           + (f"{1000 * r['baseline_median_s']:.2f} | {r['speedup_vs_baseline']:.2f}x |" if "speedup_vs_baseline" in r else " | |")
           for r in rows]
    md += ["", "Sites (12) vs full mesh, same run: " + ", ".join(f"{k} {v:.1f}x" for k, v in ratios.items()), "",
           "Start-up (whole process, median of " + str(args.imports) + "): " + ", ".join(
               f"`{k}` {v:.2f} s" for k, v in imports["median_s"].items())
           + f"; wearpose.body / torch = {imports['body_over_torch']:.2f}"
           + (f" (baseline {imports['baseline_body_over_torch']:.2f})" if "baseline_body_over_torch" in imports else ""), ""]
    args.out.with_suffix(".md").write_text("\n".join(md))


if __name__ == "__main__":
    main()
