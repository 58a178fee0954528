"""``wearpose evaluate``: model arguments, the EM-POSE protocol end to end on synthetic clips, and
the unseen-subject offsets of Table 4."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from tests.estimators.test_empose import FakeStore
from wearpose.cli import app
from wearpose.cli.cmd_evaluate import resolve_model
from wearpose.estimators.empose import EmposeConfig, EmposeEstimator
from wearpose.estimators.empose.evaluate import unseen_subject_offsets
from wearpose.geometry import matrix_to_axis_angle

runner = CliRunner()


def test_help_has_an_example() -> None:
    res = runner.invoke(app, ["evaluate", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose evaluate" in res.output and "--offsets" in res.output and "--clips" in res.output


def test_model_arguments_resolve_to_checkpoints(tmp_path: Path) -> None:
    name, path = resolve_model("empose12_cpu")
    assert name == "empose12_cpu" and path.name == "empose12_cpu.pt" and path.is_file()
    assert resolve_model("LGD=empose6_cpu")[0] == "LGD"
    ck = tmp_path / "myrun" / "best.pt"
    ck.parent.mkdir()
    ck.write_bytes(b"x")
    assert resolve_model(str(ck)) == ("myrun", ck)
    import typer

    for bad in ("nope_cpu", "=empose12_cpu", "A="):
        with pytest.raises(typer.BadParameter):
            resolve_model(bad)


def test_methods_with_other_protocols_are_not_mixed_with_empose() -> None:
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "pip_cpu", "--clips", "1"])
    assert res.exit_code == 2 and "different protocols" in res.output


def test_an_empty_split_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 23: evaluate on a split with no clips printed NaN and exited 0."""
    store = FakeStore(tmp_path, {"val": 1})
    monkeypatch.setattr("wearpose.motion.CorpusStore", lambda *a, **k: store)
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--split", "test", "--json"])
    assert res.exit_code == 2 and "has no clips" in res.output, res.output


#: The shipped pose models of issue 21's acceptance -> (the metric their paper leads with, a
#: plausible range on one simulated test clip). Ranges are wide: this checks the path, not the model.
SHIPPED = {"empose12_cpu": ("mpjpe_mm", 5, 80), "empose6_cpu": ("mpjpe_mm", 5, 120),
           "empose12_twostage_cpu": ("mpjpe_mm", 5, 120), "pip_cpu": ("sip_error_deg", 2, 60),
           "birae6_cpu": ("mpjae_all_deg", 2, 60), "birae3_cpu": ("mpjae_all_deg", 2, 60),
           "miposer_cpu": ("calibrated_mpjpe_upper_cm", 0.5, 20), "imuposer_cpu": ("mpjpe_upper_cm", 0.5, 30)}


@pytest.mark.corpus
@pytest.mark.budget(30)  # PIP's physics and MI-Poser's calibration on one clip
@pytest.mark.parametrize("model", list(SHIPPED))
def test_every_shipped_pose_model_evaluates(model: str, corpus_store: Path) -> None:
    res = runner.invoke(app, ["evaluate", model, "--clips", "2", "--json", "--cache", str(corpus_store)])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout[res.stdout.index("{"):])
    m = r["models"][model]
    # Every method's result names the store and the corpus version its clips came from.
    prov = m.get("store") or r["store"]
    assert prov["converter"] and prov["corpus"]["manifest_sha1"], prov
    key, lo, hi = SHIPPED[model]
    value = m[key] if key in m else m["metrics"][key]
    assert lo < value < hi, (model, key, value)
    clips = r["clips"] if "clips" in r else m["clips"]
    assert clips == 2


