"""``wearpose train <method> --config tiny`` (README's smoke test) for every trainable method:
wall and CPU seconds, against issue 22's "under a minute".

Run: ``python benchmarks/train_tiny.py [--cold]``. Each method runs as a user runs it, one
process per method (``nice -n 10``, ``--threads 1``, ``OMP_NUM_THREADS=1``) into a fresh temporary
run directory, on the prepared store of ``$WEARPOSE_CACHE`` (default ``~/.cache/wearpose``). The
``data cache`` column says whether the method's simulated training windows
(``<store>/estimators/<method>``) existed before the run (``warm``) or were simulated in it
(``cold``); ``--cold`` runs on a temporary view of the store (its index copied, its clips linked)
without them, as a first run after ``wearpose data prepare``. Writes
``benchmarks/results/train_tiny[_cold].{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 60.0


def _run(method: str, store: Path) -> dict:
    cache = store / "estimators" / method
    warm = cache.is_dir() and any(cache.iterdir())
    env = {**os.environ, "OMP_NUM_THREADS": "1", "WEARPOSE_CACHE": str(store)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.TemporaryDirectory() as tmp:
        cmd = ["nice", "-n", "10", sys.executable, "-m", "wearpose.cli", "train", method, "--config", "tiny",
               "--threads", "1", "--out", str(Path(tmp) / "run"), "--json"]
        t0 = time.perf_counter()
        p = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"method": method, "exit_code": p.returncode, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
            "data_cache": "warm" if warm else "cold", "under_a_minute": wall < LIMIT_S,
            "load_average_after": round(os.getloadavg()[0], 1),
            "stderr_tail": p.stderr[-800:] if p.returncode else ""}


def main() -> int:
    from wearpose.estimators.registry import list_methods
    from wearpose.motion import cache_dir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cold", action="store_true", help="no simulated training windows cached (module doc)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    args.out = args.out or ROOT / "benchmarks" / "results" / ("train_tiny_cold" if args.cold else "train_tiny")
    store = cache_dir()
    with tempfile.TemporaryDirectory() as view:
        if args.cold:  # the prepared clips without any method's cached training windows
            for item in store.iterdir():
                if item.name != "estimators":
                    (Path(view) / item.name).symlink_to(item, target_is_directory=item.is_dir())
            store = Path(view)
        rows = [_run(m, store) for m in list_methods(trainable=True)]
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    res = {"command": "python benchmarks/train_tiny.py" + (" --cold" if args.cold else ""), "rows": rows,
           "store": str(cache_dir()), "cold": args.cold, "commit": commit, "python": platform.python_version(), "cores": os.cpu_count()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=2) + "\n")
    lines = ["# `wearpose train <method> --config tiny`", "",
             f"Produced by `{res['command']}`; commit `{commit}`; one process per method, nice 10, one thread, "
             f"on the shared {os.cpu_count()}-core machine.", "",
             "| method | exit | wall s | CPU s | data cache | under a minute | load after |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {r['method']} | {r['exit_code']} | {r['wall_s']} | {r['cpu_s']} | {r['data_cache']} | "
              f"{'yes' if r['under_a_minute'] else 'NO'} | {r['load_average_after']} |" for r in rows]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0 if all(r["exit_code"] == 0 and r["under_a_minute"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
