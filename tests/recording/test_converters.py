"""Converters from public dataset layouts, on small synthetic files written in each source layout."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from recording_testutils import rotations
from wearpose.errors import InputFileError
from wearpose.geometry import Z_UP_TO_Y_UP, matrix_to_quat
from wearpose.recording import (
    EMPOSE_SENSORS,
    amass_ground_truth,
    from_dip_imu,
    from_empose,
    from_totalcapture,
    load_recording,
)


# ------------------------------------------------------------------------------------ DIP-IMU
def _write_dip(path, T=90, nan_frames=(3, 4)):
    rng = np.random.default_rng(0)
    ori = np.stack([rotations(T, seed=i) for i in range(17)], axis=1)
    acc = rng.normal(size=(T, 17, 3))
    ori[list(nan_frames), 7] = np.nan  # left "elbow" (forearm) sensor drops out
    acc[list(nan_frames), 7] = np.nan
    gt = rng.normal(scale=0.2, size=(T, 72))
    with open(path, "wb") as fh:
        pickle.dump({"imu_ori": ori, "imu_acc": acc, "gt": gt, "imu": np.zeros((T, 17, 12))}, fh, protocol=2)
    return ori, acc, gt


def test_dip_imu_six(tmp_path):
    p = tmp_path / "s_09" / "01.pkl"
    p.parent.mkdir()
    ori, acc, gt = _write_dip(p)
    rec = from_dip_imu(p)
    assert rec.names == ("left_forearm", "right_forearm", "left_lower_leg", "right_lower_leg", "head", "pelvis")
    lf = rec.sensor("left_forearm")
    assert lf.kind == "imu" and lf.info.site == "left_forearm" and lf.info.rate == 60.0
    assert not lf.valid[3] and not lf.valid[4] and lf.valid[5]  # NaN frames masked, not filled
    np.testing.assert_allclose(lf.orientation[5], ori[5, 7], atol=1e-6)
    np.testing.assert_allclose(rec.sensor("pelvis").acceleration, acc[:, 2], atol=1e-6)
    assert rec.sensor("head").timestamps[60] == pytest.approx(1.0)
    assert rec.ground_truth.num_frames == 90 and rec.ground_truth.fps == 60.0
    assert float(rec.ground_truth.trans.abs().max()) == 0.0
    assert rec.subject["id"] == "s_09" and rec.is_canonical
    assert rec.meta["source_sensor_indices"]["pelvis"] == 2
    back = load_recording(rec.save(tmp_path / "dip.npz"))
    assert back.names == rec.names


def test_dip_imu_all_and_errors(tmp_path):
    p = tmp_path / "01.pkl"
    _write_dip(p)
    rec = from_dip_imu(p, sensors="all", with_ground_truth=False)
    assert len(rec.sensors) == 17 and rec.sensor("left_elbow").info.site == "left_forearm"
    assert rec.ground_truth is None
    with open(p, "wb") as fh:
        pickle.dump({"imu_ori": np.zeros((5, 17, 3, 3))}, fh)
    with pytest.raises(InputFileError) as ei:
        from_dip_imu(p)
    assert ei.value.field == "imu_acc"


class _Evil:
    def __reduce__(self):
        return (print, ("this must never run",))


def test_dip_imu_refuses_code_in_pickles(tmp_path):
    p = tmp_path / "evil.pkl"
    with open(p, "wb") as fh:
        pickle.dump({"imu_ori": _Evil()}, fh)
    with pytest.raises(InputFileError, match="refusing to unpickle"):
        from_dip_imu(p)


# ------------------------------------------------------------------------------- TotalCapture
def _tc_truth(T=80):
    """Truth: Y-up R_WS and free acceleration; written as TotalCapture would (Z up, sensor frame, gravity in)."""
    rng = np.random.default_rng(2)
    C = Z_UP_TO_Y_UP.numpy()
    names = ["Head", "R_LowArm", "Pelvis"]
    truth = {}
    for i, n in enumerate(names):
        R = rotations(T, seed=10 + i)
        a = rng.normal(size=(T, 3))
        Rz = C.T @ R
        f_s = np.einsum("nji,nj->ni", Rz, (a - np.array([0, -9.81, 0])) @ C)
        q = matrix_to_quat(torch.from_numpy(Rz)).numpy()
        truth[n] = (R, a, q, f_s, rng.normal(size=(T, 3)), rng.normal(size=(T, 3)))
    return names, truth


def _write_tc(path, names, truth, aux, T, drop=None):
    lines = [f"{len(names)}\t{T}"]
    for f in range(T):
        lines.append(str(f + 1))
        for n in names:
            R, a, q, f_s, g, m = truth[n]
            vals = list(q[f]) + list(f_s[f]) + (list(g[f]) + list(m[f]) if aux else [])
            if drop == (n, f):
                vals = [float("nan")] * len(vals)
            lines.append(n + "\t" + "\t".join(f"{v:.9f}" for v in vals))
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("aux", [False, True])
def test_totalcapture(tmp_path, aux):
    T = 80
    names, truth = _tc_truth(T)
    p = tmp_path / ("Acting1_Xsens_AuxFields.sensors" if aux else "s1_acting1_Xsens.sensors")
    _write_tc(p, names, truth, aux, T, drop=("Pelvis", 7))
    rec = from_totalcapture(p)
    assert rec.names == ("head", "right_forearm", "pelvis")
    s = rec.sensor("right_forearm")
    assert s.kind == ("mimu" if aux else "imu")
    assert s.info.acc_frame == "sensor" and s.info.acc_gravity == "included" and s.info.world_up == "z_up"
    assert not rec.sensor("pelvis").valid[7] and rec.sensor("pelvis").valid[6]
    can = rec.to_canonical()
    for n, wp in zip(names, rec.names):
        R, a = truth[n][0], truth[n][1]
        c = can.sensor(wp)
        ok = c.valid
        np.testing.assert_allclose(c.orientation[ok], R[ok], atol=1e-5)
        np.testing.assert_allclose(c.acceleration[ok], a[ok], atol=1e-4)
        if aux:
            np.testing.assert_allclose(c.angular_velocity[ok], truth[n][4][ok], atol=1e-5)
    assert rec.meta["source_sensor_names"]["right_forearm"] == "R_LowArm"
    only = from_totalcapture(p, sensors=["Head"])
    assert only.names == ("head",)


def test_totalcapture_truncated_and_garbled(tmp_path):
    names, truth = _tc_truth(10)
    p = tmp_path / "x.sensors"
    _write_tc(p, names, truth, True, 10)
    lines = p.read_text().splitlines()
    p.write_text("\n".join(lines[:-5]) + "\n")
    with pytest.raises(InputFileError, match="truncated"):
        from_totalcapture(p)
    lines[3] = lines[3].replace("\t", "\tabc\t", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputFileError) as ei:
        from_totalcapture(p)
    assert ei.value.field == "line 4"
    p.write_text("three 10\n")
    with pytest.raises(InputFileError) as ei:
        from_totalcapture(p)
    assert ei.value.field == "line 1"


# ------------------------------------------------------------------------------------ EM-POSE
def _write_empose(path, F=60):
    rng = np.random.default_rng(4)
    pos = rng.normal(scale=0.5, size=(F, 12, 3))
    ori = np.stack([rotations(F, seed=20 + i) for i in range(12)], axis=1)
    mask = np.ones((F, 12), bool)
    mask[10:15, 2] = False
    pos[10:15, 2] = 0.0  # what a dropped frame may hold in the file
    np.savez(path, id=np.array("0402_arms_M"), sensor_pos=pos.reshape(F, 36), sensor_oris=ori.reshape(F, 108),
             sensor_masks=mask, smpl_poses=rng.normal(scale=0.2, size=(F, 156)), smpl_shape=rng.normal(size=16),
             smpl_trans=rng.normal(size=(F, 3)), offset_means=rng.normal(scale=0.01, size=(12, 3)),
             offset_covs=np.tile(np.eye(3) * 1e-5, (12, 1, 1)), offset_r=np.tile(np.eye(3), (12, 1, 1)),
             vertex_ids=np.arange(12))
    return pos, ori


def test_empose(tmp_path):
    p = tmp_path / "0402_arms_M_clean.npz"
    pos, ori = _write_empose(p)
    rec = from_empose(p)
    assert rec.names == EMPOSE_SENSORS and rec.kinds == ("em6dof",)
    rf = rec.sensor("right_lower_arm")
    assert rf.info.reference == "world" and rf.info.rate == 30.0 and rf.info.site == "right_wrist"
    assert not rf.valid[10:15].any() and np.isnan(rf.position[12]).all()
    np.testing.assert_allclose(rec.sensor("left_lower_leg").position, pos[:, 11], atol=1e-6)
    np.testing.assert_allclose(rec.sensor("back").orientation, ori[:, 0], atol=1e-6)
    assert rec.subject["id"] == "0402" and len(rec.subject["offsets"]["translation_mean_m"]) == 12
    gt = rec.ground_truth
    assert gt.num_frames == 60 and gt.betas.shape == (10,)
    assert torch.allclose(gt.pose[:, 22:], torch.eye(3).expand(60, 2, 3, 3))  # SMPL-H body: hands at identity
    six = from_empose(p, sensors="six", with_ground_truth=False)
    assert six.names == ("back", "head", "right_lower_arm", "right_lower_leg", "left_lower_arm", "left_lower_leg")
    back = load_recording(rec.save(tmp_path / "em.npz"))
    assert back.subject == rec.subject and back.ground_truth.num_frames == 60


def test_empose_errors(tmp_path):
    p = tmp_path / "bad_clean.npz"
    np.savez(p, sensor_pos=np.zeros((5, 36)), sensor_oris=np.zeros((5, 100)), sensor_masks=np.ones((5, 12), bool))
    with pytest.raises(InputFileError) as ei:
        from_empose(p)
    assert ei.value.field == "sensor_oris"
    with pytest.raises(InputFileError, match="file not found"):
        from_empose(tmp_path / "missing_clean.npz")


# -------------------------------------------------------------------------------------- AMASS
def test_amass_ground_truth_round_trip(tmp_path):
    from wearpose.motion import MotionSequence, save_amass

    rng = np.random.default_rng(6)
    from wearpose.geometry import axis_angle_to_matrix

    pose = axis_angle_to_matrix(torch.from_numpy(rng.normal(scale=0.2, size=(20, 24, 3)))).float()
    pose[:, 22:] = torch.eye(3)  # SMPL-H files cannot hold SMPL's hand joints
    seq = MotionSequence(pose, torch.zeros(10), torch.from_numpy(rng.normal(size=(20, 3))).float(), 60.0, {})
    rest = torch.zeros(24, 3, dtype=torch.float64)
    rest[0] = torch.tensor([0.0, -0.2, 0.03], dtype=torch.float64)
    p = save_amass(seq, tmp_path / "clip_poses.npz", rest_joints=rest)
    gt = amass_ground_truth(p, rest_joints=rest)
    assert torch.allclose(gt.pose, seq.pose, atol=1e-5) and torch.allclose(gt.trans, seq.trans, atol=1e-5)
