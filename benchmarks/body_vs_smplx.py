"""wearpose's BodyModel against smplx on the same SMPL-format model file, one thread, one run.

Run: ``python benchmarks/body_vs_smplx.py [--repeats N] [--threads 1]`` (needs the ``bench``
extra: ``pip install -e '.[bench]'``; smplx is a benchmark-only comparison, never a runtime
dependency, and its licence is non-commercial).

The model file is written here: the embedded free asset (13,718 vertices) in SMPL's pickle
layout (``v_template``, ``f``, ``shapedirs`` ``(V, 3, 10)``, ``J_regressor``, ``weights``,
``kintree_table``) plus synthetic pose correctives ``posedirs`` ``(V, 3, 207)`` (the free asset
has none; SMPL always has them and smplx always applies them, so both do equal work). Both
libraries load that file; joints (the 24 SMPL joints) and vertices are checked equal on random
poses; then forward calls with axis-angle input ``(B, 72)``, betas and translation are timed at
B = 1 and B = 1024, interleaved call by call:

- smplx ``SMPL.forward`` (always skins the mesh: its joints are regressed from it);
- wearpose full mesh (vertices, no normals: the work smplx does), full mesh with vertex normals,
  joints only (forward kinematics on the regressed rest skeleton), and the 12-site fast path.

Writes ``benchmarks/results/body_vs_smplx.json`` and ``.md`` with the machine reference
(:func:`wearpose.evaluate.latency.reference_timing`) and the load average.
"""

from __future__ import annotations

import argparse
import json
import pickle
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from wearpose.body import BodyModel, load_default_asset
from wearpose.body.skeleton import PARENTS
from wearpose.evaluate.latency import machine_info, reference_timing, time_calls

SITES_12 = ("head", "pelvis", "left_upper_arm", "right_upper_arm", "left_forearm", "right_forearm",
            "left_wrist", "right_wrist", "left_thigh", "right_thigh", "left_shin", "right_shin")


