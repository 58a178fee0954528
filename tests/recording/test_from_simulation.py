"""Recording.from_simulation: field mapping, dropped EM frames, and the save/load round trip."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion, tiny_full_sites_asset
from wearpose.body import BodyModel
from wearpose.errors import ShapeError
from wearpose.geometry import quat_to_matrix
from wearpose.recording import Recording, load_recording, save_recording
from wearpose.sensors import EMNoise, NoiseConfig, simulate


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel(tiny_full_sites_asset(), dtype=torch.float64)


@pytest.fixture(scope="module")
def motion():
    return smooth_motion(T=90, fps=60.0, seed=1)


def _sim(motion, kit, body, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(motion, kit, body, **kw)


@pytest.fixture(scope="module")
def em_result(motion, body):
    # Frequent dropouts so that every sensor has masked frames to carry through the file.
    noise = dataclasses.replace(NoiseConfig.default(), em=EMNoise(dropout_rate=0.3, dropout_mean_frames=4.0))
    return _sim(motion, "em12", body, seed=7, noise=noise, offsets="random")


def test_em_mapping(em_result, motion):
    rec = Recording.from_simulation(em_result, motion, "P3", meta={"clip_id": "x/y/z"})
    assert rec.names == em_result.kit.sensor_names
    for s in rec.sensors:
        sd = em_result[s.name]
        i = s.info
        assert (i.kind, i.site, i.rate, i.reference, i.source_site) == ("em6dof", sd.site, 120.0, "source", "pelvis")
        assert i.is_canonical and s.position.dtype == np.float32
        assert np.array_equal(s.valid, sd.valid.numpy())
        assert np.array_equal(s.timestamps, sd.timestamps.numpy())
        ok = s.valid
        assert np.allclose(s.position[ok], sd.position.numpy()[ok], atol=1e-6)
        assert np.isnan(s.position[~ok]).all() and np.isnan(s.orientation[~ok]).all()
    assert sum(int((~s.valid).sum()) for s in rec.sensors) > 0
    assert rec.ground_truth is motion and rec.ground_truth_start == 0.0
    assert rec.subject["id"] == "P3"
    off = rec.subject["offsets"]
    assert off["sensors"] == list(em_result.kit.sensor_names)
    assert np.allclose(off["translation_mean_m"], em_result.em_offsets.t.numpy(), atol=1e-8)
    assert np.allclose(off["rotation"], em_result.em_offsets.R.numpy(), atol=1e-8)
    m = rec.meta
    assert (m["source"], m["kit"], m["seed"], m["clip_id"]) == ("simulation", "em12", 7, "x/y/z")
    assert m["noise"]["em"]["dropout_rate"] == 0.3 and m["site_substitutions"] == {}
    src = m["em_source"]["rates"]["120"]
    P = np.asarray(src["position_m"])
    assert P.shape == (em_result["head"].num_frames, 3)
    assert np.allclose(P, em_result.em_source[120.0]["position"].numpy(), atol=1e-6)
    R = quat_to_matrix(torch.tensor(src["orientation_wxyz"], dtype=torch.float64))
    assert torch.allclose(R, em_result.em_source[120.0]["orientation"], atol=1e-6)


def test_round_trip_with_dropped_frames(em_result, motion, tmp_path):
    rec = Recording.from_simulation(em_result, motion)
    back = load_recording(save_recording(rec, tmp_path / "sim.npz"))  # conventions checked too
    assert back.names == rec.names
    for a, b in zip(rec.sensors, back.sensors):
        assert a.info == b.info
        assert np.array_equal(a.valid, b.valid) and np.array_equal(a.timestamps, b.timestamps)
        assert np.array_equal(a.position, b.position, equal_nan=True)  # NaN exactly where dropped
        ok = a.valid
        assert np.isnan(b.orientation[~ok]).all()
        assert np.allclose(a.orientation[ok], b.orientation[ok], atol=2e-6)  # quaternions on disk
    assert back.subject == rec.subject
    assert back.meta == rec.meta
    gt = back.ground_truth
    assert gt.num_frames == motion.num_frames and gt.fps == motion.fps
    assert torch.allclose(gt.pose.double(), motion.pose.double(), atol=1e-5)
    assert torch.allclose(gt.trans.double(), motion.trans.double(), atol=1e-6)


@pytest.mark.parametrize("kit", ["imu6", "mimu6", "miposer"])
def test_other_kinds_round_trip(kit, motion, body, tmp_path):
    res = _sim(motion, kit, body, seed=2)
    rec = Recording.from_simulation(res, motion, {"id": "s", "height_m": 1.7}, source_pose=False)
    back = load_recording(save_recording(rec, tmp_path / f"{kit}.npz"), check_conventions=True)
    assert back.subject["id"] == "s" and back.subject["height_m"] == 1.7
    assert ("offsets" in back.subject) == (kit == "miposer")  # only kits with EM sensors have offsets
    for s in back.sensors:
        sd = res[s.name]
        assert s.num_frames == sd.num_frames and s.info.rate == sd.rate
        assert s.info.reference == ("source" if sd.kind == "em6dof" else "world")
        if sd.kind in ("imu", "mimu"):
            assert np.allclose(s.acceleration[s.valid], sd.acceleration.numpy()[s.valid], atol=1e-4)
            assert np.allclose(s.angular_velocity[s.valid], sd.angular_velocity.numpy()[s.valid], atol=1e-5)
        if sd.kind == "mimu":
            assert s.info.mag_unit == "T" and s.magnetic_field is not None
    if kit == "miposer":
        # mixed rates: VIO at 60 Hz, EM and IMU at 120 Hz, each on its own grid
        assert back.sensor("head_vio").info.rate == 60.0 and back.sensor("left_wrist_em").info.rate == 120.0
        assert back.meta["em_source"] == {"name": "em_source", "site": "head", "frame": "world"}
        assert back.subject["offsets"]["sensors"] == ["left_wrist_em", "right_wrist_em"]


def test_errors_and_optional_parts(em_result, motion):
    rec = Recording.from_simulation(em_result)
    assert rec.ground_truth is None and rec.subject["id"] == "synthetic"
    with pytest.raises(ShapeError, match="frames"):
        Recording.from_simulation(em_result, motion.slice(0, 30))
    with pytest.raises(ShapeError, match="SimulationResult"):
        Recording.from_simulation(object())
    with pytest.raises(ShapeError, match="subject"):
        Recording.from_simulation(em_result, subject=3)
