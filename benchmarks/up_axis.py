"""The import's up-axis detector on every corpus clip (issue 23 acceptance: right on all corpus clips).

Run: ``python benchmarks/up_axis.py [--data DIR] [--limit N]``. Writes
``benchmarks/results/up_axis.md`` and ``.json``.

Every manifest row (BVH and ASF/AMC) is read as a user's file would be
(:func:`wearpose.motion.importer.read_motion_file`), its skeleton matched
(:func:`wearpose.motion.mapping.match_skeleton`), and :func:`wearpose.motion.importer.detect_up`
run on the whole clip without the corpus's declaration (every corpus clip is Y up: the README
says so). Counted per source: clips detected ``y``, which evidence decided (floor or standing),
and clips with an up-axis warning; the wrong and warned clips are listed.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from wearpose.motion.importer import detect_up, read_motion_file
from wearpose.motion.mapping import match_skeleton
from wearpose.motion.retarget import _rest_offsets


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1].parent / "shared" / "data-v2")
    ap.add_argument("--limit", type=int, default=0, help="first N rows only (0: all)")
    args = ap.parse_args()
    rows = list(csv.DictReader((args.data / "manifest.csv").open()))
    if args.limit:
        rows = rows[: args.limit]
    per: dict[str, dict] = {}
    odd: list[dict] = []
    t0 = time.perf_counter()
    for i, r in enumerate(rows):
        path = args.data / r["path"].removeprefix("data/")
        m = read_motion_file(path, fps=float(r["fps"]))
        smap = match_skeleton(m.skeleton, _rest_offsets(m).numpy(), None, path).smap
        res = detect_up(m, smap)
        s = per.setdefault(r["source"], {"clips": 0, "y": 0, "floor_decided": 0, "warned": 0})
        s["clips"] += 1
        s["y"] += res["axis"] == "y"
        s["floor_decided"] += res["evidence"]["floor"]["axis"] is not None
        s["warned"] += bool(res["warnings"])
        if res["axis"] != "y" or res["warnings"]:
            odd.append({"clip": f"{r['source']}/{r['subject']}/{r['clip']}", "description": r.get("description", ""),
                        "axis": res["axis"], "agreement": round(res["agreement"], 3), "evidence": res["evidence"],
                        "warnings": res["warnings"]})
        if (i + 1) % 200 == 0:
            print(f"{i + 1}/{len(rows)} clips, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    total = {k: sum(s[k] for s in per.values()) for k in ("clips", "y", "floor_decided", "warned")}
    out = {"data": str(args.data), "per_source": per, "total": total, "not_y_or_warned": odd,
           "seconds": round(time.perf_counter() - t0, 1)}
    res_dir = Path(__file__).resolve().parent / "results"
    (res_dir / "up_axis.json").write_text(json.dumps(out, indent=1) + "\n")
    lines = ["# Up-axis detector on the corpus", "", "`python benchmarks/up_axis.py` on " + args.data.name
             + " (every clip is Y up); detector run without the corpus's declaration.", "",
             "| source | clips | detected y | floor decided | warned |", "| --- | --- | --- | --- | --- |"]
    for src, s in list(per.items()) + [("all", total)]:
        lines.append(f"| {src} | {s['clips']} | {s['y']} | {s['floor_decided']} | {s['warned']} |")
    lines += ["", f"{len(odd)} clips not y or warned" + (":" if odd else "."), ""]
    lines += [f"- {o['clip']} ({o['description']}): {o['axis']}, agreement {o['agreement']}; "
              + ("; ".join(o["warnings"]) or "no warning") for o in odd[:60]]
    (res_dir / "up_axis.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:8 + len(per)]))


if __name__ == "__main__":
    main()
