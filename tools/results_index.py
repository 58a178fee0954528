"""Write ``benchmarks/results/README.md``: one row per result (a ``.md`` table and/or its
``.json``), with its title, the command that produced it and the weights it names, read from
the files themselves (the ``command`` / ``produced_by`` field of the JSON, else the markdown's
"Produced by" line). Rows whose producer is not recorded say so. Weights are named by their run
directory (``runs/pip_w256_arms/best.pt`` -> ``pip_w256_arms``), with the shipped name a weights
card (``src/wearpose/weights/*.json``, ``shipped_with``) gives that run.

Run: ``python tools/results_index.py`` (after adding or re-running a benchmark).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
CARDS = ROOT / "src" / "wearpose" / "weights"

#: Producers of results whose file does not record one, from the commit that wrote the file
#: (``git log -- benchmarks/results/<stem>.json``); re-running the benchmark records it in the file.
PRODUCERS = {
    "birae_stream_latency": "python benchmarks/birae_stream.py --skip-eval (commit 45d3452)",
    "birae_stream_test": "python benchmarks/birae_stream.py --skip-latency (birae6_cpu v2; evaluate mode='stream', "
                         "noise scenario, test split, every 10th frame; commit daae08e)",
    "body": "python benchmarks/body.py --baseline <a checkout of e726f1e>/src (commit 0e330e5)",
    "body_vs_smplx": "python benchmarks/body_vs_smplx.py --threads 1 (commit 9d01953)",
    "card_reproduction": "python benchmarks/card_reproduction.py (commit 2c8556c)",
    "convention_checks": "python benchmarks/convention_checks.py (80 clips per kit x 2 noise settings; commit d2f963b)",
    "foot_skate": "python benchmarks/foot_skate.py (60 clips per source x motion; commit 0a8dbc3)",
    "inputs_fuzz": "python benchmarks/inputs_fuzz.py --examples 10000 (branch cli22 at 1d2b93f, before a rebase that left the decoders unchanged)",
    "live_inputs": "python benchmarks/live_inputs.py --wait 2400 (commit 521ba91)",
    "recording_fuzz": "python benchmarks/recording_fuzz.py --examples 1250 (commit 2906dca)",
    "simulate": "python benchmarks/simulate.py (em12, val split, 1 and 2 workers; commit eb3a866)",
    "up_axis": "python benchmarks/up_axis.py (commit 94ede4c)",
    "ximu3_noise": "python benchmarks/ximu3_noise.py (commit d7799b5)",
}

#: What the file name and command do not say: which shipped model a kept file stands for when its
#: weights changed since, or why a result not measured with today's shipped weights stays.
NOTES = {
    "birae_heading_sweep": "current for birae3_cpu (3param); its 6param row is the width-128 birae6_cpu of commit "
                           "ddbc6df, the shipped width-256 birae6_cpu is in birae_heading_sweep_w256",
    "birae_heading_sweep_w256": "6param_w256 = birae6_cpu v1 (archive:birae6_cpu_v1, shipped in 5570a1e), not "
                                "re-run with v2; its 6param row is the previous width-128 birae6_cpu",
    **{k: "its 6param row is birae6_cpu v1 (archive:birae6_cpu_v1); v2 (same architecture) not re-run here"
       for k in ("birae_framerate", "birae_window", "birae_stream_latency")},
    "birae_tables": "its 6param row is birae6_cpu v1 (archive:birae6_cpu_v1); v2 in birae_tables_v2",
    "birae_calibration": "its 6param row is birae6_cpu v1 (archive:birae6_cpu_v1); v2 in birae_calibration_v2",
    **{k: "recipe birae3_cpu_v3 (v2 plus the sigma phase), run and not shipped (birae3_cpu stays v1: test coverage "
          "59.8 %; docs/birae.md)"
       for k in ("birae_tables_birae3_v3", "birae_calibration_birae3_v3", "generalisation_birae3_v3_unseen_motion")},
    **{k: "recipe birae3_cpu_v2, run and not shipped (birae3_cpu stays v1: test coverage 61.0 %; docs/birae.md)"
       for k in ("birae_tables_birae3_v2", "birae_calibration_birae3_v2", "generalisation_birae3_test",
                 "generalisation_birae3_unseen_motion")},
    **{k: "birae6_cpu v1 (archive:birae6_cpu_v1); v2 has the same architecture, so the same cost"
       for k in ("latency_birae6_cpu", "latency_birae6_cpu_stream")},
    "unseen_motion_birae6_cpu": "birae6_cpu v1 (archive:birae6_cpu_v1); v1 and v2 side by side in "
                                "generalisation_birae_unseen_motion",
    **{k: "its LGD-RNN 6 row is empose6_cpu v1 (archive:empose6_cpu_v1); v3 in generalisation_empose6_v3_*"
       for k in ("empose_table2_em6", "empose_table4")},
    **{k: "miposer1_cpu v1 (archive:miposer1_cpu_v1); v2 in generalisation_miposer1_v2_*, same architecture"
       for k in ("miposer_fig5_smartwatch", "latency_miposer1_cpu")},
    **{k: "recipe empose6_cpu_v2: empose6_cpu v2, shipped for an hour on 2026-12-04 and replaced by v3"
       for k in ("generalisation_empose6_v2_test", "generalisation_empose6_v2_unseen_motion",
                 "generalisation_empose6_v2_heldout_bodies", "generalisation_empose6_v2_shapefit_heldout_bodies")},
    **{k: "empose12_cpu v5 (archive:empose12_cpu_v5), shipped until v6; v1, v5 and v6 in generalisation_empose12_v6_*"
       for k in ("generalisation_empose12_v5_test", "generalisation_empose12_v5_unseen_motion",
                 "generalisation_empose12_v5_heldout_bodies", "generalisation_empose12_v5_shapefit_heldout_bodies")},
    "miposer_fig5": "its IMU-only column is imuposer_cpu v1 (archive:imuposer_cpu_v1); v3 in generalisation_imuposer_v3_*",
    **{k: "recipe imuposer_cpu_v2, run and not shipped (v3, 7 epochs, lower on validation: 57.6 against 58.8 mm)"
       for k in ("generalisation_imuposer_v2_test", "generalisation_imuposer_v2_unseen_motion",
                 "generalisation_imuposer_v2_heldout_bodies")},
    **{k: "recipe empose12_cpu_v7, run and not shipped (test 14.7 mm against v6's 13.4; docs/empose.md); its "
          "v6 / empose12_cpu is archive:empose12_cpu_v6, shipped until v8"
       for k in ("generalisation_empose12_v7_test", "generalisation_empose12_chain_v7_asf_takes")},
    "recipe_reproduction": "its empose12_cpu_v5 row's reference, 'shipped empose12_cpu', is now archive:empose12_cpu_v5; "
                           "its empose12_cpu_v6 row's, archive:empose12_cpu_v6",
    **{k: "its v6 / empose12_cpu is empose12_cpu v6 (archive:empose12_cpu_v6), shipped until v8 on 2026-12-05"
       for k in ("generalisation_empose12_v8_test", "generalisation_empose12_v8_unseen_motion",
                 "generalisation_empose12_v8_heldout_bodies", "generalisation_empose12_chain_v8_asf_takes",
                 "generalisation_empose12_unseen_lab_v6_bandai", "generalisation_empose12_unseen_lab_v6_cmu_daz",
                 "generalisation_empose12_unseen_lab_v6_bandai_refine_gn3",
                 "generalisation_empose12_unseen_lab_v6_cmu_daz_refine_gn3", "floor_contact_empose_val")},
    "interference_correction_nbeats_v1": "nbeats_cpu v1 (archive:nbeats_cpu_v1), shipped until v2 on 2026-12-05, on "
                                         "the same simulated sessions as interference_correction (docs/interference.md)",
    "latency_empose6_cpu": "empose6_cpu v1 (archive:empose6_cpu_v1); v3 has the same architecture, so the same cost",
    "empose_table10_long": "Table 10 with 2-4 s removals (docs/empose.md, row 'miss., 2-4 s removals'), with the v1 "
                           "weights (archive:empose12_cpu_v1, archive:empose12_twostage_cpu_v1); not rerun",
    "empose_table10_lgdik": "the paper's LGD IK behind the v1 two-stage mapper (archive:empose12_twostage_cpu_v1); "
                            "not rerun with v3",
    "empose_table3_rep": "a second training of four Table 3 rows: the run-to-run spread",
    "physics_val_kres0.1": "made before contact_no_lift; with physics_val_literal_weights the evidence "
                           "PhysicsConfig.weights_in_norm's docstring cites",
    "physics_val_literal_weights": "made before contact_no_lift; see physics_val_kres0.1",
    "pip_dualpd_inputs_test_aug3": "session-6 weights (pip_cpu until ce012f7): not re-run with the shipped weights",
    "pip_dualpd_inputs_val_aug3": "session-6 weights (pip_cpu until ce012f7): not re-run with the shipped weights",
    "pip_sitting_synthetic_arms_noinit": "the shipped pair's no-learned-init partner (not shipped)",
    "pip_sitting_synthetic_arms_1h_noinit": "the shipped pair's no-learned-init partner (not shipped)",
    "pip_val_travel_clips": "the 64 val clips that travel > 1 m (the pip_perclip_valtravel_* selection)",
    "pip_grf_walk": "plot of the session-6 weights (commit efd9441)",
    "pip_torque_wave": "plot of the width-128 weights (commit a528881)",
}


def _producer(stem: str, js: dict | None, md: str | None) -> str:
    for k in ("command", "produced_by", "cmd"):
        if isinstance(js, dict) and isinstance(js.get(k), str):
            return js[k]
    m = re.search(r"Produced by `([^`]+)`", md or "")
    return m.group(1) if m else PRODUCERS.get(stem, "(not recorded in the file)")


def shipped_runs() -> dict[str, str]:
    """``{run directory name: shipped weights name}`` from the cards' ``shipped_with`` commands;
    archived weights (``weights/archive/<name>.json``) by their archive name (``pip_cpu_v1``)."""
    out = {}
    for card in [*sorted((CARDS / "archive").glob("*.json")), *sorted(CARDS.glob("*.json"))]:
        m = re.search(r"(\S+\.pt) (\w+)", str(json.loads(card.read_text(encoding="utf-8")).get("shipped_with", "")))
        if m and Path(m.group(1)).parent.name:
            out[Path(m.group(1)).parent.name] = card.stem if card.parent.name == "archive" else m.group(2)
    return out


def _weight_name(path: str, shipped: dict[str, str]) -> str:
    """A checkpoint as its run (``runs/X/best.pt`` -> ``X``), a shipped file as its name."""
    p = Path(path)
    run = p.parent.name if p.suffix == ".pt" and p.parent.name not in ("", "runs", "weights") else p.stem
    return f"{run} (shipped as {shipped[run]})" if shipped.get(run, run) != run else run


def _weights(js: dict | None, producer: str, shipped: dict[str, str]) -> str:
    """The weights a result names: its JSON's weights field, else the checkpoints in its command."""
    paths: list[str] = []
    for k in ("weights", "checkpoints", "checkpoint", "model"):
        v = js.get(k) if isinstance(js, dict) else None
        if isinstance(v, str):
            paths = [v]
        elif isinstance(v, dict):
            paths = [str(n) if isinstance(x, dict) else str(x) for n, x in v.items()]
        elif isinstance(v, list):
            paths = [str(x) for x in v]
        if paths:
            break
    if not paths:  # checkpoints, then shipped weights given by name (``--weights miposer_cpu``)
        names = "|".join(sorted(c.stem for c in CARDS.glob("*.json")))
        paths = re.findall(r"[\w./-]+\.pt\b", producer) + re.findall(rf"(?<![\w./-])(?:{names})(?![\w./-])", producer)
    return ", ".join(dict.fromkeys(_weight_name(x, shipped) for x in paths))


