"""tools/results_index.py and the docs' citations of ``benchmarks/results/``: the committed index is
what the tool writes today, every result has a producer, and a doc cites a result file that is no
longer in the tree only at the commit that holds it."""

from __future__ import annotations

import re

from tests.tools.tool_loader import ROOT, load_tool

RESULTS = ROOT / "benchmarks" / "results"

results_index = load_tool("results_index")


def test_committed_index_is_current() -> None:
    """A result added, re-run or removed without ``python tools/results_index.py`` fails here."""
    assert (RESULTS / "README.md").read_text(encoding="utf-8") == results_index.render()


def test_every_result_has_a_producer_and_every_file_a_row() -> None:
    rows = results_index.rows()
    assert [r[0] for r in rows if "(not recorded in the file)" in r[2]] == []
    listed = {m for r in rows for m in re.findall(r"\]\(([^)]+)\)", r[0])}
    assert listed == {p.name for p in RESULTS.iterdir() if p.name != "README.md"}


def test_weights_named_by_run_and_shipped_name() -> None:
    shipped = {"pip_w256_arms": "pip_cpu", "empose12_cpu": "empose12_cpu"}
    assert results_index._weight_name("runs/pip_w256_arms/best.pt", shipped) == "pip_w256_arms (shipped as pip_cpu)"
    assert results_index._weight_name("runs/empose12_cpu/best.pt", shipped) == "empose12_cpu"
    assert results_index._weight_name("src/wearpose/weights/pip_cpu.pt", shipped) == "pip_cpu"
    assert results_index._weight_name("runs/twostage12_lgdik_site.pt", shipped) == "twostage12_lgdik_site"
    assert results_index._weights(None, "python b.py --ckpt a=runs/x/best.pt --weights miposer_cpu", shipped) \
        == "x, miposer_cpu"
    # the cards name the run each shipped (or archived) weights file came from
    runs = results_index.shipped_runs()
    assert runs["pip_w256_arms"] == "pip_cpu_v1" and runs["pip_v2"] == "pip_cpu" and runs["miposer_v2"] == "miposer_cpu"


def _result_like(name: str, prefixes: set[str]) -> bool:
    return name.split("_")[0].split(".")[0] in prefixes


def test_docs_cite_removed_results_at_their_commit() -> None:
    """`name.json` / `name.md` in docs/*.md that looks like a result (its first word starts a result
    file's name) is in benchmarks/results/ (or is a doc page), else followed by "at commit `<sha>`"."""
    present = {p.name for p in RESULTS.iterdir()} | {p.name for p in (ROOT / "docs").iterdir()}
    prefixes = {p.name.split("_")[0].split(".")[0] for p in RESULTS.iterdir() if p.name != "README.md"}
    cite = re.compile(r"`(?:benchmarks/results/)?([\w.-]+?)(\.md/\.json|\.json|\.md|\.png)`"
                      r"( at commit `[0-9a-f]{7,}`)?")
    dangling = []
    for doc in sorted((ROOT / "docs").glob("*.md")):
        for n, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            for m in cite.finditer(line):
                name = m.group(1) + (".md" if m.group(2) == ".md/.json" else m.group(2))
                if _result_like(name, prefixes) and name not in present and not m.group(3):
                    dangling.append(f"{doc.name}:{n}: {name}")
    assert dangling == []
