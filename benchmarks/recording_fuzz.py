"""Hostile files for the recording reader: ``load_recording`` fuzzed with hypothesis.

Run: ``python benchmarks/recording_fuzz.py [--examples 1250]``. Runs the strategies of
``tests/recording/test_fuzz.py`` (random bytes; a valid file truncated or overwritten; arrays
replaced by any dtype/shape, dropped, compressed; arrays of the right shape with hostile values,
byte orders and dtypes; every sensor-info and ground-truth header field set to any JSON; header
text that is not JSON or nested past the recursion limit; forged ``.npy`` headers declaring huge
shapes over a few bytes) with ``--examples`` inputs each (CI runs 60), and counts the files
loaded. Passing means every file either loaded or raised ``InputFileError`` with a problem and an
expected form, never through the reader's safety net (an unanticipated exception) and never
another exception type. Writes ``benchmarks/results/recording_fuzz.{md,json}``.
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
TEST = ROOT / "tests" / "recording" / "test_fuzz.py"


class _Collect:
    """pytest plugin: outcome and duration per test."""

    def __init__(self) -> None:
        self.rows: dict[str, dict] = {}

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" or (report.when == "setup" and report.outcome != "passed"):
            name = report.nodeid.split("::")[-1]
            self.rows[name] = {"outcome": report.outcome, "seconds": round(report.duration, 1),
                               "failure": str(report.longrepr)[-2000:] if report.failed else None}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=1250, help="hypothesis examples per strategy")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "recording_fuzz")
    ap.add_argument("-k", dest="only", default=None,
                    help="re-run only these strategies (pytest -k) and replace their rows in the existing --out "
                         "JSON (after a fix: each row keeps the commit it ran at)")
    args = ap.parse_args()
    os.environ["WEARPOSE_FUZZ_EXAMPLES"] = str(args.examples)
    plugin = _Collect()
    t0 = time.time()
    code = pytest.main([str(TEST), "-q", "-p", "no:cacheprovider", "--durations=0"]
                       + (["-k", args.only] if args.only else []), plugins=[plugin])
    seconds = time.time() - t0
    mod = next(m for m in list(sys.modules.values()) if getattr(m, "__file__", None) == str(TEST))
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    for name, row in plugin.rows.items():
        row["files_loaded"] = mod.LOADS.get(name, 0)
        row["commit"] = commit
    if args.only and args.out.with_suffix(".json").is_file():
        old = json.loads(args.out.with_suffix(".json").read_text())
        earlier = {n: {**r, "commit": r.get("commit", old.get("commit"))} for n, r in old["strategies"].items()}
        plugin.rows = {**earlier, **plugin.rows}
        code = 0 if all(r["outcome"] == "passed" for r in plugin.rows.values()) else 1
    total = sum(r["files_loaded"] for r in plugin.rows.values())
    failed = [n for n, r in plugin.rows.items() if r["outcome"] != "passed"]
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "src", "tests/recording/test_fuzz.py"],
                           capture_output=True, text=True).stdout.strip()
    res = {"examples_per_strategy": args.examples, "files_loaded": total, "failed_strategies": failed,
           "pytest_exit_code": int(code), "seconds": round(seconds, 1), "strategies": plugin.rows,
           "commit": commit, "uncommitted_source_edits": bool(dirty), "python": platform.python_version(),
           "load_average_at_end": os.getloadavg()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=2) + "\n")
    lines = [f"# Recording reader fuzzing (`load_recording`, hypothesis)", "",
             "Each row ran at the commit in its column (a strategy re-run after a fix with `-k`).", "",
             f"`python benchmarks/recording_fuzz.py --examples {args.examples}`; commit `{commit}`"
             f"{' with uncommitted edits' if dirty else ''}; {seconds / 60:.1f} min on the shared 2-core machine "
             f"(load average at the end {res['load_average_at_end'][0]:.1f}).", "",
             "| strategy | files loaded | outcome | seconds | commit |", "| --- | --- | --- | --- | --- |"]
    for name, r in plugin.rows.items():
        lines.append(f"| `{name}` | {r['files_loaded']:,} | {r['outcome']} | {r['seconds']} | `{r.get('commit', commit)}` |")
    lines += [f"| **total** | **{total:,}** | {'all passed' if not failed else 'FAILED: ' + ', '.join(failed)} | | |", "",
              "Passed = every file loaded or raised `InputFileError` naming a problem and the expected form, never "
              "through the reader's safety net and never another exception type. A strategy may load a file more "
              "than once per example (truncated and overwritten copies)."]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
