"""simulate(): kits on bodies, noise-free consistency, resampling, seeding, errors."""

import math
import warnings
from pathlib import Path

import pytest
import torch

from sensor_testutils import smooth_motion
from wearpose.body import BodyModel
from wearpose.geometry import geodesic_angle
from wearpose.motion.resample import resample
from wearpose.sensors import (
    EMOffsets, KitError, NoiseConfig, SensorKit, SensorSpec, angular_velocity, get_kit, integrate_gyro, list_kits,
    random_subject_offsets, simulate,
    synthetic_acceleration,
)

D = torch.float64


def _sim(*a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # site substitutions of custom kits (none in the built-in kits)
        return simulate(*a, **k)


def test_noise_free_em_is_source_relative_site_pose(body_all_sites):
    m = smooth_motion(T=120, fps=120.0)
    res = _sim(m, "em6", body_all_sites, noise="none")
    so = body_all_sites.sites(m.pose, m.betas, m.trans, ["back_upper", "head", "right_wrist", "pelvis"])
    Rs, ps = so.rotations[:, 3], so.positions[:, 3]
    head = res["head"]
    assert head.frame == "source" and head.num_frames == 120 and head.valid.all()
    assert torch.allclose(head.position, torch.einsum("tji,tj->ti", Rs, so.positions[:, 1] - ps), atol=1e-10)
    assert torch.allclose(head.orientation, Rs.transpose(-1, -2) @ so.rotations[:, 1], atol=1e-10)
    assert torch.allclose(res.em_source[120.0]["position"], ps)
    assert torch.allclose(res["right_lower_arm"].extras["world_position"], so.positions[:, 2])
    assert torch.allclose(head.timestamps, torch.arange(120, dtype=D) / 120)


def test_noise_free_imu_and_resampling(body_all_sites):
    m = smooth_motion(T=241, fps=120.0)
    res = _sim(m, "imu6", body_all_sites, noise="none")
    m60 = resample(m, 60.0)
    s = res["left_forearm"]
    assert s.num_frames == m60.num_frames == 121 and s.rate == 60.0
    so = body_all_sites.sites(m60.pose, m60.betas, m60.trans, ["left_forearm"])
    a, _ = synthetic_acceleration(so.positions[:, 0], 60.0, smooth_n=4)
    assert torch.allclose(s.acceleration, a, atol=1e-8)
    assert torch.allclose(s.orientation, so.rotations[:, 0], atol=1e-12)
    assert torch.allclose(s.angular_velocity, angular_velocity(so.rotations[:, 0], 60.0))
    # rate override
    r30 = _sim(m, "imu6", body_all_sites, noise="none", rate=30)
    assert r30.kit.rates == (30.0,) and r30["head"].num_frames == resample(m, 30.0).num_frames


def test_acceptance_gyro_integration_on_a_body_site_10s(body_all_sites):
    m = smooth_motion(T=601, fps=60.0, amp=0.8)
    res = _sim(m, "imu6", body_all_sites, noise="none")
    for name in ("left_forearm", "right_lower_leg", "head"):
        s = res[name]
        Ri = integrate_gyro(s.angular_velocity, s.orientation[0], 60.0)
        assert math.degrees(geodesic_angle(Ri, s.orientation).max().item()) < 1.0


def test_all_kits_run_with_default_noise_and_are_seeded(body_all_sites):
    m = smooth_motion(T=40, fps=60.0)
    for k in list_kits():
        a = _sim(m, k, body_all_sites, seed=3)
        b = _sim(m, k, body_all_sites, seed=3)
        c = _sim(m, k, body_all_sites, seed=4)
        assert list(a.sensors) == list(get_kit(k).sensor_names)
        for n, s in a.sensors.items():
            for f in ("position", "orientation", "acceleration", "angular_velocity", "magnetic_field"):
                x, y = getattr(s, f), getattr(b[n], f)
                assert (x is None) == (y is None)
                if x is not None:
                    assert torch.equal(torch.nan_to_num(x), torch.nan_to_num(y)), (k, n, f)
        some = next(iter(a.sensors))
        assert not torch.equal(torch.nan_to_num(a[some].orientation), torch.nan_to_num(c[some].orientation))
    mi = _sim(m, "miposer", body_all_sites, seed=1)
    assert mi["head_vio"].rate == 60.0 and mi["left_wrist_em"].rate == 120.0 and mi["left_wrist_imu"].rate == 120.0
    assert mi["left_wrist_em"].num_frames == 2 * mi["head_vio"].num_frames - 1
    # a sensor's noise does not depend on the other sensors of the kit
    mi1 = _sim(m, "miposer1", body_all_sites, seed=1)
    assert torch.equal(torch.nan_to_num(mi["left_wrist_em"].position), torch.nan_to_num(mi1["left_wrist_em"].position))


def test_offsets_options_and_errors(body_all_sites, body_tiny):
    m = smooth_motion(T=60, fps=120.0)
    r = _sim(m, "em6", body_all_sites, noise="none", offsets="random", seed=2)
    assert r.em_offsets.num_sensors == 6 and r.em_offsets.t.abs().max() > 0
    known = EMOffsets.identity(6)
    known.t[:, 2] = 0.02  # 2 cm along the normal
    r2 = _sim(m, "em6", body_all_sites, noise="none", offsets=known)
    r0 = _sim(m, "em6", body_all_sites, noise="none")
    so = body_all_sites.sites(m.pose, m.betas, m.trans, ["head"])
    n = so.rotations[:, 0, :, 2]
    assert torch.allclose(r2["head"].extras["world_position"] - r0["head"].extras["world_position"], 0.02 * n, atol=1e-12)
    with pytest.raises(Exception, match="EM offsets"):
        _sim(m, "em6", body_all_sites, offsets=EMOffsets.identity(5))
    with pytest.raises(KitError, match="tiny-test"):
        simulate(m, "imu6", body_tiny)
    with pytest.raises(KitError, match="available kits"):
        simulate(m, "nope", body_all_sites)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # em12 has its own shoulder sites now: no substitution
        r12 = simulate(m, "em12", body_all_sites, noise="none")
    assert r12.site_substitutions == {} and r12["left_shoulder"].site == "left_shoulder"
    # a custom kit on the tiny conftest asset (sites head, left_forearm)
    kit = SensorKit("tiny", (SensorSpec("arm", "em6dof", "left_forearm", 60.0), SensorSpec("h", "imu", "head", 60.0)), "head")
    rt = simulate(m, kit, body_tiny, noise=NoiseConfig.none())
    assert rt["arm"].num_frames == resample(m, 60.0).num_frames


ASSET = Path(__file__).resolve().parents[2] / "src/wearpose/body/assets/wearpose_anny_v1.npz"


@pytest.mark.skipif(not ASSET.exists(), reason="embedded body asset not built yet")
def test_every_kit_on_the_embedded_asset():
    body = BodyModel()
    m = smooth_motion(T=60, fps=60.0, dtype=torch.float32)
    for k in list_kits():
        r = _sim(m, k, body, seed=0)
        for s in r.sensors.values():
            assert s.valid.shape == s.timestamps.shape
            if s.kind == "em6dof":
                d = s.extras["distance"]
                assert (d > 0.05).all() and (d < 2.0).all()  # within EM range of the source


def test_segment_orientation_mode(body_all_sites):
    m = smooth_motion(T=60, fps=60.0)
    site = _sim(m, "imu6", body_all_sites, noise="none")
    seg = _sim(m, "imu6", body_all_sites, noise="none", imu_orientation="segment")
    so = body_all_sites.sites(m.pose, m.betas, m.trans, ["left_forearm"])
    # TransPose ji_mask: the left forearm IMU takes the left elbow's global rotation (joint 18)
    assert torch.allclose(seg["left_forearm"].orientation, so.global_rot[:, 18])
    assert torch.allclose(site["left_forearm"].extras["segment_orientation"], so.global_rot[:, 18])
    assert torch.allclose(seg["left_forearm"].acceleration, site["left_forearm"].acceleration)  # same vertex
    with pytest.raises(Exception, match="imu_orientation"):
        _sim(m, "imu6", body_all_sites, imu_orientation="bone")


def test_mimu_fusion_through_simulate(body_all_sites):
    pytest.importorskip("ahrs")
    m = smooth_motion(T=60, fps=60.0)
    r = _sim(m, "mimu6", body_all_sites, noise="none", mimu_fusion="madgwick")
    truth = _sim(m, "mimu6", body_all_sites, noise="none")
    err = geodesic_angle(r["head"].orientation, truth["head"].orientation).max().item()
    assert 0 < math.degrees(err) < 5


def test_participant_pool_and_rate_scaled_smoothing(body_all_sites):
    m = smooth_motion(T=61, fps=120.0)
    pool = [EMOffsets.identity(6), random_subject_offsets(6, torch.Generator().manual_seed(1))]
    picks = {_sim(m, "em6", body_all_sites, noise="none", offsets=pool, seed=s).meta["offsets_index"] for s in range(8)}
    assert picks == {0, 1}
    # at 120 Hz the default stencil is 8 frames (TransPose's 1/15 s window)
    r = _sim(m, "imu6", body_all_sites, noise="none", rate=120)
    so = body_all_sites.sites(m.pose, m.betas, m.trans, ["head"])
    a8, _ = synthetic_acceleration(so.positions[:, 0], 120.0, smooth_n=8)
    assert torch.allclose(r["head"].acceleration, a8, atol=1e-8)
