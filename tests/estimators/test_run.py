"""wearpose.estimators.run: one path from a --model to a pose (checkpoint read once, rate fitted,
the recording's T-pose mark used, the estimate placed in the world)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wearpose.errors import ConfigError, InputFileError
from wearpose.estimators.run import ModelSource, open_model, use_calibration_window


class _Rec:
    def __init__(self, meta):
        self.meta = meta


def test_use_calibration_window_only_touches_estimators_that_calibrate() -> None:
    from wearpose.recording import CALIBRATION_WINDOW_KEY

    class Est:
        calibration_window = (0.0, 1.0)

    rec = _Rec({CALIBRATION_WINDOW_KEY: {"pose": "tpose", "start_s": 0.1, "stop_s": 0.4}})
    est = Est()
    assert use_calibration_window(est, rec) == (0.1, 0.4) and est.calibration_window == (0.1, 0.4)
    other = object()  # an EM estimator: nothing to calibrate from a pose
    assert use_calibration_window(other, rec) is None
    assert use_calibration_window(Est(), _Rec({})) is None

    class NoDefault:  # MI-Poser, segments: no window of their own until a recording marks one
        calibration_window = None

    est = NoDefault()
    assert use_calibration_window(est, rec) == (0.1, 0.4) and est.calibration_window == (0.1, 0.4)


def test_open_model_reads_the_card_and_checkpoint_alike() -> None:
    """Shipped weights and the same file given as a path resolve to the same setting; the card
    says what the checkpoint says (kit, sensors, method, trained rate), for every pose weight."""
    from wearpose.cli.models import pose_weights
    from wearpose.weights import card, weight_path

    for name in pose_weights():
        a, b = open_model(name), open_model(weight_path(name))
        assert (a.method, a.kit, a.sensors, a.fps) == (b.method, b.kit, b.sensors, b.fps), name
        c = card(name)
        assert (c["method"], c["kit"], tuple(c["sensors"])) == (a.method, a.kit, a.sensors), name
        assert c.get("config", {}).get("rate") == a.fps, name


def test_open_model_names_what_it_accepts(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"neither shipped weights .*empose12_cpu.*weight-free estimator \(.*segments"):
        open_model("no_such_model")
    with pytest.raises(InputFileError, match="no such checkpoint file"):
        open_model(tmp_path / "missing.pt")
    seg = open_model("segments")
    assert seg.checkpoint is None and seg.fps is None and seg.make().name == "segments"


@pytest.fixture
def torch_loads(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The files ``torch.load`` reads during the test, in order."""
    calls: list[str] = []
    real = torch.load

    def counting(f, *a, **k):
        calls.append(str(f))
        return real(f, *a, **k)

    monkeypatch.setattr(torch, "load", counting)
    return calls


def test_make_builds_fresh_estimators_from_one_read(torch_loads: list[str]) -> None:
    """The checkpoint is read by open_model and never again, however many estimators are made
    (the server makes one per subject)."""
    src = open_model("empose12_cpu")
    e1, e2 = src.make(), src.factory()
    assert len(torch_loads) == 1 and e1 is not e2
    assert e1.sensor_names == e2.sensor_names == src.sensors
    assert isinstance(src, ModelSource)


@pytest.mark.parametrize("as_path", [False, True])
def test_wearpose_estimate_reads_its_checkpoint_once(as_path: bool, tmp_path: Path, torch_loads: list[str]) -> None:
    from typer.testing import CliRunner

    from tests.sensors.sensor_testutils import smooth_motion
    from wearpose.cli.app import app
    from wearpose.evaluate.conventions import kit_recording
    from wearpose.recording import save_recording
    from wearpose.weights import weight_path

    rec = kit_recording("em12", smooth_motion(T=60, fps=30.0, seed=1, dtype=torch.float32), 30.0)
    save_recording(rec, tmp_path / "rec.npz")
    model = str(weight_path("empose12_cpu")) if as_path else "empose12_cpu"
    torch_loads.clear()  # only what the command reads
    res = CliRunner().invoke(app, ["estimate", str(tmp_path / "rec.npz"), "--model", model,
                                   "--out", str(tmp_path / "pose.npz"), "--json"])
    assert res.exit_code == 0, res.output
    assert [c for c in torch_loads if c.endswith(".pt")] == [str(weight_path("empose12_cpu"))], torch_loads


