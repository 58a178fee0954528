"""Corpus store on a tiny synthetic corpus (manifest and folder modes), and path resolution."""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path

import pytest
import torch

from wearpose.errors import ConfigError, InputFileError
from wearpose.motion import (
    BANDAI, CorpusStore, MotionSequence, cache_dir, data_dir, prepare_corpus, save_amass, template_rest_joints,
)
from wearpose.motion.store import _hash_split
from motion_testutils import synthetic_bvh_from_smpl, synthetic_smpl_motion

REST = template_rest_joints()


def bandai_like_bvh(seed: int = 0, T: int = 20) -> str:
    local, pelvis = synthetic_smpl_motion(REST, T=T, seed=seed)
    text, _ = synthetic_bvh_from_smpl(REST, local, pelvis, seed=seed + 1)
    # Rename longest names first so that J_left_hip does not clobber J_left_hip...
    for smpl, b in sorted(BANDAI.joints.items(), key=lambda kv: -len(kv[0])):
        text = text.replace(f"J_{smpl}\n", f"{b}\n")
    return text


def write_gz(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with gzip.open(path, "wt") as f:
        f.write(text)
    return path


@pytest.fixture()
def corpus(tmp_path: Path) -> Path:
    data = tmp_path / "data"
    write_gz(data / "bandai" / "s1" / "walk.bvh.gz", bandai_like_bvh(0))
    write_gz(data / "bandai" / "s2" / "wave.bvh.gz", bandai_like_bvh(1, T=31))
    write_gz(data / "bandai" / "s2" / "broken.bvh.gz", bandai_like_bvh(2).replace("Frames: 20", "Frames: 25"))
    rows = [
        "path,source,subject,clip,description,frames,fps,seconds,split,licence,frame0_is_tpose",
        "data/bandai/s1/walk.bvh.gz,bandai,s1,walk,walk,20,30,0.667,train,CC-BY-NC-4.0,1",
        "data/bandai/s2/wave.bvh.gz,bandai,s2,wave,wave,31,30,1.033,test,CC-BY-NC-4.0,0",
        "data/bandai/s2/broken.bvh.gz,bandai,s2,broken,x,20,30,0.667,test,CC-BY-NC-4.0,0",
        "data/bandai/s2/gone.bvh.gz,bandai,s2,gone,x,20,30,0.667,val,CC-BY-NC-4.0,0",
    ]
    (data / "manifest.csv").write_text("\n".join(rows) + "\n")
    return data


def test_prepare_with_manifest(corpus: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    r = prepare_corpus(corpus, cache, progress=False, workers=1, rest_joints=REST)
    assert r["converted"] == 2 and r["skipped"] == 0 and r["failed"] == 2
    assert "truncated" in r["failures"]["bandai/s2/broken"] and "not found" in r["failures"]["bandai/s2/gone"]
    store = CorpusStore(cache)
    assert store.clips() == ["bandai/s1/walk", "bandai/s2/wave"]
    assert store.clips(split="test") == ["bandai/s2/wave"] and store.clips(source="cmu_daz") == []
    assert store.clips(licence=["CC-BY-NC-4.0"], split=("train", "test")) == ["bandai/s1/walk", "bandai/s2/wave"]
    walk = store.load("bandai/s1/walk")
    assert walk.num_frames == 19 and walk.meta["skipped_frame0"] and walk.meta["split"] == "train"  # T-pose frame dropped
    assert walk.meta["skeleton"] == "bandai" and walk.fps == 30.0
    e = store.entry("bandai/s2/wave")
    assert e["frames"] == 31 and e["seconds"] == pytest.approx(31 / 30) and e["licence"] == "CC-BY-NC-4.0"
    s = store.summary()
    assert s["clips"] == 2 and s["subjects"] == 2 and s["failures"] == 2
    assert s["minutes_per_split"] == {"test": round(31 / 30 / 60, 2), "train": round(19 / 30 / 60, 2)}
    assert s["frame_rates"] == {"30": 2} and isinstance(s["floor_suspect"], list)
    with pytest.raises(KeyError, match="nope"):
        store.load("nope")

    # Idempotent: nothing to do the second time; a touched source is converted again.
    r2 = prepare_corpus(corpus, cache, progress=False, workers=1, rest_joints=REST)
    assert r2["converted"] == 0 and r2["skipped"] == 2
    src = corpus / "bandai" / "s2" / "wave.bvh.gz"
    os.utime(src, ns=(src.stat().st_atime_ns, src.stat().st_mtime_ns + 10**9))
    r3 = prepare_corpus(corpus, cache, progress=False, workers=1, rest_joints=REST)
    assert r3["converted"] == 1 and r3["skipped"] == 1


def test_prepare_a_subset_per_split_and_named_clips(corpus: Path, tmp_path: Path) -> None:
    # One clip of each (split, source): the first clip id of the test split is the broken one.
    r = prepare_corpus(corpus, tmp_path / "c1", progress=False, workers=1, rest_joints=REST, per_split=1)
    assert r["converted"] == 1 and sorted(r["failures"]) == ["bandai/s2/broken", "bandai/s2/gone"]
    assert CorpusStore(tmp_path / "c1").clips() == ["bandai/s1/walk"]
    r = prepare_corpus(corpus, tmp_path / "c2", progress=False, workers=1, rest_joints=REST, per_split=0,
                       clips=["bandai/s2/wave"])
    assert r["converted"] == 1 and not r["failures"] and CorpusStore(tmp_path / "c2").clips() == ["bandai/s2/wave"]
    with pytest.raises(ConfigError, match=r"\['bandai/s9/nope'\] are not in the corpus"):
        prepare_corpus(corpus, tmp_path / "c3", progress=False, workers=1, rest_joints=REST, clips=["bandai/s9/nope"])
    with pytest.raises(ConfigError, match="per_split = -1"):
        prepare_corpus(corpus, tmp_path / "c4", progress=False, workers=1, rest_joints=REST, per_split=-1)


@pytest.mark.budget(20)  # two spawned workers: 6.6 s measured
def test_prepare_parallel_and_resampled(corpus: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache60"
    r = prepare_corpus(corpus, cache, fps=60.0, progress=False, workers=2, rest_joints=REST)
    assert r["converted"] == 2
    wave = CorpusStore(cache).load("bandai/s2/wave")
    assert wave.fps == 60.0 and wave.num_frames == 61  # 30 source intervals -> 60


def test_prepare_folders_without_manifest(tmp_path: Path) -> None:
    root = tmp_path / "mine"
    write_gz(root / "subjA" / "a.bvh.gz", bandai_like_bvh(3))
    g = torch.Generator().manual_seed(0)
    seq = MotionSequence(torch.eye(3).repeat(8, 24, 1, 1), torch.zeros(10), torch.randn(8, 3, generator=g), 50.0, {})
    save_amass(seq, root / "subjB" / "b.npz", REST)
    cache = tmp_path / "c"
    r = prepare_corpus([root], cache, progress=False, workers=1, rest_joints=REST)
    assert r["converted"] == 2 and r["failed"] == 0, r["failures"]
    store = CorpusStore(cache)
    e = store.entry("mine/subjA/a")
    assert e["split"] == _hash_split("subjA") and e["licence"] == "unknown"
    b = store.load("mine/subjB/b")
    assert b.fps == 50.0 and b.meta["source_format"] == "amass"
    assert _hash_split("subjA") == _hash_split("subjA") and {_hash_split(f"s{i}") for i in range(50)} == {"train", "val", "test"}


def test_one_corpus_folder_given_as_a_list_is_the_corpus(corpus: Path, tmp_path: Path) -> None:
    # `wearpose data prepare ../shared/data-v2` passes [folder]: the manifest's splits, sources and
    # licences hold (it was prepared as "your own folders": hash splits, licence "unknown").
    r = prepare_corpus([corpus], tmp_path / "cache", progress=False, workers=1, rest_joints=REST)
    assert r["converted"] == 2 and r["store"]["corpus"]["kind"] == "manifest"
    e = CorpusStore(tmp_path / "cache").entry("bandai/s2/wave")
    assert e["split"] == "test" and e["licence"] == "CC-BY-NC-4.0"


def test_a_corpus_folder_among_other_folders_is_refused(corpus: Path, tmp_path: Path) -> None:
    other = tmp_path / "mine"
    write_gz(other / "subjA" / "a.bvh.gz", bandai_like_bvh(3))
    with pytest.raises(ConfigError, match="manifest.csv.*on its own"):
        prepare_corpus([other, corpus], tmp_path / "cache", progress=False, workers=1, rest_joints=REST)


def test_store_errors(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="prepare_corpus"):
        CorpusStore(tmp_path)
    (tmp_path / "index.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(InputFileError):
        CorpusStore(tmp_path)


def test_paths(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("WEARPOSE_DATA", str(tmp_path))
    assert data_dir() == tmp_path
    monkeypatch.setenv("WEARPOSE_DATA", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match="WEARPOSE_DATA"):
        data_dir()
    assert data_dir(tmp_path) == tmp_path
    monkeypatch.setenv("WEARPOSE_CACHE", str(tmp_path / "cc"))
    assert cache_dir() == tmp_path / "cc"
    monkeypatch.delenv("WEARPOSE_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "wearpose"
    assert cache_dir("~/x") == Path.home() / "x"


def test_manifest_amc_rows_and_paths_of_a_renamed_corpus(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Corpus v2 layout: the folder is ``data-v2`` but manifest paths start with ``data/``; a row
    may be an ``.amc.gz`` (CMU-layout ASF beside it) read at the manifest's fps through the
    built-in cmu_asf map. A same-named file in a sibling ``data`` folder (v1) is never read."""
    from import_testutils import cmu_layout_asf_amc, cmu_layout_motion

    local, pelvis = synthetic_smpl_motion(REST, T=16, seed=5)
    asf, amc = cmu_layout_asf_amc(cmu_layout_motion(local, pelvis, REST))
    v2 = tmp_path / "data-v2"
    (v2 / "cmu_asf" / "86").mkdir(parents=True)
    (v2 / "cmu_asf" / "86" / "86.asf").write_text(asf)
    write_gz(v2 / "cmu_asf" / "86" / "86_01.amc.gz", amc)
    write_gz(v2 / "bandai" / "s1" / "walk.bvh.gz", bandai_like_bvh(0, T=20))
    write_gz(tmp_path / "data" / "bandai" / "s1" / "walk.bvh.gz", bandai_like_bvh(0, T=12))  # v1 decoy
    rows = ["path,source,subject,clip,description,frames,fps,seconds,split,licence,frame0_is_tpose",
            "data/cmu_asf/86/86_01.amc.gz,cmu_asf,86,86_01,synthetic,16,60,0.267,train,CMU-mocap-terms,0",
            "data/bandai/s1/walk.bvh.gz,bandai,s1,walk,walk,20,30,0.667,test,CC-BY-NC-4.0,0"]
    (v2 / "manifest.csv").write_text("\n".join(rows) + "\n")
    cache = tmp_path / "cache"
    r = prepare_corpus(v2, cache, progress=False, workers=1, rest_joints=REST)
    assert r["failed"] == 0 and r["converted"] == 2, r["failures"]
    store = CorpusStore(cache)
    e = store.entry("cmu_asf/86/86_01")
    assert e["skeleton"] == "cmu_asf" and e["fps"] == 60.0 and e["frames"] == 16
    assert store.entry("bandai/s1/walk")["frames"] == 20 and str(v2) in store.entry("bandai/s1/walk")["source_file"]
    seq = store.load("cmu_asf/86/86_01")
    assert seq.meta["import"]["up"]["how"] == "given" and seq.meta["import"]["map_source"] == "built-in cmu_asf"
    # A corpus AMC clip id loads from the corpus folder when no store holds it.
    from wearpose.motion import load_motion

    monkeypatch.setenv("WEARPOSE_DATA", str(v2))
    assert load_motion("cmu_asf/86/86_01", cache=tmp_path / "no_store", rest_joints=REST).meta["skeleton"] == "cmu_asf"
    # The ASF is an input of the AMC row: touching it converts the clip again.
    a = v2 / "cmu_asf" / "86" / "86.asf"
    os.utime(a, ns=(a.stat().st_atime_ns, a.stat().st_mtime_ns + 10**9))
    assert prepare_corpus(v2, cache, progress=False, workers=1, rest_joints=REST)["converted"] == 1
    # A corpus AMC whose skeleton no built-in map fits is refused, not matched automatically.
    (v2 / "cmu_asf" / "86" / "86.asf").write_text(asf.replace("lowerback", "lumbar"))
    write_gz(v2 / "cmu_asf" / "86" / "86_01.amc.gz", amc.replace("lowerback", "lumbar"))
    r = prepare_corpus(v2, cache, progress=False, workers=1, rest_joints=REST)
    assert "not a built-in one" in r["failures"]["cmu_asf/86/86_01"]


def test_default_corpus_is_v2_beside_the_checkout(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Without WEARPOSE_DATA: ../shared/data-v2 beside the checkout; a lone v1 folder is named in
    the error (never used silently)."""
    from wearpose.motion import paths

    monkeypatch.delenv("WEARPOSE_DATA", raising=False)
    monkeypatch.setattr(paths, "__file__", str(tmp_path / "elsewhere" / "paths.py"))  # not the real checkout
    checkout = tmp_path / "work" / "main" / "src"
    checkout.mkdir(parents=True)
    (tmp_path / "work" / "shared" / "data").mkdir(parents=True)
    monkeypatch.chdir(checkout)
    with pytest.raises(ConfigError, match=r"shared/data-v2.*older corpus .*shared/data \(v1\).*WEARPOSE_DATA="):
        data_dir()
    assert data_dir(must_exist=False) == Path("../shared/data-v2")
    (tmp_path / "work" / "shared" / "data-v2").mkdir()
    assert data_dir() == tmp_path / "work" / "shared" / "data-v2"
