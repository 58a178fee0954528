"""wearpose.interference.study (the computations of benchmarks/interference.py) on tiny inputs:
session grouping, statistics by hand, threshold choice, detection sweep on an injected spike,
and the simulate -> cache -> load round trip on the corpus fixture."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from tests.interference.test_simulate_mim import _clean_stream
from wearpose.geometry import axis_angle_to_matrix
from wearpose.interference import MIMConfig, rotation_error, study


class _Store:
    """Clips ``c0..c4`` of 0.5, 2, 2, 1, 3 s at 120 fps, all in ``test``."""

    seconds = {"c0": 0.5, "c1": 2.0, "c2": 2.0, "c3": 1.0, "c4": 3.0}

    def clips(self, split: str) -> list[str]:
        return list(self.seconds) if split == "test" else []

    def entry(self, c: str) -> dict[str, Any]:
        return {"frames": int(self.seconds[c] * 120), "fps": 120.0}


def test_head_sessions_group_consecutive_clips_of_at_least_the_n_beats_window() -> None:
    # c0 (0.5 s) and c3 (1 s) are shorter than MIN_CLIP_S; 3 s sessions: c1+c2 (4 s), c4 (3 s)
    assert study.head_sessions("test", 3.0, None, _Store()) == [["c1", "c2"], ["c4"]]
    assert study.head_sessions("test", 3.0, 1, _Store()) == [["c1", "c2"]]


def _clip(session: int, pos_cm: list[float], rot_deg: list[float]) -> dict[str, Any]:
    n = len(pos_cm)
    return {"session": session, "p": np.zeros((n, 3)), "pos_error": np.array(pos_cm) / 100,
            "rot_error": np.radians(rot_deg), "carried": np.array([True] + [False] * (n - 1))}


def test_condition_stats_are_per_session_mean_and_sd() -> None:
    clips = [_clip(0, [1, 3], [2, 2]), _clip(0, [5, 7], [2, 6]), _clip(1, [2, 2], [4, 4])]
    s = study.condition_stats(clips)
    # session 0: mean 4 cm, max 7 cm, mean 3 deg, max 6 deg; session 1: 2, 2, 4, 4
    assert s["sessions"] == 2 and s["frames"] == 6 and s["minutes"] == pytest.approx(6 / 120 / 60)
    assert s["mean_pos_cm"] == pytest.approx((3.0, 1.0)) and s["max_pos_cm"] == pytest.approx((4.5, 2.5))
    assert s["mean_rot_deg"] == pytest.approx((3.5, 0.5)) and s["max_rot_deg"] == pytest.approx((5.0, 1.0))
    assert s["carried_fraction"] == pytest.approx(3 / 6)
    parts = study.per_session(clips, np.arange(6.0))
    assert [p.tolist() for p in parts] == [[0, 1, 2, 3], [4, 5]]


def test_best_threshold_maximises_mcc_first_of_equals() -> None:
    truth = np.array([0, 0, 1, 1, 0, 0], bool)
    flags = {1.0: np.array([1, 1, 1, 1, 1, 1], bool), 2.0: np.array([0, 0, 1, 1, 0, 0], bool),
             3.0: np.array([0, 0, 1, 1, 0, 0], bool)}
    assert study.best_threshold(flags, truth) == 2.0


def _spiky_clip(session: int, seed: int) -> dict[str, Any]:
    """A clean wrist stream with a 12 deg, 20-frame orientation bump at frame 150 whose position
    error (the ground truth) is 20 cm on those frames, 0.1 cm elsewhere."""
    R, p, gyro = _clean_stream(seed=seed)
    Rm = R.copy()
    bump = np.radians(np.r_[np.linspace(0, 12, 10), np.linspace(12, 0, 10)])
    for i, b in enumerate(bump):
        Rm[150 + i] = R[150 + i] @ axis_angle_to_matrix(torch.tensor([0.0, b, 0.0], dtype=torch.float64)).numpy()
    err = np.full(len(R), 0.001)
    err[150:170] = 0.2
    return {"session": session, "R": Rm, "R_true": R, "p": p, "p_true": p, "gyro": gyro, "acc": np.zeros_like(p),
            "carried": np.zeros(len(R), bool), "pos_error": err, "rot_error": np.zeros(len(R))}


@pytest.mark.budget(30)  # MIM / the interference simulator per frame on a shared 2-core machine
def test_detection_sweep_finds_the_spike_with_a_val_chosen_threshold() -> None:
    test, val = [_spiky_clip(0, 0)], [_spiky_clip(0, 1)]
    ths = (1.0, 5.0, 15.0)
    sweep = study.detection_sweep(test, val, e_p_cm=(10.0, 30.0), thresholds=ths)
    row = sweep[0]
    assert row["e_p_cm"] == 10.0 and row["val_threshold_deg"] in ths
    assert row["test"]["mcc"] > 0.7 and row["oracle"]["mcc"] >= row["test"]["mcc"], row
    assert sweep[1]["test"]["positive_ratio"] == 0.0  # nothing above 30 cm: no positives, MCC 0
    lit = study.literal_detection(test, val, 10.0, thresholds=ths)
    assert lit["val_threshold_deg"] in ths and -1.0 <= lit["test"]["mcc"] <= 1.0


def test_run_mim_corrects_the_spiked_rotation() -> None:
    clip = _spiky_clip(0, 0)
    raw = np.degrees(rotation_error(clip["R"], clip["R_true"])[150:170].mean())
    r = study.run_mim([clip], MIMConfig(threshold_deg=2.0, position="none"), timing=True)
    assert r["rot_error"].shape == (360,) and r["interfered"][150:170].any()
    assert np.degrees(r["rot_error"][150:170].mean()) < 0.5 * raw
    assert len(r["times"]) + len(r["corr_times"]) == 360


@pytest.mark.budget(30)  # MIM / the interference simulator per frame on a shared 2-core machine
def test_simulate_load_round_trip_on_the_corpus(corpus_store: Path, tmp_path: Path) -> None:
    from wearpose.motion import CorpusStore

    store = CorpusStore(corpus_store)
    (path,) = study.simulate_sessions("test", 1.0, 1, ["open-space"], tmp_path, source="head", store=store,
                                      log=lambda s: None)
    assert path == study.cache_path(tmp_path, "test", "open-space")
    clips = study.load_sessions(path)
    first = study.head_sessions("test", 1.0, 1, store)[0]
    assert [c["clip"] for c in clips] == first and clips[0]["site"] == "left_wrist"
    for c in clips:
        assert c["R"].shape == (len(c["p"]), 3, 3) and c["pos_error"].shape == (len(c["p"]),)
        assert np.allclose(c["pos_error"], np.linalg.norm(c["p"] - c["p_true"], axis=1))
    again = study.load_sessions(study.simulate_sessions("test", 1.0, 1, ["open-space"], tmp_path / "b", source="head",
                                                        store=store, log=lambda s: None)[0])
    assert all(np.array_equal(a["p"], b["p"]) for a, b in zip(clips, again))  # seeded per clip
    stats = study.condition_stats(clips)
    assert stats["sessions"] == 1 and stats["mean_pos_cm"][0] < 2.0  # open space: small errors


def test_detection_metrics_score_the_spike_and_leave_undefined_ratios_undefined() -> None:
    clips = [_spiky_clip(0, 0)]
    m = study.detection_metrics(clips, 2.0, 10.0)
    assert m["frames"] == 360 and m["positive_ratio"] == pytest.approx(20 / 360) and m["mcc"] > 0.7, m
    none = study.detection_metrics(clips, 2.0, 30.0)  # nothing above 30 cm: MCC undefined, not 0
    assert none["mcc"] is None and none["positive_ratio"] == 0.0
    assert study.detection_metrics([], 2.0, 10.0)["frames"] == 0


@pytest.mark.budget(30)  # MIM / the interference simulator per frame on a shared 2-core machine
def test_world_clips_match_the_cached_sessions(corpus_store: Path) -> None:
    from wearpose.body import BodyModel
    from wearpose.motion import CorpusStore

    store, body = CorpusStore(corpus_store), BodyModel()
    cid = store.clips(split="test")[0]
    clips, skipped = study.world_clips([(cid, store.load(cid))], "test", "standard", body)
    assert len(clips) + skipped == 2 and [c["session"] for c in clips] == list(range(len(clips)))
    for c in clips:  # the same seed key as simulate_sessions: the same streams
        tr, _ = study.world_source_trajectories(store.load(cid), body, c["site"])
        s = study.simulate_clip(tr, "test", "standard", cid, c["site"], body)
        assert np.array_equal(s.p, c["p"]) and c["pos_error"].shape == (s.num_frames,)