def _hopping_track(fps: float = 30.0, ground: int = 9, flight: int = 21, hops: int = 3,
                   forward_m_s: float = 0.0, leap_m_s: float = 2.0):
    """A body bounding forward like a runner: ``ground`` frames still on its floor (lowest point
    at 0.4 m above y = 0 before placement), then ``flight`` frames of a 20 cm parabola travelling
    ``leap_m_s`` forward, ``hops`` times; the whole body also gliding at ``forward_m_s``."""
    from wearpose.body import BodyModel
    from wearpose.estimators.base import PoseTrack

    body = BodyModel(dtype=torch.float64)
    rest = torch.eye(3, dtype=torch.float64).expand(1, 24, 3, 3)
    up = -float(body.lowest_height(rest, None, None)[0]) + 0.4  # root height that puts the feet at 0.4 m
    s = torch.arange(flight, dtype=torch.float64).add(1) / (flight + 1)
    cycle = torch.cat([torch.zeros(ground, dtype=torch.float64), 0.8 * s * (1 - s)])  # peak 0.2 m
    y = cycle.repeat(hops) + up
    T = y.shape[0]
    trans = torch.zeros(T, 3, dtype=torch.float64)
    trans[:, 1] = y
    speed = torch.where(cycle.repeat(hops) == 0, 0.0, leap_m_s) + forward_m_s  # m/s, per frame
    trans[:, 2] = torch.cumsum(speed, 0) / fps
    track = PoseTrack(torch.eye(3, dtype=torch.float64).expand(T, 24, 3, 3).clone(), torch.zeros(10, dtype=torch.float64),
                      trans, torch.ones(T, dtype=torch.bool), fps)
    return track, body, (cycle.repeat(hops) == 0)


def test_on_the_floor_puts_the_contact_frames_on_it_not_the_flight() -> None:
    """A bounding run is in the air for 70 % of its frames: the median over all frames would put
    the flight on the floor and the stance 9 cm under it; the contact frames' median puts the
    stance feet at 0 (to float precision) and keeps the leaps' heights. The frame before each
    take-off and after each landing is not: its central difference spans a flight frame."""
    from wearpose.estimators.run import contact_frames, on_the_floor

    track, body, ground = _hopping_track()
    low = body.lowest_point(track.local_rot, track.betas, track.trans)
    contact = contact_frames(low, track.fps)
    assert float(contact[ground].float().mean()) > 0.7 and not bool(contact[~ground].any()), contact
    placed = on_the_floor(track, body)
    after = body.lowest_height(placed.local_rot, placed.betas, placed.trans)
    assert float(after[ground].abs().max()) < 1e-9, after[ground]
    assert float(after.max()) == pytest.approx(0.2, abs=0.01)  # the hops stay hops
    assert placed.extras["floor"] == "median lowest point of the contact frames on y = 0"
    # the rule it replaces: the median over all frames sinks the stance (what runs showed)
    assert float((low.height[ground] - low.height.median()).max()) < -0.09


def test_on_the_floor_without_contact_takes_every_frame_and_says_so() -> None:
    """A body gliding at 1 m/s never has a joint at rest: the median over every frame, named."""
    from wearpose.estimators.run import contact_frames, on_the_floor

    track, body, _ = _hopping_track(forward_m_s=1.0)
    low = body.lowest_point(track.local_rot, track.betas, track.trans)
    assert not bool(contact_frames(low, track.fps).any())
    placed = on_the_floor(track, body)
    after = body.lowest_height(placed.local_rot, placed.betas, placed.trans)
    assert float(after.median().abs()) < 1e-9
    assert placed.extras["floor"] == "median lowest point on y = 0 (too few contact frames)"
