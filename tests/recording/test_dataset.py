"""simulate_corpus: a recording set from corpus clips (index, seeds, idempotence, failures, licences)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.recording.dataset_testutils import make_mini_store
from wearpose.errors import ConfigError
from wearpose.recording import load_recording
from wearpose.recording.dataset import clip_seed, is_noncommercial, load_index, simulate_corpus


def test_clip_seed_is_a_stable_hash():
    assert clip_seed(0, "a/b/c") == clip_seed(0, "a/b/c")
    assert len({clip_seed(s, c) for s in (0, 1) for c in ("a/b/c", "a/b/d")}) == 4
    assert 0 <= clip_seed(123, "x") < 2 ** 48
    assert clip_seed(0, "cmu_daz/05/05_01") == 146344845633653  # pinned: sets must stay reproducible


def test_noncommercial_licences():
    assert is_noncommercial("CC-BY-NC-4.0") and is_noncommercial("CC BY-NC-SA 4.0")
    assert not is_noncommercial("CMU-mocap-terms") and not is_noncommercial("CC0-1.0") and not is_noncommercial(None)


@pytest.fixture(scope="module")
def mini(tmp_path_factory, corpus_root):
    return make_mini_store(tmp_path_factory.mktemp("corpus"), corpus_root)


@pytest.fixture(scope="module")
def em_set(mini, tmp_path_factory):
    cache, ids = mini
    out = tmp_path_factory.mktemp("set") / "em12"
    res = simulate_corpus(out, "em12", None, cache_dir=cache, seed=5, workers=1, progress=False)
    return out, res


@pytest.mark.corpus
def test_set_index_and_recordings(mini, em_set):
    cache, ids = mini
    out, res = em_set
    assert (res["selected"], res["simulated"], res["failed"], res["workers"]) == (3, 3, 0, 1)
    assert res["sensor_frames"] > 0 and res["bytes"] > 0
    idx = load_index(out)
    assert idx["settings"]["kit"] == "em12" and idx["include_nc"] is True
    assert sorted(idx["clips"]) == ids
    store_index = json.loads((cache / "index.json").read_text())["clips"]
    for cid, row in idx["clips"].items():
        assert row["seed"] == clip_seed(5, cid) and row["kit"] == "em12"
        assert row["licence"] == store_index[cid]["licence"]
        assert row["noncommercial"] == is_noncommercial(row["licence"])
        assert (out / row["file"]).stat().st_size == row["bytes"]
        rec = load_recording(out / row["file"])
        assert len(rec.sensors) == 12 and rec.sensors[0].num_frames == row["frames"]
        assert rec.ground_truth.num_frames == store_index[cid]["frames"] == row["motion_frames"]
        assert rec.meta["clip_id"] == cid and rec.meta["clip_seed"] == row["seed"] and rec.meta["kit"] == "em12"
        assert "offsets" in rec.subject and rec.meta["em_source"]["site"] == "pelvis"
    assert idx["noncommercial_clips"] == sum(r["noncommercial"] for r in idx["clips"].values())


@pytest.mark.corpus
def test_rerun_is_idempotent_and_repairs(mini, em_set):
    cache, ids = mini
    out, _ = em_set
    row = load_index(out)["clips"][ids[0]]
    before = (out / row["file"]).stat().st_mtime_ns
    res = simulate_corpus(out, "em12", None, cache_dir=cache, seed=5, workers=1, progress=False)
    assert (res["simulated"], res["skipped"]) == (0, 3)
    assert (out / row["file"]).stat().st_mtime_ns == before
    # a lost file is simulated again, identically (the clip seed does not depend on the run)
    data = dict(np.load(out / row["file"]))
    (out / row["file"]).unlink()
    res = simulate_corpus(out, "em12", None, cache_dir=cache, seed=5, workers=1, progress=False)
    assert (res["simulated"], res["skipped"]) == (1, 2)
    again = np.load(out / row["file"])
    assert sorted(again.files) == sorted(data) and all(
        np.array_equal(again[k], data[k], equal_nan=data[k].dtype.kind == "f") for k in data)
    # other settings in the same directory: refused, naming the difference
    with pytest.raises(ConfigError, match="seed"):
        simulate_corpus(out, "em12", None, cache_dir=cache, seed=6, workers=1, progress=False)


@pytest.mark.corpus
def test_a_broken_clip_is_reported_and_the_batch_carries_on(mini, tmp_path):
    cache, ids = mini
    broken = tmp_path / "store"
    shutil.copytree(cache, broken)
    idx = json.loads((broken / "index.json").read_text())
    (broken / idx["clips"][ids[1]]["file"]).write_bytes(b"not an npz")
    res = simulate_corpus(tmp_path / "out", "imu6", None, cache_dir=broken, workers=1, progress=False, source_pose=False)
    assert (res["simulated"], res["failed"]) == (2, 1)
    assert list(res["failures"]) == [ids[1]] and "InputFileError" in res["failures"][ids[1]]
    index = load_index(tmp_path / "out")
    assert ids[1] in index["failures"] and ids[1] not in index["clips"] and len(index["clips"]) == 2


@pytest.mark.corpus
def test_exclude_noncommercial_and_filters(mini, tmp_path):
    cache, ids = mini
    idx = json.loads((cache / "index.json").read_text())["clips"]
    nc = [c for c in ids if is_noncommercial(idx[c]["licence"])]
    if not nc:
        pytest.skip("the corpus has no NonCommercial clip")
    res = simulate_corpus(tmp_path / "out", "imu6", None, cache_dir=cache, include_nc=False, workers=1, progress=False,
                          limit=5, rate=30.0)
    assert res["excluded_nc"] == len(nc) and res["selected"] == len(ids) - len(nc)
    index = load_index(tmp_path / "out")
    assert index["include_nc"] is False and index["noncommercial_clips"] == 0 and index["settings"]["rate"] == 30.0
    with pytest.raises(ConfigError, match="no clip selected"):
        simulate_corpus(tmp_path / "out2", "imu6", "train", cache_dir=cache, source="no-such-source", progress=False)
    with pytest.raises(ConfigError, match="noise"):
        simulate_corpus(tmp_path / "out3", "imu6", cache_dir=cache, noise="loud", progress=False)


@pytest.mark.corpus
def test_imu6_clips_open_with_a_marked_tpose_by_default(mini, em_set, tmp_path):
    """imu6 sets hold 1 s of T-pose before each clip (PIP calibrates from it); --tpose 0 and
    other kits do not, and their settings (hence existing sets' keys) carry no tpose entry."""
    from wearpose.motion import CorpusStore
    from wearpose.recording import calibration_window

    cache, ids = mini
    res = simulate_corpus(tmp_path / "imu", "imu6", None, cache_dir=cache, limit=1, workers=1, progress=False)
    assert res["settings"]["tpose_s"] == 1.0
    row = load_index(tmp_path / "imu")["clips"][ids[0]]
    rec = load_recording(tmp_path / "imu" / row["file"])
    clip = CorpusStore(cache).load(ids[0])
    a, b = calibration_window(rec)
    assert 0 < a < b < 1.0 and rec.meta["calibration_window"]["prefix_s"] == pytest.approx(1.5, abs=1.0 / clip.fps)
    assert rec.ground_truth.num_frames == clip.num_frames + round(1.5 * clip.fps)
    assert "tpose_s" not in em_set[1]["settings"]
    res0 = simulate_corpus(tmp_path / "imu0", "imu6", None, cache_dir=cache, limit=1, workers=1, progress=False, tpose=0)
    rec0 = load_recording(tmp_path / "imu0" / row["file"])
    assert "tpose_s" not in res0["settings"] and calibration_window(rec0) is None
    assert rec0.ground_truth.num_frames == clip.num_frames


@pytest.mark.corpus
def test_sets_of_every_body_size(mini, em_set, tmp_path):
    """--shapes random / heldout: each clip's recording is simulated on its own wearer (seeded by
    the clip seed), its ground truth re-fitted to that body (betas stored, rotations kept); the two
    draws differ; sets without the option keep their settings key."""
    from wearpose.motion import CorpusStore
    from wearpose.sensors import random_body_shape

    cache, ids = mini
    assert "shapes" not in em_set[1]["settings"]
    betas = {}
    for draw in ("random", "heldout"):
        res = simulate_corpus(tmp_path / draw, "em12", None, cache_dir=cache, limit=1, workers=1, progress=False,
                              shapes=draw, seed=5)
        assert res["failed"] == 0 and res["settings"]["shapes"] == draw
        row = load_index(tmp_path / draw)["clips"][ids[0]]
        rec = load_recording(tmp_path / draw / row["file"])
        gt, clip = rec.ground_truth, CorpusStore(cache).load(ids[0])
        want = random_body_shape(clip_seed(5, ids[0]), draw=draw)
        assert np.allclose(np.asarray(gt.betas), want.numpy()) and float(np.abs(gt.betas).max()) > 0
        assert np.allclose(np.asarray(gt.pose), clip.pose.numpy(), atol=1e-6)
        betas[draw] = np.asarray(gt.betas)
    assert not np.allclose(betas["random"], betas["heldout"])
    with pytest.raises(ConfigError, match="shapes"):
        simulate_corpus(tmp_path / "x", "em12", None, cache_dir=cache, limit=1, workers=1, progress=False, shapes="tall")


def test_worker_default_ignores_a_momentary_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """The default worker count is the cores the process may use, whatever the load average says."""
    import os

    from wearpose.recording.dataset import usable_cores

    monkeypatch.setattr(os, "getloadavg", lambda: (5.0, 5.0, 5.0))
    expect = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    assert usable_cores() == max(1, expect)
