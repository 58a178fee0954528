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


def _producer(js: dict | None, md: str | None) -> str:
    for k in ("command", "produced_by", "cmd"):
        if isinstance(js, dict) and isinstance(js.get(k), str):
            return js[k]
    m = re.search(r"Produced by `([^`]+)`", md or "")
    return m.group(1) if m else "(not recorded in the file)"


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
        out.append((f"`{stem}` {files}", title.replace("|", "/"), _producer(js, md).replace("|", "/"), _weights(js)))
    return out


def main() -> None:
    lines = ["# Benchmark results", "",
             "Written by `python tools/results_index.py` from the files themselves: each result's title, the "
             "command that produced it (as recorded in the file) and the weights it names. A result whose "
             "producer is not recorded says so; re-running its benchmark records it.", "",
             "| result | title | produced by | weights |", "| --- | --- | --- | --- |"]
    lines += [f"| {a} | {b} | `{c}` | {d} |" for a, b, c, d in rows()]
    (RESULTS / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {RESULTS / 'README.md'} ({len(lines) - 6} results)")


if __name__ == "__main__":
    main()