def write_smpl_file(path: Path, seed: int = 0) -> Path:
    """The embedded asset in SMPL's pickle layout with synthetic pose correctives (module doc)."""
    a = load_default_asset()
    rng = np.random.default_rng(seed)
    V = a.num_vertices
    kintree = np.array([[4294967295] + list(PARENTS[1:]), list(range(24))], dtype=np.int64)
    d = {"v_template": a.v_template.astype(np.float64), "f": a.faces.astype(np.uint32),
         "shapedirs": a.shapedirs[:, :, :10].astype(np.float64), "J_regressor": a.J_regressor.astype(np.float64),
         "weights": a.weights.astype(np.float64), "kintree_table": kintree,
         "posedirs": rng.normal(scale=1e-3, size=(V, 3, 207))}
    with open(path, "wb") as f:
        pickle.dump(d, f, protocol=2)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=20, help="calls per path at B = 1 (B = 1024: a fifth, >= 3)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "body_vs_smplx.json")
    args = ap.parse_args()
    import smplx  # the bench extra

    torch.set_num_threads(args.threads)
    ref0, machine0 = reference_timing(), machine_info()
    with tempfile.TemporaryDirectory() as tmp:
        path = write_smpl_file(Path(tmp) / "SMPL_NEUTRAL.pkl")
        ours = BodyModel(path)
        theirs = smplx.SMPL(model_path=str(path), num_betas=10)
    # An SMPL file carries no sensor sites: the 12 sites of the embedded asset by vertex id (same mesh).
    asset = load_default_asset()
    pos = [asset.site_names.index(n) for n in SITES_12]
    site_v, site_t = asset.site_vertices[pos].tolist(), asset.site_tangent[pos].tolist()
    g = torch.Generator().manual_seed(0)

    def smplx_call(aa: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor) -> Any:
        return theirs(betas=betas, global_orient=aa[:, :3], body_pose=aa[:, 3:], transl=trans)

    with torch.no_grad():
        aa = torch.randn(64, 72, generator=g) * 0.4
        betas = torch.randn(64, 10, generator=g)
        trans = torch.randn(64, 3, generator=g)
        a, b = ours(aa, betas, trans), smplx_call(aa, betas, trans)
        check = {"poses": 64, "max_abs_joint_diff_m": float((a.joints - b.joints[:, :24]).abs().max()),
                 "max_abs_vertex_diff_m": float((a.vertices - b.vertices).abs().max()),
                 "joints_only_vs_smplx_joints_m": float((ours(aa, betas, trans, return_vertices=False).joints
                                                         - b.joints[:, :24]).abs().max())}
        rows: list[dict[str, Any]] = []
        for B in (1, 1024):
            aa = torch.randn(B, 72, generator=g) * 0.4
            betas = torch.randn(B, 10, generator=g)
            trans = torch.randn(B, 3, generator=g)
            fns = {
                "smplx full mesh": lambda: smplx_call(aa, betas, trans),
                "wearpose full mesh": lambda: ours(aa, betas, trans),
                "wearpose full mesh + normals": lambda: ours(aa, betas, trans, return_normals=True),
                "wearpose joints only": lambda: ours(aa, betas, trans, return_vertices=False),
                "wearpose 12 sites": lambda: ours.sites(aa, betas, trans, vertex_ids=site_v, tangent_ids=site_t),
            }
            reps = args.repeats if B == 1 else max(3, args.repeats // 5)
            times = time_calls(fns, reps)
            base = float(np.median(times["smplx full mesh"]))
            for k, v in times.items():
                med = float(np.median(v))
                rows.append({"path": k, "batch": B, "median_ms": 1000 * med, "p99_ms": 1000 * float(np.percentile(v, 99)),
                             "frames_per_s": B / med, "speed_vs_smplx_full_mesh": base / med, "calls": reps})
    res = {"machine": machine0, "reference": ref0, "reference_end": reference_timing(), "machine_end": machine_info(),
           "threads": args.threads, "smplx": smplx.__version__ if hasattr(smplx, "__version__") else "0.1.28",
           "model_file": "embedded asset in SMPL pickle layout + synthetic posedirs (V, 3, 207)",
           "vertices": ours.num_vertices, "check": check, "forward": rows}
    table = Table(title=f"wearpose vs smplx, same SMPL-format file ({ours.num_vertices} vertices), {args.threads} thread(s)")
    for c in ("path", "batch", "median ms", "p99 ms", "frames/s", "x smplx full mesh"):
        table.add_column(c)
    for r in rows:
        table.add_row(r["path"], str(r["batch"]), f"{r['median_ms']:.2f}", f"{r['p99_ms']:.2f}", f"{r['frames_per_s']:,.0f}",
                      f"{r['speed_vs_smplx_full_mesh']:.2f}x")
    con = Console()
    con.print(table)
    con.print(check)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2) + "\n")
    md = [f"# wearpose BodyModel vs smplx {res['smplx']} ({args.threads} thread(s), {ours.num_vertices} vertices)", "",
          f"Same SMPL-format file ({res['model_file']}), loaded by both; axis-angle input. Equality on 64 random "
          f"poses: joints {check['max_abs_joint_diff_m']:.1e} m, vertices {check['max_abs_vertex_diff_m']:.1e} m "
          f"(joints-only path {check['joints_only_vs_smplx_joints_m']:.1e} m). smplx skins the mesh on every call "
          "(its joints come from the posed mesh); wearpose's full mesh here has no normals (equal work).", "",
          f"Reference: {ref0['loop']} best {ref0['best_ms']:.1f} ms ({ref0['gflops']:.1f} GFLOP/s) at the start, "
          f"{res['reference_end']['best_ms']:.1f} ms at the end; load average {machine0['load_average']} -> "
          f"{res['machine_end']['load_average']}. Calls interleaved path by path.", "",
          "| path | batch | median ms | p99 ms | frames/s | x smplx full mesh |", "| --- | --- | --- | --- | --- | --- |"]
    md += [f"| {r['path']} | {r['batch']} | {r['median_ms']:.2f} | {r['p99_ms']:.2f} | {r['frames_per_s']:,.0f} | "
           f"{r['speed_vs_smplx_full_mesh']:.2f}x |" for r in rows]
    args.out.with_suffix(".md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
