"""Body model throughput and corpus load time.

Run: ``python benchmarks/body.py [--repeats N] [--threads N]``. Prints a table and writes
``benchmarks/results/body.json``. Measures (CPU, float32, no grad):
- full-mesh forward (vertices + normals) frames/s at B=1 and B=1024;
- 12 sensor sites only (``BodyModel.sites``) frames/s at B=1 and B=1024;
- joints only (FK, no skinning) frames/s;
- corpus: time to load every clip of the prepared store (``wearpose data prepare`` first).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from wearpose.body import BodyModel
from wearpose.geometry import axis_angle_to_matrix

SITES_12 = ("head", "pelvis", "left_upper_arm", "right_upper_arm", "left_forearm", "right_forearm",
            "left_wrist", "right_wrist", "left_thigh", "right_thigh", "left_shin", "right_shin")


def _rate(fn, batch: int, repeats: int) -> float:
    fn()  # warm-up (allocations, lazy caches)
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return batch / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "body.json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    body = BodyModel()
    rows = []
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for B in (1, 1024):
            pose = axis_angle_to_matrix(torch.randn(B, 24, 3, generator=g) * 0.3)
            betas = torch.randn(B, 10, generator=g)
            trans = torch.randn(B, 3, generator=g)
            rows.append(("full mesh + normals", B, _rate(lambda: body(pose, betas, trans), B, args.repeats)))
            rows.append(("12 sensor sites", B, _rate(lambda: body.sites(pose, betas, trans, SITES_12), B, args.repeats)))
            rows.append(("joints only", B, _rate(lambda: body(pose, betas, trans, return_vertices=False), B, args.repeats)))
    corpus = None
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

    table = Table(title=f"BodyModel forward on CPU ({args.threads} threads, {body.num_vertices} vertices)")
    for c in ("path", "batch", "frames/s"):
        table.add_column(c)
    for name, B, r in rows:
        table.add_row(name, str(B), f"{r:,.0f}")
    Console().print(table)
    Console().print({"corpus_load": corpus})
    result = {
        "machine": {"platform": platform.platform(), "cpu_count": torch.get_num_threads(), "torch": torch.__version__},
        "asset_id": body.asset_id, "vertices": body.num_vertices,
        "forward": [{"path": n, "batch": B, "frames_per_s": r} for n, B, r in rows],
        "corpus_load": corpus,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
