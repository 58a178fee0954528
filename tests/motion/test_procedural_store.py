"""The unseen-motion store (wearpose.motion.procedural_store): procedural eval-namespace clips
written as a corpus store, read back by CorpusStore, rebuilt only when its settings change;
``wearpose data procedural`` over it; store subsets by source and the motion class of an entry."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from wearpose.body import BodyModel
from wearpose.cli import app
from wearpose.errors import ConfigError
from wearpose.motion import CorpusStore
from wearpose.motion.procedural import procedural_clip
from wearpose.motion.procedural_store import LICENCE, build_procedural_store, unseen_motion_dir
from wearpose.motion.store import motion_class

FAMS = ("crawl", "reach")  # the two quickest families to generate


@pytest.fixture(scope="module")
def body() -> BodyModel:
    torch.set_num_threads(1)
    return BodyModel()


@pytest.mark.budget(20)
def test_store_of_eval_clips_reads_back_and_is_kept(tmp_path: Path, body: BodyModel) -> None:
    res = build_procedural_store(tmp_path / "s", per_family=1, families=FAMS, body=body)
    assert (res["clips"], res["generated"], res["kept"]) == (2, 2, 0)
    store = CorpusStore(tmp_path / "s")
    ids = store.clips(split="test", source="procedural")
    assert ids == ["procedural/crawl/eval/0000", "procedural/reach/eval/0000"] == store.clips()
    e = store.entry(ids[1])
    assert (e["class"], e["subject"], e["licence"], motion_class(e)) == ("reach", "reach", LICENCE, "reach")
    assert store.provenance()["corpus"]["kind"] == "procedural" and store.index["corpus"]["namespace"] == "eval"
    seq = store.load(ids[1])
    fresh = procedural_clip("reach", 0, body, seed=0, namespace="eval", body_shape=False)
    assert seq.num_frames == fresh.num_frames == e["frames"]
    assert torch.allclose(seq.pose, fresh.pose, atol=1e-5) and torch.allclose(seq.trans, fresh.trans, atol=1e-5)
    assert float(seq.betas.abs().max()) == 0.0  # the mean body by default
    again = build_procedural_store(tmp_path / "s", per_family=1, families=FAMS, body=body)
    assert (again["generated"], again["kept"]) == (0, 2)
    other = build_procedural_store(tmp_path / "s", per_family=1, families=("reach",), seed=1, body=body)
    assert other["generated"] == 1 and CorpusStore(tmp_path / "s").clips() == ["procedural/reach/eval/0000"]
    assert not torch.allclose(CorpusStore(tmp_path / "s").load(ids[1]).pose[:50], seq.pose[:50])


@pytest.mark.budget(20)
def test_val_namespace_store_is_a_validation_split_with_its_own_draws(tmp_path: Path, body: BodyModel) -> None:
    res = build_procedural_store(tmp_path / "v", per_family=1, families=("reach",), body=body, namespace="val")
    store = CorpusStore(tmp_path / "v")
    assert res["clips"] == 1 and store.clips(split="val") == ["procedural/reach/val/0000"] and not store.clips(split="test")
    assert store.index["corpus"]["namespace"] == "val" and store.entry("procedural/reach/val/0000")["clip"] == "val/0000"
    seq = store.load("procedural/reach/val/0000")
    assert torch.allclose(seq.pose, procedural_clip("reach", 0, body, seed=0, namespace="val", body_shape=False).pose, atol=1e-5)
    held_out = procedural_clip("reach", 0, body, seed=0, namespace="eval", body_shape=False)
    n = min(seq.num_frames, held_out.num_frames)
    assert not torch.allclose(seq.pose[:n], held_out.pose[:n])  # another draw than the evaluation clip


def test_bad_settings_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="per_family = 0"):
        build_procedural_store(tmp_path, per_family=0)
    with pytest.raises(ConfigError, match="unknown families"):
        build_procedural_store(tmp_path, families=("cartwheel",))
    with pytest.raises(ConfigError, match="namespace 'train'; expected one of eval, val"):
        build_procedural_store(tmp_path, namespace="train")
    assert unseen_motion_dir().name == "unseen-motion-n6-s0" and unseen_motion_dir().parent.name == "protocols"


def test_motion_class_of_corpus_and_procedural_entries() -> None:
    assert motion_class({"description": "wave-left-hand (style: angry)", "clip": "x"}) == "wave-left-hand"
    assert motion_class({"description": "", "clip": "02_01"}) == "02_01"
    assert motion_class({"class": "squat", "description": "anything"}) == "squat"


def _store_with_sources(root: Path, sources: dict[str, int]) -> CorpusStore:
    from wearpose.motion.store import write_index

    clips = {f"{s}/x/{i}": {"id": f"{s}/x/{i}", "clip": str(i), "subject": "x", "source": s, "split": "test",
                            "licence": "l", "description": "walk", "file": f"clips/{s}/x/{i}.npz"}
             for s, n in sources.items() for i in range(n)}
    write_index(root, clips, {}, corpus={"kind": "test"}, converter="t", fps=None, rest_joints=[], rest_source="t")
    return CorpusStore(root)


def test_subset_keeps_one_source(tmp_path: Path) -> None:
    store = _store_with_sources(tmp_path, {"bandai": 3, "cmu_daz": 2})
    sub = store.subset("cmu_daz")
    assert sub.clips(split="test") == ["cmu_daz/x/0", "cmu_daz/x/1"] and len(store.clips()) == 5
    assert sub.provenance()["sources"] == ["cmu_daz"] and "sources" not in store.provenance()
    assert store.subset(["bandai", "cmu_daz"]).clips() == store.clips()
    with pytest.raises(ConfigError, match="no clips of source 'cmu_asf'; expected one of bandai, cmu_daz"):
        store.subset("cmu_asf")


@pytest.mark.budget(15)
def test_cli_builds_the_store(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["data", "procedural", "--per-family", "1", "--family", "crawl",
                                   "--out", str(tmp_path / "u"), "--json"])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout)
    assert (r["clips"], r["generated"]) == (1, 1)
    assert CorpusStore(tmp_path / "u").clips(split="test") == ["procedural/crawl/eval/0000"]
    assert "Example: wearpose data procedural" in CliRunner().invoke(app, ["data", "procedural", "--help"]).output