def rows() -> list[tuple[str, str, str, str, str]]:
    """``(stem, title, producer, weights, note)`` for every result stem, sorted."""
    out = []
    shipped = shipped_runs()
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
        producer = _producer(stem, js, md)
        out.append((f"`{stem}` {files}", title.replace("|", "/"), producer.replace("|", "/"),
                    _weights(js, producer, shipped), NOTES.get(stem, "")))
    extra = sorted(p.name for p in RESULTS.iterdir() if p.suffix not in (".md", ".json"))
    out += [(f"[{name}]({name})", "", "", "", NOTES.get(Path(name).stem, "")) for name in extra]
    return out


def render() -> str:
    """The index's markdown, one row per result stem, then the other files (plots, clip lists)."""
    lines = ["# Benchmark results", "",
             "Written by `python tools/results_index.py` from the files themselves: each result's title, the "
             "command that produced it (as recorded in the file) and the weights it names (a run directory, "
             "with the name it was shipped under when a weights card says so). A result whose "
             "producer is not recorded in it is given from the commit that wrote it (`PRODUCERS` in the tool). "
             "One current file per table per shipped model: superseded variants (earlier weights, earlier "
             "code, development checks and parameter sweeps) are removed from the tree; git keeps them and "
             "the docs cite them at their commit. A kept result not measured with today's shipped weights "
             "says why in its note.", "",
             "| result | title | produced by | weights | note |", "| --- | --- | --- | --- | --- |"]
    lines += [f"| {a} | {b} | {f'`{c}`' if c else ''} | {d} | {e} |" for a, b, c, d, e in rows()]
    return "\n".join(lines) + "\n"


def main() -> None:
    text = render()
    (RESULTS / "README.md").write_text(text, encoding="utf-8")
    print(f"wrote {RESULTS / 'README.md'} ({text.count(chr(10)) - 6} rows)")


if __name__ == "__main__":
    main()
