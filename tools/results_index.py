"""Write ``benchmarks/results/README.md``: one row per result (a ``.md`` table and/or its
``.json``), with its title, the command that produced it and the weights it names, read from
the files themselves (the ``command`` / ``produced_by`` field of the JSON, else the markdown's
"Produced by" line). Rows whose producer is not recorded say so.

Run: ``python tools/results_index.py`` (after adding or re-running a benchmark).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"

#: Producers of results whose file does not record one, from the commit that wrote the file
#: (``git log -- benchmarks/results/<stem>.json``); re-running the benchmark records it in the file.
PRODUCERS = {
    "birae_stream_latency": "python benchmarks/birae_stream.py --skip-eval (commit 45d3452)",
    "birae_stream_test": "python benchmarks/birae_stream.py (evaluate mode='stream', noise scenario, test split, "
                         "every 10th frame; commit 0d23f7c)",
    "body": "python benchmarks/body.py --baseline <a checkout of e726f1e>/src (commit 0e330e5)",
    "body_vs_smplx": "python benchmarks/body_vs_smplx.py --threads 1 (commit 9d01953)",
    "card_reproduction": "python benchmarks/card_reproduction.py (commit 2c8556c)",
    "convention_checks": "python benchmarks/convention_checks.py (80 clips per kit x 2 noise settings; commit d2f963b)",
    "foot_skate": "python benchmarks/foot_skate.py (60 clips per source x motion; commit 0a8dbc3)",
    "live_inputs": "python benchmarks/live_inputs.py --wait 2400 (commit 521ba91)",
    "recording_fuzz": "python benchmarks/recording_fuzz.py --examples 1250 (commit 2906dca)",
    "simulate": "python benchmarks/simulate.py (em12, val split, 1 and 2 workers; commit eb3a866)",
    "up_axis": "python benchmarks/up_axis.py (commit 94ede4c)",
    "ximu3_noise": "python benchmarks/ximu3_noise.py (commit d7799b5)",
}


def _producer(stem: str, js: dict | None, md: str | None) -> str:
    for k in ("command", "produced_by", "cmd"):
        if isinstance(js, dict) and isinstance(js.get(k), str):
            return js[k]
    m = re.search(r"Produced by `([^`]+)`", md or "")
    return m.group(1) if m else PRODUCERS.get(stem, "(not recorded in the file)")


def _weights(js: dict | None) -> str:
    if not isinstance(js, dict):
        return ""
    for k in ("weights", "checkpoints", "checkpoint", "model"):
        v = js.get(k)
        if isinstance(v, str):
            return Path(v).stem
        if isinstance(v, dict):
            return ", ".join(sorted(Path(str(x)).stem if not isinstance(x, dict) else str(n) for n, x in v.items()))
        if isinstance(v, list):
            return ", ".join(Path(str(x)).stem for x in v)
    return ""


def rows() -> list[tuple[str, str, str, str]]:
    """``(stem, title, producer, weights)`` for every result stem, sorted."""
    out = []
    stems = sorted({p.stem for p in RESULTS.iterdir() if p.suffix in (".md", ".json") and p.name != "README.md"})
    for stem in stems:
        md_path, js_path = RESULTS / f"{stem}.md", RESULTS / f"{stem}.json"
        md = md_path.read_text(encoding="utf-8") if md_path.is_file() else None
        try:
            js = json.loads(js_path.read_text(encoding="utf-8")) if js_path.is_file() else None
        except ValueError:
            js = None
        title = next((ln.lstrip("# ").strip() for ln in (md or "").splitlines() if ln.startswith("#")), "")
        files = " ".join(f"[{p.suffix[1:]}]({p.name})" for p in (md_path, js_path) if p.is_file())
        out.append((f"`{stem}` {files}", title.replace("|", "/"), _producer(stem, js, md).replace("|", "/"), _weights(js)))
    return out


def main() -> None:
    lines = ["# Benchmark results", "",
             "Written by `python tools/results_index.py` from the files themselves: each result's title, the "
             "command that produced it (as recorded in the file) and the weights it names. A result whose "
             "producer is not recorded in it is given from the commit that wrote it (`PRODUCERS` in the tool); "
             "superseded variants are removed from the tree (git keeps them).", "",
             "| result | title | produced by | weights |", "| --- | --- | --- | --- |"]
    lines += [f"| {a} | {b} | `{c}` | {d} |" for a, b, c, d in rows()]
    (RESULTS / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {RESULTS / 'README.md'} ({len(lines) - 6} results)")


if __name__ == "__main__":
    main()
