"""How two conversion chains of the same captures differ, joint by joint.

Run: ``python benchmarks/chain_offsets.py [--out benchmarks/results/chain_offsets]``. Writes
``<out>.md`` and ``<out>.json``.

The corpus holds CMU's takes 02_01-04 twice: through cgspeed's Daz BVH conversion
(``cmu_daz/02``) and as CMU's own ASF/AMC (``crosscheck/cmu_asf/02``). Each version is imported
onto SMPL-24 (:func:`wearpose.motion.import_motion`, the importer a user's file goes through),
both are brought to 60 Hz, the Daz file's first two frames are dropped (0 is the converter's
T-pose, 1 still blends from it: tests/motion/crosscheck_testutils.py), and the frames are aligned by the lag (within +-0.1 s) that makes the local rotations closest. Then
:func:`wearpose.motion.augment.joint_frame_offsets` per take: the constant per-joint offset
between the versions, how constant it is, and the local-rotation difference a model sees. This is
what ``--rest-offset`` (:func:`wearpose.motion.augment.offset_rest`) simulates; its recipes use
the largest offset found at a major joint.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import torch

from wearpose.body.skeleton import JOINT_NAMES, MAJOR_JOINTS
from wearpose.geometry import geodesic_angle
from wearpose.motion import data_dir, import_motion, resample
from wearpose.motion.augment import joint_frame_offsets

ROOT = Path(__file__).resolve().parents[1]
TAKES = ("02_01", "02_02", "02_03", "02_04")
RATE_HZ = 60.0
MAX_LAG = 6  # frames at 60 Hz
DAZ_SKIP = 2  # the converter's T-pose and the frame blending from it


def aligned(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, int]:
    """``a``, ``b`` ``(T, 24, 3, 3)`` cut to their overlap at the lag (b later by ``lag`` frames)
    whose mean local angle is smallest."""
    best = None
    for lag in range(-MAX_LAG, MAX_LAG + 1):
        x, y = (a[lag:], b) if lag >= 0 else (a, b[-lag:])
        n = min(len(x), len(y))
        err = float(geodesic_angle(x[:n].double(), y[:n].double()).mean())
        if best is None or err < best[0]:
            best = (err, x[:n], y[:n], lag)
    return best[1], best[2], best[3]


def measure(data: Path) -> dict:
    takes = {}
    for take in TAKES:
        daz = resample(import_motion(data / "cmu_daz" / "02" / f"{take}.bvh.gz").sequence, RATE_HZ)
        asf = resample(import_motion(data / "crosscheck" / "cmu_asf" / "02" / f"{take}.amc.gz").sequence, RATE_HZ)
        a, b, lag = aligned(daz.pose[DAZ_SKIP:], asf.pose)
        off = joint_frame_offsets(a, b)
        takes[take] = {"frames": len(a), "lag_frames": lag, "angle_deg": off.angle_deg.tolist(),
                       "spread_deg": off.spread_deg.tolist(), "local_deg": off.local_deg.tolist()}
    return takes


def table(takes: dict) -> list[str]:
    mean = {k: torch.tensor([t[k] for t in takes.values()]).mean(0) for k in ("angle_deg", "spread_deg", "local_deg")}
    lo = torch.tensor([t["angle_deg"] for t in takes.values()]).min(0).values
    hi = torch.tensor([t["angle_deg"] for t in takes.values()]).max(0).values
    lines = ["| joint | constant offset [deg] (4 takes: mean, range) | its spread over a take [deg] | "
             "local rotation difference [deg] |", "| --- | --- | --- | --- |"]
    for j in MAJOR_JOINTS:
        lines.append(f"| {JOINT_NAMES[j]} | {mean['angle_deg'][j]:.1f} ({lo[j]:.1f}-{hi[j]:.1f}) | "
                     f"{mean['spread_deg'][j]:.1f} | {mean['local_deg'][j]:.1f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="corpus directory (default: ../shared/data-v2)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "chain_offsets"))
    args = ap.parse_args(argv)
    takes = measure(data_dir(args.data))
    major = [max(t["angle_deg"][j] for j in MAJOR_JOINTS) for t in takes.values()]
    cmd = "python benchmarks/chain_offsets.py" + ("" if argv is None else " " + " ".join(argv))
    md = ["# Two conversion chains of the same captures: per-joint offsets", "",
          f"Produced by `{cmd}` (`wearpose.motion.augment.joint_frame_offsets`).", "",
          "CMU takes 02_01-04 through the Daz BVH conversion (`cmu_daz/02`) against CMU's own ASF/AMC "
          "(`crosscheck/cmu_asf/02`), both imported onto SMPL-24, at 60 Hz, aligned by lag "
          f"({', '.join(str(t['lag_frames']) for t in takes.values())} frames), "
          f"{sum(t['frames'] for t in takes.values())} frames in all. The 15 major joints:", "",
          *table(takes), "",
          f"Largest constant offset at a major joint, per take: {', '.join(f'{m:.1f}' for m in major)} deg. "
          "`--rest-offset` draws each joint's offset about a random axis, angle uniform up to the value given."]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    blob = {"command": cmd, "takes": takes, "joints": list(JOINT_NAMES), "major_joints": list(MAJOR_JOINTS),
            "machine": {"python": platform.python_version(), "torch": torch.__version__}}
    out.with_suffix(".json").write_text(json.dumps(blob, indent=1) + "\n", encoding="utf-8")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
