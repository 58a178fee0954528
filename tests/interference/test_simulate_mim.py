"""Condition simulation (spikes from static metal, persistent error from carried metal), MIM."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.errors import ConfigError
from wearpose.geometry import axis_angle_to_matrix
from wearpose.interference import (
    MIM, ConditionPreset, MetalObject, MIMConfig, NBeats, NBeatsConfig, NumpyNBeats, Scene, SiteTrajectories,
    binary_metrics, detect, rotation_error, simulate_condition,
)
from wearpose.sensors import ImuNoise, angular_velocity

FPS = 120.0


def _traj(T: int = 360) -> SiteTrajectories:
    """A wrist sweeping along x in front of a room-fixed source 1.5 m above the floor, slowly turning."""
    t = np.arange(T) / FPS
    p = np.stack([-0.6 + 1.2 * t / t[-1], 1.2 + 0.02 * np.sin(3 * t), np.full(T, 0.5)], 1)
    aa = np.stack([0.3 * np.sin(2 * t), 0.5 * t, 0.2 * np.cos(t)], 1)
    R = axis_angle_to_matrix(torch.from_numpy(aa))
    eye = torch.eye(3, dtype=torch.float64).expand(T, 3, 3).clone()
    src = torch.tensor([0.0, 1.5, 0.0], dtype=torch.float64).expand(T, 3).clone()
    return SiteTrajectories(("right_wrist",), R[:, None], torch.from_numpy(p)[:, None], eye, src, FPS)


QUIET = ConditionPreset("quiet", floor_reflection=0.0, coil_gain_sigma=0.0, coil_misalign_deg=0.0)


def test_open_space_is_accurate():
    sim = simulate_condition(_traj(), ConditionPreset("open", floor_reflection=0.3), seed=0)
    s = sim["right_wrist"]
    assert s.pos_error.max() < 0.01 and np.degrees(s.rot_error.max()) < 1.5
    assert s.R.shape == (360, 3, 3) and s.p.shape == s.gyro.shape == s.acc.shape == (360, 3) and s.valid.all()


def test_static_object_gives_a_spike():
    tr = _traj()
    k = 180  # closest approach half way
    c = tr.p[k, 0].numpy() + np.array([0.0, -0.08, 0.0])
    s = simulate_condition(tr, QUIET, seed=0, scene=Scene([MetalObject.sphere("hammer", c, 0.04)]))["right_wrist"]
    peak = int(np.argmax(s.pos_error))
    assert abs(peak - k) < 15
    assert s.pos_error[peak] > 10 * np.median(s.pos_error)
    far = np.r_[0:60, 300:360]
    assert s.pos_error[far].max() < 0.2 * s.pos_error[peak]  # the error is a spike, not a bias


def test_carried_object_gives_persistent_error():
    tr = _traj()
    active = np.zeros(360, bool)
    active[100:300] = True
    can = MetalObject.sphere("can", [0.06, 0.0, 0.0], 0.033, carrier="right_wrist", active=active)
    s = simulate_condition(tr, QUIET, seed=0, scene=Scene([can]))["right_wrist"]
    assert s.carried[150] and not s.carried[50]
    assert np.median(s.pos_error[110:290]) > 5 * np.median(s.pos_error[:90])
    assert (s.pos_error[110:290] > 3 * np.median(s.pos_error[:90])).mean() > 0.9


def test_head_source_rejects_head_sensor():
    from wearpose.interference import body_trajectories

    class _Body:
        site_names = ("head", "left_wrist")

    with pytest.raises(ConfigError):
        body_trajectories(None, _Body(), ("head",), source="head")


def _clean_stream(T=360, seed=0):
    tr = _traj(T)
    R = tr.R[:, 0].numpy()
    gyro = angular_velocity(tr.R[:, 0], FPS).numpy()
    gyro = gyro + np.radians(0.01) * np.sqrt(FPS) * np.random.default_rng(seed).standard_normal(gyro.shape)
    return R, tr.p[:, 0].numpy(), gyro


def test_detection_flags_an_injected_spike():
    R, p, gyro = _clean_stream()
    Rm = R.copy()
    bump = np.radians(np.r_[np.linspace(0, 12, 10), np.linspace(12, 0, 10)])
    for i, b in enumerate(bump):
        Rm[150 + i] = R[150 + i] @ axis_angle_to_matrix(torch.tensor([0.0, b, 0.0], dtype=torch.float64)).numpy()
    flags, disc = detect(Rm, gyro, FPS, threshold_deg=1.0)
    truth = np.zeros(len(R), bool)
    truth[150:170] = True
    assert flags[153:167].all()
    assert not flags[:140].any() and not flags[185:].any()
    assert binary_metrics(flags, truth)["mcc"] > 0.7


def test_rotation_correction_and_degraded_flag():
    R, p, gyro = _clean_stream()
    acc = np.zeros_like(p)
    Rm = R.copy()
    for i in range(150, 170):  # short interference: 20 frames of a 10 deg offset
        Rm[i] = R[i] @ axis_angle_to_matrix(torch.tensor([0.17, 0.0, 0.0], dtype=torch.float64)).numpy()
    out = MIM(MIMConfig(position="none")).process(Rm, p, gyro, acc, FPS)
    raw = np.degrees(rotation_error(Rm[150:170], R[150:170]).mean())
    cor = np.degrees(rotation_error(out["R"][150:170], R[150:170]).mean())
    assert cor < 0.2 * raw and out["corrected"][150:170].all() and not out["degraded"].any()
    # persistent interference (2 s): corrected for max_correction_s, then degraded, no drift-prone correction
    Rm2 = R.copy()
    for i in range(100, 340):
        Rm2[i] = R[i] @ axis_angle_to_matrix(torch.tensor([0.17, 0.0, 0.0], dtype=torch.float64)).numpy()
    out2 = MIM(MIMConfig(position="none", max_correction_s=0.5)).process(Rm2, p, gyro, acc, FPS)
    assert out2["corrected"][100:160].all() and not out2["corrected"][170:340].any()
    assert out2["degraded"][170:340].all() and (out2["interfered"] | out2["degraded"])[100:340].all()
    assert not out2["degraded"][350:].any()  # released once EM and the gyro chain agree again
    assert out2["level"][200] > 1.0 > out2["level"][50]


class _KalmanAlways(MIM):
    """MIM with its trusted-position Kalman filter run whatever the config (as before issue 25)."""

    def reset(self) -> None:
        super().reset()
        self._use_kf = True


@pytest.mark.parametrize("position", ["none", "hold", "odometry"])
def test_skipping_the_unused_kalman_filter_changes_no_output(position):
    """Without a position test or "fusion" the Kalman filter is skipped (issue 25, MIM's cost): the
    outputs equal those of the filter run every frame, bit for bit, through a correction and a
    degraded stretch."""
    R, p, gyro = _clean_stream()
    acc = np.random.default_rng(0).normal(0.0, 0.3, p.shape)
    Rm = _ramp(R, 100, 10, 20, 10.0)
    Rm[200:330] = _ramp(R, 200, 5, 125, 12.0)[200:330]
    cfg = MIMConfig(position=position, max_correction_s=0.5)
    skip, full = MIM(cfg), _KalmanAlways(cfg)
    assert not skip._use_kf and full._use_kf
    a, b = skip.process(Rm, p, gyro, acc, FPS), full.process(Rm, p, gyro, acc, FPS)
    assert a["corrected"].any() and a["degraded"].any()
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def _ramp(R: np.ndarray, start: int, rise: int, hold: int, deg: float) -> np.ndarray:
    """``R`` with a rotation offset growing linearly to ``deg`` over ``rise`` frames, held ``hold`` frames."""
    Rm = R.copy()
    amp = np.r_[np.linspace(0, deg, rise), np.full(hold, deg)]
    for i, a in enumerate(np.radians(amp)):
        Rm[start + i] = R[start + i] @ axis_angle_to_matrix(torch.tensor([a, 0.0, 0.0], dtype=torch.float64)).numpy()
    return Rm


def test_anchor_before_the_onset_keeps_a_growing_distortion_out_of_the_correction():
    # interference that grows over ~0.17 s: by the time it crosses the threshold the previous
    # frames are already distorted; restarting the gyro chain 36 frames back avoids that
    R, p, gyro = _clean_stream()
    Rm = _ramp(R, 150, 20, 30, 20.0)
    acc = np.zeros_like(p)
    sl = slice(175, 200)
    err = {}
    for L in (1, 36):
        out = MIM(MIMConfig(position="none", threshold_deg=5.0, anchor_frames=L)).process(Rm, p, gyro, acc, FPS)
        if L == 36:  # with the previous frame as anchor the flag flickers: the chain starts distorted
            assert out["corrected"][160:200].all()
        err[L] = np.degrees(rotation_error(out["R"][sl], R[sl]).mean())
    raw = np.degrees(rotation_error(Rm[sl], R[sl]).mean())
    assert err[36] < 0.3 * raw and err[36] < 0.5 * err[1]


def test_hysteresis_and_position_test():
    R, p, gyro = _clean_stream()
    acc = np.gradient(np.gradient(p, 1 / FPS, axis=0), 1 / FPS, axis=0)
    # a 6 cm position jump without any rotation change: only the position test sees it
    pm = p.copy()
    pm[200:220] += np.array([0.06, 0.0, 0.0])
    off, _ = detect(R, gyro, FPS, 5.0, p=pm, acc=acc)
    on, _ = detect(R, gyro, FPS, 5.0, p=pm, acc=acc, pos_threshold_cm=3.0)
    assert not off[195:225].any() and on[200:215].all() and not on[:190].any()
    # hysteresis: a distortion hovering between release and detection thresholds stays flagged
    Rm = _ramp(R, 150, 6, 40, 8.0)
    Rm[156:196] = np.stack([R[i] @ axis_angle_to_matrix(torch.tensor([np.radians(8.0 if i < 160 else 4.0), 0.0, 0.0],
                                                                        dtype=torch.float64)).numpy() for i in range(156, 196)])
    plain, _ = detect(Rm, gyro, FPS, 5.0)
    hyst, _ = detect(Rm, gyro, FPS, 5.0, release_ratio=0.5)
    assert hyst[165:195].all() and not plain[165:195].any()


def test_kalman_fusion_corrects_a_position_spike():
    R, p, gyro = _clean_stream()
    acc = np.gradient(np.gradient(p, 1 / FPS, axis=0), 1 / FPS, axis=0)
    pm, Rm = p.copy(), R.copy()
    ramp = np.r_[np.linspace(0, 1, 20), np.ones(20)]
    pm[200:240] += 0.1 * ramp[:, None] * np.array([0.0, 1.0, 0.0])
    for i in range(200, 240):
        Rm[i] = R[i] @ axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.35 * ramp[i - 200]], dtype=torch.float64)).numpy()
    out = MIM(MIMConfig(position="fusion")).process(Rm, pm, gyro, acc, FPS)  # shipped forecaster
    c = out["corrected"]
    assert c[210:240].all()
    raw = np.linalg.norm(pm[c] - p[c], axis=1).mean()
    fus = np.linalg.norm(out["p"][c] - p[c], axis=1).mean()
    assert fus < 0.02 and fus < 0.3 * raw  # exact acceleration, clean state 12 frames before the detection


def _tiny_forecaster():
    torch.manual_seed(0)
    return NBeats(NBeatsConfig(width=16, layers=2))


def test_numpy_nbeats_matches_torch():
    m = _tiny_forecaster().eval()
    x = np.random.default_rng(0).normal(scale=0.1, size=(120, 3))
    with torch.no_grad():
        ref = m(torch.from_numpy(x).float()[None])[0].double().numpy()
    np.testing.assert_allclose(NumpyNBeats(m)(x), ref, atol=1e-5)


@pytest.mark.parametrize("method", ["none", "hold", "odometry", "nbeats", "fusion", "fusion-eq3"])
def test_position_methods_run_and_stay_bounded(method):
    R, p, gyro = _clean_stream()
    acc = np.gradient(np.gradient(p, 1 / FPS, axis=0), 1 / FPS, axis=0)
    pm = p.copy()
    pm[200:230] += np.array([0.0, 0.08, 0.0])  # a position spike
    Rm = R.copy()
    for i in range(200, 230):
        Rm[i] = R[i] @ axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.15], dtype=torch.float64)).numpy()
    out = MIM(MIMConfig(position=method), forecaster=NumpyNBeats(_tiny_forecaster())).process(Rm, pm, gyro, acc, FPS)
    assert out["p"].shape == (360, 3) and np.isfinite(out["p"]).all()
    err = np.linalg.norm(out["p"][200:230] - p[200:230], axis=1).mean()
    if method == "odometry":
        assert err < 0.02  # exact acceleration: only the initial velocity estimate errs (the spike is 8 cm)
    if method == "none":
        assert err == pytest.approx(0.08, abs=1e-6)


def test_mim_step_latency_budget():
    import time
    R, p, gyro = _clean_stream()
    mim = MIM(MIMConfig(position="odometry"))
    acc = np.zeros(3)
    t0 = time.perf_counter()
    for t in range(360):
        mim.step(R[t], p[t], gyro[t], acc, 1 / FPS)
    per_frame_ms = (time.perf_counter() - t0) / 360 * 1e3
    assert per_frame_ms < 5.0  # loose bound for a loaded CI machine; benchmarks/interference.py measures it


def test_metrics():
    y = np.array([1, 1, 0, 0, 0, 0], bool)
    assert binary_metrics(y, y)["mcc"] == pytest.approx(1.0)
    assert binary_metrics(~y, y)["mcc"] == pytest.approx(-1.0)
    m = binary_metrics(np.array([1, 0, 1, 0, 0, 0], bool), y)
    assert m["precision"] == pytest.approx(0.5) and m["recall"] == pytest.approx(0.5) and m["f1"] == pytest.approx(0.5)


def test_shipped_forecaster_beats_holding_on_a_swing():
    from wearpose.interference.mim import load_numpy_forecaster

    f = load_numpy_forecaster("nbeats_cpu")
    t = np.arange(180) / FPS
    errs_nb, errs_hold = [], []
    for ph in np.linspace(0, 2 * np.pi, 6, endpoint=False):
        x = np.stack([0.25 * np.sin(2 * np.pi * 0.5 * t + ph), -0.4 + 0.1 * np.cos(2 * np.pi * 0.5 * t + ph), np.full_like(t, 0.3)], 1)
        pred = f(x[:120])
        errs_nb.append(np.abs(pred - x[120:]).mean())
        errs_hold.append(np.abs(x[119] - x[120:]).mean())
    assert np.mean(errs_nb) < 0.8 * np.mean(errs_hold)


@pytest.mark.corpus
def test_nbeats_training_pipeline_tiny(tmp_path, corpus_store):
    from wearpose.interference.nbeats import NBeatsConfig, load_forecaster, train

    res = train(NBeatsConfig.preset("tiny"), tmp_path, max_train_clips=3, log=lambda s: None)
    assert (tmp_path / "best.pt").exists() and np.isfinite(res["best_val_mae_cm"])
    model, ck = load_forecaster(tmp_path / "best.pt")
    assert ck["config"]["width"] == 32


@pytest.mark.corpus
def test_forecasters_side_by_side_pool_their_groups(corpus_store):
    """``evaluate_on_store``: per-source figures pool to the overall one (window-weighted), every
    model sees the same windows as the baselines, and forecasters of different windows are
    refused."""
    import dataclasses

    import torch

    from wearpose.errors import ConfigError
    from wearpose.interference.nbeats import NBeats, NBeatsConfig, evaluate_on_store
    from wearpose.motion import CorpusStore

    cfg = NBeatsConfig.preset("tiny")
    torch.manual_seed(0)
    a, b = NBeats(cfg), NBeats(dataclasses.replace(cfg, seed=1))
    res = evaluate_on_store({"a": a, "b": b}, CorpusStore(), "test")
    for m in res["models"].values():
        groups = m["groups"].values()
        assert sum(g["windows"] for g in groups) == m["all"]["windows"] > 0
        pooled = sum(g["mae_cm"] * g["windows"] for g in groups) / m["all"]["windows"]
        assert pooled == pytest.approx(m["all"]["mae_cm"], rel=1e-6)
    assert res["models"]["a"]["all"]["mae_cm"] != res["models"]["b"]["all"]["mae_cm"]
    assert set(res["baselines"]["groups"]) == set(res["models"]["a"]["groups"])
    with pytest.raises(ConfigError, match="windows differ"):
        evaluate_on_store({"a": a, "short": NBeats(dataclasses.replace(cfg, output_len=30))}, CorpusStore(), "test")
