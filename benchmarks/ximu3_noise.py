"""IMU noise fitted to the real x-IMU3 log beside the simulator's defaults.

Run: ``python benchmarks/ximu3_noise.py [--log ../shared/real-sensors/ximu3-lower-body]``.
Prints a table and writes ``benchmarks/results/ximu3_noise.{md,json}``. The fit
(``wearpose.calibration.fit_imu_noise``) reads the first second, when the subject stands in the
calibration pose: the feet stand still on the floor (sensor noise); the legs and pelvis sway
(sensor noise plus standing sway, for comparison).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from rich.console import Console
from rich.table import Table

from wearpose.calibration import fit_imu_noise
from wearpose.recording import from_ximu3
from wearpose.sensors.imu import ImuNoise

ROWS = (("gyro_white", "gyro white, deg/s/sqrt(Hz)", math.degrees), ("gyro_bias", "gyro bias, deg/s", math.degrees),
        ("acc_white", "acc white, ug/sqrt(Hz)", lambda v: v / 9.81e-6), ("acc_bias", "acc bias, m/s^2", float),
        ("orientation_white", "orientation white, deg", math.degrees))


def main() -> None:
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, default=here.parents[1] / "shared" / "real-sensors" / "ximu3-lower-body")
    ap.add_argument("--out", type=Path, default=here / "results")
    a = ap.parse_args()
    rec = from_ximu3(a.log)
    feet = fit_imu_noise(rec, (0.0, 1.0), ["left_foot", "right_foot"])
    legs = fit_imu_noise(rec, (0.0, 1.0), [n for n in rec.names if not n.endswith("foot")])
    default = ImuNoise()
    table = Table(title="IMU noise: x-IMU3 log (first 1 s standing) vs simulator default")
    for c in ("term", "default", "fit: feet", "fit: legs + pelvis (with sway)"):
        table.add_column(c, justify="left" if c == "term" else "right")
    rows = []
    for key, label, unit in ROWS:
        r = {"term": label, "default": unit(getattr(default, key)), "feet": unit(feet[key]), "legs_pelvis": unit(legs[key])}
        rows.append(r)
        table.add_row(label, f"{r['default']:.4g}", f"{r['feet']:.4g}", f"{r['legs_pelvis']:.4g}")
    Console().print(table)
    a.out.mkdir(parents=True, exist_ok=True)
    res = {"log": str(a.log), "window_s": [0.0, 1.0], "samples_per_sensor": feet["samples"], "rows": rows,
           "preset": "simulate(noise='ximu3') uses the feet fit (ImuNoise.ximu3)"}
    (a.out / "ximu3_noise.json").write_text(json.dumps(res, indent=1))
    md = ["| term | default | fit: feet | fit: legs + pelvis (with sway) |", "|---|---|---|---|"]
    md += [f"| {r['term']} | {r['default']:.4g} | {r['feet']:.4g} | {r['legs_pelvis']:.4g} |" for r in rows]
    (a.out / "ximu3_noise.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