def test_evaluate_end_to_end_on_synthetic_clips(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    torch.manual_seed(0)
    est = EmposeEstimator(EmposeConfig.preset("tiny", 12))
    ck = tmp_path / "tiny12" / "best.pt"
    est.save(ck)
    store = FakeStore(tmp_path, {"test": 2, "val": 1})
    monkeypatch.setattr("wearpose.motion.CorpusStore", lambda *a, **k: store)
    out = tmp_path / "res" / "table"
    res = runner.invoke(app, ["evaluate", f"A={ck}", str(ck), "--json", "--out", str(out), "--offsets", "unseen"])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout[res.stdout.index("{"):])
    assert (r["split"], r["clips"], r["offsets"], r["spread"]) == ("test", 2, "unseen", 2.0)
    assert set(r["models"]) == {"A", "tiny12"}
    a, b = r["models"]["A"], r["models"]["tiny12"]
    assert math.isfinite(a["mpjpe_mm"]) and a["mpjpe_mm"] > 0 and a["frames"] == r["frames"] > 0
    assert a["mpjpe_mm"] == b["mpjpe_mm"]  # the same checkpoint on the same simulated clips
    assert "| A 12 |" in out.with_suffix(".md").read_text() and json.loads(out.with_suffix(".json").read_text())["clips"] == 2
    res = runner.invoke(app, ["evaluate", str(ck), "--split", "val", "--clips", "1", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout[res.stdout.index("{"):])["clips"] == 1
    res = runner.invoke(app, ["evaluate", str(ck), "--split", "val", "--clips", "1"])
    assert res.exit_code == 0, res.output
    line = " ".join(res.output.split())  # the console wraps at 80 columns
    assert re.search(r"tiny12: \d+ % of the squared joint error is constant over a clip; the largest constant "
                     r"part: [a-z_]+ \d+\.\d mm", line), res.output


def test_unseen_subjects_are_wider_than_the_training_prior() -> None:
    from wearpose.sensors.em import random_subject_offsets

    seen = [random_subject_offsets(12, torch.Generator().manual_seed(i)) for i in range(40)]
    wide = [unseen_subject_offsets(12, torch.Generator().manual_seed(i), 2.0) for i in range(40)]

    def angle(o) -> torch.Tensor:
        return matrix_to_axis_angle(o.R).norm(dim=-1)

    a_seen, a_wide = torch.cat([angle(o) for o in seen]), torch.cat([angle(o) for o in wide])
    assert a_wide.mean() > 1.7 * a_seen.mean()
    standoff_seen, standoff_wide = torch.cat([o.t[:, 2] for o in seen]), torch.cat([o.t[:, 2] for o in wide])
    assert abs(float(standoff_wide.mean()) - 2 * float(standoff_seen.mean())) < 0.004
    assert torch.allclose(unseen_subject_offsets(12, torch.Generator().manual_seed(0), 1.0).R, seen[0].R)


@pytest.mark.corpus
def test_shipped_weights_on_two_test_clips(corpus_store: Path) -> None:
    """The shipped LGD-RNN (a checkpoint from before the ablation options existed) through the
    command on the real corpus: finite, plausible figures."""
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--clips", "2", "--json"])
    assert res.exit_code == 0, res.output
    m = json.loads(res.stdout[res.stdout.index("{"):])["models"]["empose12_cpu"]
    assert m["config"]["inputs"] == "both" and m["config"]["init"] == "rnn"
    assert 5.0 < m["mpjpe_mm"] < 60.0 and m["frames"] > 0


def test_breakdown_pools_clips_by_source_and_class(tmp_path: Path) -> None:
    """Issue 24: every result groups its per-clip figures by source and motion class; over all
    clips a frame-weighted group is the pooled figure."""
    from wearpose.evaluate.protocols import breakdown, breakdown_markdown
    from wearpose.motion import CorpusStore
    from wearpose.motion.store import write_index

    rows = {"bandai/b/walk_1": ("bandai", "walk (style: x)", None), "bandai/b/run_1": ("bandai", "run", None),
            "procedural/squat/eval/0000": ("procedural", "squat", "squat")}
    clips = {cid: {"id": cid, "clip": cid.rpartition("/")[2], "subject": "s", "source": src, "split": "test",
                   "licence": "l", "description": d, "file": "x.npz", **({"class": c} if c else {})}
             for cid, (src, d, c) in rows.items()}
    write_index(tmp_path, clips, {}, corpus={"kind": "test"}, converter="t", fps=None, rest_joints=[], rest_source="t")
    store = CorpusStore(tmp_path)
    per_clip = [{"clip": "bandai/b/walk_1", "frames": 100, "mpjpe_mm": 10.0},
                {"clip": "bandai/b/run_1", "frames": 300, "mpjpe_mm": 30.0},
                {"clip": "procedural/squat/eval/0000", "frames": 50, "mpjpe_mm": 80.0, "coverage_pct": 60.0}]
    b = breakdown(per_clip, store)
    assert b["source"]["bandai"] == {"clips": 2, "frames": 400, "mpjpe_mm": 25.0}
    assert b["source"]["procedural"] == {"clips": 1, "frames": 50, "mpjpe_mm": 80.0, "coverage_pct": 60.0}
    assert set(b["class"]) == {"walk", "run", "squat"} and b["class"]["run"]["mpjpe_mm"] == 30.0
    md = breakdown_markdown({"m": {"breakdown": b}}, "class")
    assert "| squat | 1 | 50 | 80 | 60 |" in md and "| walk | 1 | 100 | 10 | - |" in md, md


def _tiny_empose_on_fake_store(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, clips: int) -> tuple[Path, FakeStore, Path]:
    """A tiny EM-POSE 12 checkpoint, ``clips`` synthetic test clips as the default store, and an
    ``--out`` stem: (checkpoint, store, stem)."""
    torch.manual_seed(0)
    ck = tmp_path / "tiny12.pt"
    EmposeEstimator(EmposeConfig.preset("tiny", 12)).save(ck)
    store = FakeStore(tmp_path, {"test": clips})
    monkeypatch.setattr("wearpose.motion.CorpusStore", lambda *a, **k: store)
    return ck, store, tmp_path / "t"


def test_empose_result_has_breakdowns_that_pool_to_the_headline(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    ck, store, out = _tiny_empose_on_fake_store(tmp_path, monkeypatch, 3)
    res = runner.invoke(app, ["evaluate", str(ck), "--json", "--out", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads(res.stdout[res.stdout.index("{"):])["models"]["tiny12"]
    assert len(m["per_clip"]) == 3 and sum(c["frames"] for c in m["per_clip"]) == m["frames"]
    (src,) = m["breakdown"]["source"].values()  # the stand-in store's clips are all "synthetic/..."
    assert src["clips"] == 3 and src["mpjpe_mm"] == pytest.approx(m["mpjpe_mm"], rel=1e-6)
    assert src["mpjae_deg"] == pytest.approx(m["mpjae_deg"], rel=1e-6)
    md = out.with_suffix(".md").read_text()
    assert "## By source" in md and "| synthetic | 3 |" in md and "## By motion class" in md


def test_source_and_protocol_options_are_checked(tmp_path: Path) -> None:
    from wearpose.motion.store import write_index

    clips = {f"{s}/x/{i}": {"id": f"{s}/x/{i}", "clip": str(i), "subject": "x", "source": s, "split": "test",
                            "licence": "l", "description": "walk", "file": "x.npz"} for s in ("bandai", "cmu_daz")
             for i in range(2)}
    write_index(tmp_path, clips, {}, corpus={"kind": "test"}, converter="t", fps=None, rest_joints=[], rest_source="t")
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--cache", str(tmp_path), "--source", "cmu_asf"])
    assert res.exit_code == 2 and "'cmu_asf'" in res.output and "--source" in res.output, res.output
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--cache", str(tmp_path), "--protocol", "unseen-motion"])
    assert res.exit_code == 2 and "procedural" in res.output and "--cache" in res.output, res.output
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--per-family", "2"])
    assert res.exit_code == 2 and "--per-family" in res.output, res.output
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--protocol", "lab"])
    assert res.exit_code == 2 and "'lab'" in res.output and "--protocol" in res.output, res.output


@pytest.mark.budget(25)  # three tiny EM-POSE evaluations on the full body asset
def test_heldout_bodies_through_the_command(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 23.6 / 24.5: ``--bodies heldout`` records the wearers and EM-POSE's shape figures;
    the default is the clips' own body."""
    from wearpose.estimators.bodies import heldout_betas

    ck, store, out = _tiny_empose_on_fake_store(tmp_path, monkeypatch, 2)
    res = runner.invoke(app, ["evaluate", str(ck), "--json", "--bodies", "heldout", "--seed", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout[res.stdout.index("{"):])
    assert r["bodies"] == "heldout" and set(r["betas"]) == set(store.clips(split="test"))
    for cid, b in r["betas"].items():
        assert b == pytest.approx(heldout_betas(cid, 1).tolist(), abs=1e-4)
    m = r["models"]["tiny12"]
    assert m["height_error_median_cm"] >= 0 and m["zero_pose_vertex_error_median_mm"] > 0
    assert all("height_error_cm" in c for c in m["per_clip"])
    md = out.with_suffix(".md").read_text()
    assert "## Body shape estimate" in md and "held-out body shape per clip" in md, md
    res = runner.invoke(app, ["evaluate", str(ck), "--json", "--seed", "1"])
    plain = json.loads(res.stdout[res.stdout.index("{"):])
    assert (plain["bodies"], plain["betas"]) == ("corpus", {})
    assert plain["models"]["tiny12"]["mpjpe_mm"] != m["mpjpe_mm"]
    res = runner.invoke(app, ["evaluate", str(ck), "--bodies", "tall"])
    assert res.exit_code == 2 and "--bodies" in res.output and "'tall'" in res.output, res.output


def test_heldout_bodies_in_a_single_model_protocol(tmp_path: Path) -> None:
    """Every declared protocol gets the wearers through evaluate_model; BiRAE reads joint
    rotations only, which a re-fit keeps, so its figures do not change (its wearers are recorded)."""
    from tests.estimators.test_empose import FakeStore as Store
    from wearpose.estimators.birae import BiraeConfig, BiraeEstimator
    from wearpose.estimators.bodies import heldout_betas
    from wearpose.estimators.run import open_model
    from wearpose.evaluate.protocols import evaluate_model

    class _Store(Store):
        def provenance(self) -> dict:
            return {"root": str(self.root)}

    torch.manual_seed(0)
    path = BiraeEstimator(BiraeConfig.preset("tiny")).save(tmp_path / "b.pt")
    src, store = open_model(path), _Store(tmp_path, {"test": 2})
    worn = evaluate_model(src, store=store, seed=4, bodies="heldout")
    own = evaluate_model(src, store=store, seed=4)
    assert (worn["bodies"], own["bodies"], own["betas"]) == ("heldout", "corpus", {})
    assert worn["betas"] == {c: pytest.approx(heldout_betas(c, 4).tolist(), abs=1e-4) for c in worn["clip_ids"]}
    assert worn["metrics"]["mpjae_all_deg"] == pytest.approx(own["metrics"]["mpjae_all_deg"], abs=1e-6)


def test_set_turns_on_the_empose_refinement(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--set reaches every EM-POSE model: the refined fraction appears (all frames with a zero
    gate, also the default one), the checkpoint path is still recorded; a setting the estimator
    lacks is refused naming --set."""
    torch.manual_seed(0)
    ck = tmp_path / "tiny12" / "best.pt"
    EmposeEstimator(EmposeConfig.preset("tiny", 12)).save(ck)
    monkeypatch.setattr("wearpose.motion.CorpusStore", lambda *a, **k: FakeStore(tmp_path, {"test": 1}))
    res = runner.invoke(app, ["evaluate", str(ck), "--json", "--set", "refine_steps=2", "--set", "refine_threshold=0"])
    assert res.exit_code == 0, res.output
    m = json.loads(res.stdout[res.stdout.index("{"):])["models"]["tiny12"]
    assert m["refined_fraction"] == 1.0 and m["config"]["refine_steps"] == 2 and m["checkpoint"] == str(ck)
    plain = json.loads((r := runner.invoke(app, ["evaluate", str(ck), "--json"])).stdout[r.stdout.index("{"):])
    assert "refined_fraction" not in plain["models"]["tiny12"] and plain["models"]["tiny12"]["checkpoint"] == str(ck)
    assert plain["models"]["tiny12"]["mpjpe_mm"] != m["mpjpe_mm"]
    res = runner.invoke(app, ["evaluate", str(ck), "--set", "mc_samples=3"])
    assert res.exit_code == 2 and "--set" in res.output
    res = runner.invoke(app, ["evaluate", str(ck), "--json", "--set", "refine_steps=2"])  # the default gate: every frame
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout[res.stdout.index("{"):])["models"]["tiny12"]["refined_fraction"] == 1.0
