"""The one input path (``wearpose.estimators.inputs``): checks, canonical conversion, grids, hold;
errors name the recording, the sensor, the field and the expected form."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.errors import ShapeError
from wearpose.estimators.inputs import InputSpec, canonical_input, hold_last_valid, on_first_grid, prepare
from wearpose.recording import Recording

#: Every non-canonical convention the recording format declares (docs/formats.md).
DECLARED = dict(position_unit="mm", gyro_unit="deg/s", acc_unit="g", acc_frame="sensor", acc_gravity="included",
                world_up="z_up")


@pytest.fixture(scope="module")
def imu_rec() -> Recording:
    from wearpose.body import BodyModel
    from wearpose.sensors import simulate

    m = smooth_motion(T=40, fps=60.0, seed=1, dtype=torch.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, "imu6", BodyModel(), seed=2, noise="none", rate=60.0)
    rec = Recording.from_simulation(res, m)
    for s in rec.sensors[:2]:  # two dropped stretches: held, never invented
        s.valid[5:9] = False
        for c in s.channels().values():
            c[5:9] = np.nan
    return rec


def _spec(**kw) -> InputSpec:
    return InputSpec.from_kit("PIP", "imu6", ("orientation", "acceleration"), **kw)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_hold_last_valid_keeps_the_last_valid_sample(dtype) -> None:
    T, S = 6, 3
    p = torch.arange(T * S * 3, dtype=dtype).reshape(T, S, 3)
    R = torch.linalg.matrix_exp(torch.randn(T, S, 3, 3, dtype=dtype).triu(1) - torch.randn(T, S, 3, 3, dtype=dtype).triu(1).mT)
    valid = torch.ones(T, S, dtype=torch.bool)
    valid[0, 0] = valid[2:4, 0] = False
    valid[:, 1] = False
    hp, hR = hold_last_valid(p, valid), hold_last_valid(R, valid)
    assert torch.equal(hp[0, 0], p[1, 0]) and torch.equal(hp[2, 0], p[1, 0]) and torch.equal(hp[3, 0], p[1, 0])
    assert torch.equal(hp[4, 0], p[4, 0]) and torch.equal(hR[3, 0], R[1, 0]) and torch.equal(hp[:, 2], p[:, 2])
    # a sensor never valid: zeros and identity rotations, not NaN
    assert torch.equal(hp[:, 1], torch.zeros(T, 3, dtype=dtype))
    assert torch.equal(hR[:, 1], torch.eye(3, dtype=dtype).expand(T, 3, 3))
    assert hp.dtype == hR.dtype == dtype


def test_prepare_of_a_declared_copy_equals_the_canonical(imu_rec: Recording) -> None:
    a = prepare(imu_rec, _spec())
    b = prepare(imu_rec.declared_as(**DECLARED), _spec())
    assert a.names == b.names == tuple(_spec().sensor_names)
    assert torch.equal(a.valid, b.valid) and not bool(a.valid[5:9, :2].any())
    for c in ("orientation", "acceleration"):
        assert a.channels[c].shape[:2] == (40, 6) and torch.isfinite(a.channels[c]).all()
        torch.testing.assert_close(b.channels[c], a.channels[c], atol=2e-5, rtol=0)
    # dropped samples held at the last valid one
    assert torch.equal(a.channels["acceleration"][5:9, 0], a.channels["acceleration"][4, 0].expand(4, 3))
    nan = prepare(imu_rec, _spec(), hold=False).channels["acceleration"]
    assert torch.isnan(nan[5:9, :2]).all() and torch.isfinite(nan[:5]).all()
    assert canonical_input(imu_rec, _spec()) is imu_rec  # canonical already: no copy


@pytest.mark.parametrize("change, match", [
    (lambda r: r.select(r.names[1:]), r"a recording not loaded from a file \(made in memory\): no sensors "
                                      r"\['left_forearm'\] \(it has \['right_forearm',"),
    (lambda r: r.select(r.names), None),
])
def test_missing_sensors_list_what_is_read_and_what_is_there(imu_rec: Recording, change, match) -> None:
    rec = change(imu_rec)
    if match is None:
        canonical_input(rec, _spec())
        return
    with pytest.raises(ShapeError, match=match) as ei:
        canonical_input(rec, _spec())
    assert "Expected: PIP reads sensors ['left_forearm', 'right_forearm'," in str(ei.value)


def test_kind_channel_rate_and_reference_are_checked(imu_rec: Recording) -> None:
    with pytest.raises(ShapeError, match=r"sensor 'left_forearm' has no \['magnetic_field'\] channel. Expected: "
                                         r"channels \['orientation', 'magnetic_field'\] for every sensor PIP reads"):
        canonical_input(imu_rec, InputSpec.from_kit("PIP", "imu6", ("orientation", "magnetic_field")))
    with pytest.raises(ShapeError, match=r"sensor 'left_forearm' \[rate\] is 60 Hz. Expected: 30 Hz, the rate PIP"):
        canonical_input(imu_rec, _spec(rates={"imu": 30.0}))
    with pytest.raises(ShapeError, match="sensor 'head' \\[kind\\] is 'imu'. Expected: kind 'em6dof' \\(EM-POSE"):
        canonical_input(imu_rec, InputSpec.from_kit("EM-POSE", "em12", ("orientation",), sensor_names=("head",)))
    with pytest.raises(ShapeError, match="reads sensor 'nope', which kit 'imu6' does not have"):
        _spec(sensor_names=("nope",)).kit_kind("nope")


def test_online_frames_of_a_declared_copy_equal_the_canonical(imu_rec: Recording) -> None:
    from wearpose.estimators import iter_frames

    names = list(imu_rec.names)
    for fa, fb in zip(iter_frames(imu_rec, names), iter_frames(imu_rec.declared_as(**DECLARED), names)):
        assert fa.timestamp == fb.timestamp and np.array_equal(fa.valid, fb.valid)
        for c in ("orientation", "acceleration", "angular_velocity"):
            np.testing.assert_allclose(fb.channels[c], fa.channels[c], atol=2e-5, equal_nan=True)


def test_errors_name_the_file_a_recording_was_loaded_from(imu_rec: Recording, tmp_path) -> None:
    """A loaded recording (and every copy made of it: canonical, resampled, selected) is named by
    its path in input errors; one made in memory says so."""
    from wearpose.recording import load_recording, save_recording

    path = tmp_path / "walk.npz"
    save_recording(imu_rec.declared_as(position_unit="cm"), path)
    rec = load_recording(path)
    assert rec.origin == str(path) and rec.to_canonical().origin == str(path)
    assert rec.select(rec.names).origin == str(path)
    with pytest.raises(ShapeError, match=rf"^recording {path}: sensor 'left_forearm' \[rate\] is 60 Hz"):
        prepare(rec, _spec(rates={"imu": 30.0}))
    with pytest.raises(ShapeError, match=rf"^recording {path}: no sensors \['left_forearm'\]"):
        prepare(rec.select(rec.names[1:]), _spec())


def test_first_sensor_grid_takes_samples_at_its_instants() -> None:
    """align="first": a 120 Hz sensor is read at a 60 Hz sensor's instants (every other sample,
    exactly); an instant without a sample within the tolerance is masked, nothing interpolated."""
    from wearpose.recording import SensorInfo, SensorStream

    t60, t120 = np.arange(10) / 60.0, np.arange(20) / 120.0
    t120[6] += 0.004  # the sample for instant 3 is 4 ms late: not used
    head = SensorStream(SensorInfo("head", "vio", rate=60.0), t60, np.ones(10, bool),
                        position=np.zeros((10, 3), np.float32), orientation=np.tile(np.eye(3, dtype=np.float32), (10, 1, 1)))
    pos = np.arange(60, dtype=np.float32).reshape(20, 3)
    wrist = SensorStream(SensorInfo("wrist", "em6dof", rate=120.0), t120, np.ones(20, bool), position=pos,
                         orientation=np.tile(np.eye(3, dtype=np.float32), (20, 1, 1)))
    rec = Recording([head, wrist])
    spec = InputSpec("MI-Poser", None, ("head", "wrist"), ("position",), kinds={"any": ("vio", "em6dof")}, align="first")
    with pytest.raises(Exception, match="do not share"):
        prepare(rec, InputSpec("MI-Poser", None, ("head", "wrist"), ("position",), kinds={"any": ("vio", "em6dof")}))
    x = prepare(rec, spec, hold=False)
    assert x.valid[:, 1].tolist() == [True] * 3 + [False] + [True] * 6
    assert torch.equal(x.channels["position"][[0, 1, 2, 4], 1], torch.as_tensor(pos[[0, 2, 4, 8]]))
    assert torch.isnan(x.channels["position"][3, 1]).all() and x.recording.sensor("wrist").num_frames == 20
    assert on_first_grid(rec, ("head", "wrist")).meta["grid"]["masked_by_grid"] == {"wrist": 1}
