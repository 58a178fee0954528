"""``data prepare`` for users' folders: ``--split`` / ``--source``, and the store's record of
which corpus (and which manifest version) it holds."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wearpose.cli import app
from wearpose.errors import ConfigError
from wearpose.motion import CorpusStore, prepare_corpus, template_rest_joints
from test_motion_store import bandai_like_bvh, write_gz

REST = template_rest_joints()


@pytest.fixture()
def mine(tmp_path: Path) -> Path:
    root = tmp_path / "lab_takes"
    write_gz(root / "p01" / "walk.bvh.gz", bandai_like_bvh(3))
    write_gz(root / "p02" / "jog.bvh.gz", bandai_like_bvh(4))
    return root


def test_split_and_source_for_your_folders(mine: Path, tmp_path: Path) -> None:
    cache = tmp_path / "store"
    r = prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, split="test", source="lab")
    assert r["converted"] == 2 and r["failed"] == 0, r["failures"]
    store = CorpusStore(cache)
    assert sorted(store.entries) == ["lab/p01/walk", "lab/p02/jog"]
    assert {e["split"] for e in store.entries.values()} == {"test"}  # an external test set: every clip
    assert store.load("lab/p01/walk").meta["split"] == "test"
    prov = store.provenance()
    assert prov["corpus"] == {"kind": "folders", "paths": [str(mine.resolve())], "split": "test", "source": "lab"}
    assert prov["converter"] == r["store"]["converter"] and prov["path"] == str(cache.resolve())
    # Another split re-converts (the split is in each clip's meta), nothing is skipped stale.
    r2 = prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, split="val", source="lab")
    assert r2["converted"] == 2 and r2["skipped"] == 0
    assert {e["split"] for e in CorpusStore(cache).entries.values()} == {"val"}


def test_two_files_naming_one_clip_are_refused_not_dropped(mine: Path, tmp_path: Path) -> None:
    # walk.bvh beside walk.bvh.gz: both are clip lab/p01/walk; keeping one would drop the other unseen.
    (mine / "p01" / "walk.bvh").write_text(bandai_like_bvh(3))
    cache = tmp_path / "store"
    with pytest.raises(ConfigError, match=r"walk.bvh and .*walk.bvh.gz both become clip lab/p01/walk.*keep one"):
        prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, split="test", source="lab")
    assert not (cache / "index.json").exists()


def test_manifest_corpus_records_its_version_and_refuses_split(tmp_path: Path) -> None:
    data = tmp_path / "data-v9"
    write_gz(data / "bandai" / "s1" / "walk.bvh.gz", bandai_like_bvh(0))
    (data / "manifest.csv").write_text("path,source,subject,clip,description,frames,fps,seconds,split,licence,frame0_is_tpose\n"
                                       "data/bandai/s1/walk.bvh.gz,bandai,s1,walk,walk,20,30,0.667,train,CC-BY-NC-4.0,0\n")
    with pytest.raises(ConfigError, match="split/source/asf/up apply to your own folders"):
        prepare_corpus(data, tmp_path / "c", progress=False, workers=1, rest_joints=REST, split="test")
    prepare_corpus(data, tmp_path / "c", progress=False, workers=1, rest_joints=REST)
    c = CorpusStore(tmp_path / "c").provenance()["corpus"]
    assert c["kind"] == "manifest" and c["name"] == "data-v9" and len(c["manifest_sha1"]) == 40


def test_cli_prepare_split_and_source(mine: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["data", "prepare", str(mine), "--cache", str(tmp_path / "s"), "--split", "test",
                                   "--source", "lab", "--workers", "1", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["converted"] == 2 and out["store"]["corpus"]["split"] == "test"
    bad = CliRunner().invoke(app, ["data", "prepare", str(mine), "--cache", str(tmp_path / "s"), "--split", "holdout"])
    assert bad.exit_code == 2 and "train, val, test, hash" in bad.output
    bad = CliRunner().invoke(app, ["data", "prepare", str(mine), "--cache", str(tmp_path / "s"), "--source", "my lab"])
    assert bad.exit_code == 2 and "'my lab'" in bad.output
    info = CliRunner().invoke(app, ["data", "info", "--cache", str(tmp_path / "s")])
    assert info.exit_code == 0 and "your folders" in info.output and "split test" in info.output


def test_up_and_asf_options_reach_the_import(mine: Path, tmp_path: Path) -> None:
    """--up is every clip's up axis (the report says 'given'); both are refused for a manifest
    corpus and checked before anything runs."""
    cache = tmp_path / "s"
    prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, up="y")
    seq = CorpusStore(cache).load("lab_takes/p01/walk")
    assert seq.meta["import"]["up"]["how"] == "given"
    with pytest.raises(ConfigError, match="up axis 'w'"):
        prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, up="w")
    with pytest.raises(ConfigError, match="ASF file .*nope.asf does not exist"):
        prepare_corpus([mine], cache, progress=False, workers=1, rest_joints=REST, asf=tmp_path / "nope.asf")
