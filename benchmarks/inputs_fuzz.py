"""Hostile input to the live-input decoders (Xsens MVN datagrams, OSC bundles, LSL samples),
fuzzed with hypothesis.

Run: ``python benchmarks/inputs_fuzz.py [--examples 10000]``. Runs
``tests/stream/test_inputs_fuzz.py`` (CI runs 200 examples per test) with ``--examples`` each
and counts the inputs tried (a receive-path example sends 1-5 datagrams or samples). Passing
means every input was decoded or raised ``PacketError``, and the inputs' receive paths never
raised. Writes ``benchmarks/results/inputs_fuzz.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT)]  # recording_fuzz beside this; tests.* as pytest imports it
from recording_fuzz import _Collect  # noqa: E402 - the same per-test outcome collector

TEST = ROOT / "tests" / "stream" / "test_inputs_fuzz.py"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=10_000, help="hypothesis examples per test")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "inputs_fuzz")
    args = ap.parse_args()
    os.environ["WEARPOSE_FUZZ_EXAMPLES"] = str(args.examples)
    plugin = _Collect()
    t0 = time.time()
    code = pytest.main([str(TEST), "-q", "-p", "no:cacheprovider", "-p", "no:randomly"], plugins=[plugin])
    seconds = time.time() - t0
    mod = next(m for m in list(sys.modules.values()) if getattr(m, "__file__", None) == str(TEST))
    git = ["git", "-C", str(ROOT)]
    commit = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run([*git, "status", "--porcelain", "src", str(TEST)], capture_output=True, text=True).stdout.strip())
    for name, row in plugin.rows.items():
        row["inputs_tried"] = mod.TRIED.get(name, 0)
    failed = [n for n, r in plugin.rows.items() if r["outcome"] != "passed"]
    res = {"command": f"python benchmarks/inputs_fuzz.py --examples {args.examples}", "examples_per_test": args.examples, "inputs_tried": sum(mod.TRIED.values()), "failed_tests": failed,
           "pytest_exit_code": int(code), "seconds": round(seconds, 1), "tests": plugin.rows, "commit": commit,
           "uncommitted_source_edits": dirty, "python": platform.python_version(),
           "load_average_at_end": os.getloadavg()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=2) + "\n")
    lines = ["# Live-input decoder fuzzing (MVN, OSC, LSL; hypothesis)", "",
             f"Produced by `{res['command']}`; commit `{commit}`"
             f"{' with uncommitted edits' if dirty else ''}; {seconds / 60:.1f} min on the shared 2-core machine "
             f"(load average at the end {res['load_average_at_end'][0]:.1f}).", "",
             "| test | inputs tried | outcome | seconds |", "| --- | --- | --- | --- |"]
    lines += [f"| `{n}` | {r['inputs_tried']:,} | {r['outcome']} | {r['seconds']} |" for n, r in plugin.rows.items()]
    lines += [f"| **total** | **{res['inputs_tried']:,}** | {'all passed' if not failed else 'FAILED: ' + ', '.join(failed)} | |",
              "", "Passed = every input decoded or raised `PacketError` (the documented error), and "
              "`MvnInput.datagram`, `OscInput.datagram`, `LslInput._samples` never raised (bad input counted as malformed)."]
    for n in failed:
        lines += ["", f"## {n}", "", "```", (plugin.rows[n]["failure"] or "")[-1500:], "```"]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
