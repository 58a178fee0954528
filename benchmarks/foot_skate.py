"""Foot skate of the retargeted corpus, per source, before and after the root-travel fix (issue 23).

Run: ``python benchmarks/foot_skate.py [--per-group N] [--out benchmarks/results/foot_skate]``.
Writes ``<out>.md`` and ``<out>.json``.

Clips: the corpus manifest (``$WEARPOSE_DATA``, default ``../shared/data-v2``), grouped per source
and motion (``walk``: descriptions starting with "walk", turns and walk-back included; ``run``:
"run"/"dash"; ``other``: the rest), at most ``--per-group`` clips per group, evenly spaced over
the sorted clip ids, all splits (a conversion check: nothing is trained). BVH rows are
retargeted with :func:`wearpose.motion.retarget_bvh`, AMC rows imported as ``data prepare``
imports them (:func:`wearpose.motion.import_motion`, Y up, the row's fps), onto the default
body (beta = 0).

Per clip, :func:`wearpose.evaluate.foot_skate.clip_foot_skate`: median mid-stance horizontal
speed of the stance foot (stance found from heights only) of the source's floor joints and of the
same SMPL joints for each root travel mode of :func:`wearpose.motion.retarget.root_path`:
``height`` = the converter before motion-4 (root path scaled by the pelvis-to-ankle ratio),
``limb`` = scaled by the hip-to-ankle ratio, ``legs`` = anchored to the planted feet (motion-4's
default). Also the fraction of frames whose lower foot PIP's contact labels call "not in
contact". Per group: median over clips of the clip medians (and the 90th percentile).
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.evaluate.foot_skate import clip_foot_skate
from wearpose.motion import default_rest_joints, import_motion, read_bvh, retarget_bvh
from wearpose.motion.paths import data_dir
from wearpose.motion.retarget import TRAVEL_MODES
from wearpose.motion.store import CONVERTER_VERSION

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ("source", "height", "limb", "legs")


def group_of(description: str) -> str:
    d = description.strip().lower()
    if d.startswith("walk"):
        return "walk"
    if d.startswith(("run", "dash")):
        return "run"
    return "other"


def pick(rows: list[dict[str, str]], n: int) -> list[dict[str, str]]:
    rows = sorted(rows, key=lambda r: r["path"])
    if len(rows) <= n:
        return rows
    return [rows[int(i)] for i in np.linspace(0, len(rows) - 1, n).round()]


def clip_file(data: Path, rel: str) -> Path:
    parts = Path(rel).parts
    cand = data / rel
    return cand if cand.exists() else data.joinpath(*parts[1:])


def measure(data: Path, row: dict[str, str], rest: torch.Tensor) -> dict[str, Any]:
    path = clip_file(data, row["path"])
    if path.name.endswith((".amc", ".amc.gz")):
        res = import_motion(path, rest, up="y", fps=float(row["fps"])).retargeted
    else:
        res = retarget_bvh(read_bvh(path), rest)
    out = clip_foot_skate(res, rest, skip_first=row.get("frame0_is_tpose", "0") == "1")
    out.update(id=f"{row['source']}/{row['subject']}/{row['clip']}", description=row["description"],
               travel_scale=res.tpose.travel_scale, height_scale=res.tpose.scale)
    return out


def summarise(clips: list[dict[str, Any]]) -> dict[str, Any]:
    s: dict[str, Any] = {"clips": len(clips)}
    for c in COLUMNS:
        v = np.array([x[c]["median_ms"] for x in clips], dtype=float)
        ok = v[np.isfinite(v)]
        s[c] = {"median_ms": float(np.median(ok)) if len(ok) else float("nan"),
                "p90_ms": float(np.percentile(ok, 90)) if len(ok) else float("nan"),
                "clips_with_stance": int(len(ok))}
        if c != "source":
            for key in ("contact_miss", "contact_miss_speed", "contact_miss_height"):
                s[c][key] = float(np.mean([x[c][key] for x in clips]))
            travel = np.array([x[c]["stance_travel_cm"] for x in clips], dtype=float)
            s[c]["stance_travel_cm"] = float(np.median(travel[np.isfinite(travel)])) if np.isfinite(travel).any() else float("nan")
    return s


def fmt(x: float, d: int = 3) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{d}f}"


def markdown(result: dict[str, Any]) -> str:
    lines = [
        "# Foot skate of the retargeted corpus (issue 23)",
        "",
        f"`python benchmarks/foot_skate.py --per-group {result['per_group']}` on {result['corpus']} "
        f"(converter {result['converter']}), default body (beta = 0). Median over clips of each clip's "
        "median mid-stance horizontal speed of the stance foot, m/s (90th percentile in brackets); "
        "source = the source skeleton's own toe (else ankle) joints, the others the same SMPL joints "
        "with the root path of each travel mode: **height** = before (motion-3: scaled by the "
        "pelvis-to-ankle ratio), **limb** = scaled by the hip-to-ankle ratio, **legs** = after "
        "(motion-4: anchored to the planted feet). Contact misses: frames whose lower foot PIP's "
        "contact labels (0.48 m/s, 10 cm above the clip's lowest foot point) call not in contact, at 60 Hz; "
        "of which: frames failing the speed test alone, the height test alone.",
        "",
        "| source | motion | clips | source [m/s] | before: height [m/s] | limb [m/s] | after: legs [m/s] "
        "| stance travel before / after [cm] | contact misses before / limb / after | of which speed / height before -> after |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key, s in result["groups"].items():
        src, grp = key.split("/")
        cells = [f"{fmt(s[c]['median_ms'])} ({fmt(s[c]['p90_ms'])})" for c in COLUMNS]
        lines.append(f"| {src} | {grp} | {s['clips']} | " + " | ".join(cells)
                     + f" | {fmt(s['height']['stance_travel_cm'], 1)} / {fmt(s['legs']['stance_travel_cm'], 1)}"
                     + f" | {s['height']['contact_miss'] * 100:.1f} % / {s['limb']['contact_miss'] * 100:.1f} %"
                     + f" / {s['legs']['contact_miss'] * 100:.1f} %"
                     + f" | {s['height']['contact_miss_speed'] * 100:.1f} / {s['height']['contact_miss_height'] * 100:.1f} % -> "
                     + f"{s['legs']['contact_miss_speed'] * 100:.1f} / {s['legs']['contact_miss_height'] * 100:.1f} % |")
    lines += ["", f"Scales (SMPL / source): " + "; ".join(
        f"{k} height {v['height']:.3f}, limb {v['limb']:.3f}" for k, v in result["scales"].items()),
        "", f"{result['seconds']:.0f} s on {result['machine']}.", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-group", type=int, default=60, help="clips per (source, motion) group")
    ap.add_argument("--data", type=Path, default=None, help="corpus folder (default: WEARPOSE_DATA or ../shared/data-v2)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "foot_skate")
    args = ap.parse_args()
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    data = data_dir(args.data)
    with open(data / "manifest.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    rest = default_rest_joints()[0]
    groups: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        groups.setdefault(f"{r['source']}/{group_of(r['description'])}", []).append(r)
    per_clip: dict[str, list[dict[str, Any]]] = {}
    scales: dict[str, dict[str, float]] = {}
    for key in sorted(groups):
        chosen = pick(groups[key], args.per_group)
        per_clip[key] = []
        for i, r in enumerate(chosen):
            m = measure(data, r, rest)
            per_clip[key].append(m)
            scales.setdefault(r["source"], {"height": m["height_scale"], "limb": m["travel_scale"]})
            print(f"\r{key}: {i + 1}/{len(chosen)}", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
    result = {"corpus": str(data), "converter": CONVERTER_VERSION, "per_group": args.per_group,
              "groups": {k: summarise(v) for k, v in per_clip.items()}, "scales": scales,
              "clips": per_clip, "seconds": time.perf_counter() - t0,
              "machine": f"{platform.machine()}, {platform.python_version()}, torch {torch.__version__}, 1 thread"}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    md = markdown(result)
    args.out.with_suffix(".md").write_text(md, encoding="utf-8")
    args.out.with_suffix(".json").write_text(json.dumps(result, indent=1, default=float), encoding="utf-8")
    print(md)


if __name__ == "__main__":
    main()
