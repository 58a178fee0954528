"""MI-Poser T-pose calibration (Sec. 4.2): arm-span scale and alignment to the model's T-pose."""

from __future__ import annotations

import json

import pytest
import torch

from calib_testutils import posed_motion
from wearpose.calibration import CalibrationError, apply_miposer, calibrate, em_to_world, miposer_tpose
from wearpose.geometry import axis_angle_to_matrix, geodesic_angle
from wearpose.sensors import simulate

FPS = 60.0
S_TRUE = 1.12  # the model is 12 % larger than the wearer
C = axis_angle_to_matrix(torch.tensor([0.0, 1.3, 0.0], dtype=torch.float64))  # VIO world heading
TAU = torch.tensor([1.0, 0.2, -3.0], dtype=torch.float64)  # VIO world origin


def _world_streams(sim):
    """Headset and both wrists in the headset's (VIO) world at 60 Hz, then scaled/rotated/shifted."""
    hv, le, re = sim["head_vio"], sim["left_wrist_em"], sim["right_wrist_em"]
    hR, hp = hv.orientation.double(), hv.position.double()
    idx = torch.arange(0, le.num_frames, 2)[: hR.shape[0]]  # the 120 Hz frames at 60 Hz instants
    eR = torch.stack([le.orientation[idx], re.orientation[idx]], 1).double()
    ep = torch.stack([le.position[idx], re.position[idx]], 1).double()
    WR, Wp = em_to_world(hR[:, None].expand_as(eR), hp[:, None].expand_as(ep), eR, ep)
    R = torch.cat([hR[:, None], WR], 1)
    p = torch.cat([hp[:, None], Wp], 1)
    return C @ R, (p @ C.T) / S_TRUE + TAU


@pytest.fixture(scope="module")
def motion():
    m = posed_motion(int(4 * FPS), FPS, seed=4, amp=0.3)
    m.trans[:] += torch.tensor([0.3, 0.0, -0.2], dtype=torch.float64)
    return m


def _truth(body, motion):
    out = body(motion.pose, motion.betas, motion.trans, return_vertices=False)
    # Targets: head (15) and wrist joints (20, 21) positions; rotations of the head and of the
    # forearms (18, 19), which carry a wrist-worn sensor. Positions relative to the T-pose spot.
    return out.joints[:, [15, 20, 21]] - motion.trans[0], out.global_rot[:, [15, 18, 19]]


@pytest.mark.parametrize("noise", ["none", "default"])
def test_scale_and_alignment(body, motion, noise, record_property):
    sim = simulate(motion, "miposer", body, seed=2, noise=noise)
    RM, pM = _world_streams(sim)
    win = slice(6, 54)
    res = miposer_tpose(RM[win, 0], pM[win, 0], RM[win, 1:], pM[win, 1:], body)
    Rc, pc = apply_miposer(res, RM, pM)
    J, G = _truth(body, motion)
    ep = (pc - J).norm(dim=-1) * 1e3
    er = torch.rad2deg(geodesic_angle(Rc, G))
    fig = {"scale": res.scale, "position_mm_median": ep.median(0).values.tolist(), "position_mm_max": ep.max(0).values.tolist(),
           "rotation_deg_median": er.median(0).values.tolist(), "rotation_deg_max": er.max(0).values.tolist()}
    record_property(f"miposer_{noise}", json.dumps(fig))
    print(f"MI-Poser T-pose calibration ({noise} noise):", json.dumps(fig))
    if noise == "none":
        # Exact up to the simulator's float32 output.
        assert abs(res.scale - S_TRUE) < 1e-5
        assert geodesic_angle(res.world_rotation[0], C.T) < 1e-4
        assert ep[win].max() < 0.01 and er[win].max() < 0.01  # exact at the T-pose by construction
        # In motion: wrist sites slide/twist a little on the forearm under skinning.
        assert ep.max() < 2.0 and er[:, 0].max() < 0.01 and er.max() < 4.0
    else:
        assert abs(res.scale - S_TRUE) < 0.01
        assert ep.median() < 30.0 and er.median() < 3.0


def test_single_wrist_variant(body, motion):
    sim = simulate(motion, "miposer", body, seed=2, noise="none")
    RM, pM = _world_streams(sim)
    win = slice(6, 54)
    res = miposer_tpose(RM[win, 0], pM[win, 0], RM[win, 1:2], pM[win, 1:2], body, wrists=["left_wrist"])
    assert abs(res.scale - S_TRUE) < 1e-5
    assert geodesic_angle(res.world_rotation[0], C.T) < 1e-4  # heading from the headset frame


def test_calibrate_recording_and_errors(body, motion):
    from wearpose.recording import Recording

    sim = simulate(motion, "miposer", body, seed=2, noise="none")
    rec = Recording.from_simulation(sim, motion)  # VIO at 60 Hz, wrist EM at 120 Hz relative to the head
    res = calibrate(rec, "miposer-tpose", body=body, window=(0.1, 0.9))
    assert res.sensors == ("head_vio", "left_wrist_em", "right_wrist_em")
    assert abs(res.scale - 1.0) < 1e-6 and res.translation.shape == (3, 3)
    with pytest.raises(CalibrationError, match="vertical"):
        # arms down is not a T-pose: the wrist span is not horizontal enough... use a stacked pose
        R = torch.eye(3, dtype=torch.float64).expand(1, 3, 3)
        miposer_tpose(R, torch.zeros(1, 3, dtype=torch.float64), R[:, None].expand(1, 2, 3, 3),
                      torch.tensor([[[0.0, 0.5, 0.0], [0.0, -0.5, 0.0]]], dtype=torch.float64), body)
