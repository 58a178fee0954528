"""The online input every estimator's step shares (wearpose.estimators.inputs.OnlineInput):
the same tensors as the three former per-method copies (EM-POSE's frame_measurements, PIP's and
BiRAE's step), frame by frame, with drops, NaNs and sensors in another order; the sensor map is
built once per stream, not per frame."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.errors import ShapeError
from wearpose.estimators.base import SensorFrame
from wearpose.estimators.inputs import OnlineInput

NAMES = ("a", "b", "c", "d")


def _frames(n: int, seed: int) -> list[SensorFrame]:
    rng = np.random.default_rng(seed)
    out = []
    for t in range(n):
        valid = rng.random(4) > 0.4
        R = np.linalg.qr(rng.normal(size=(4, 3, 3)))[0]
        ch = {"position": rng.normal(size=(4, 3)), "acceleration": rng.normal(size=(4, 3)), "orientation": R}
        for k in ch:
            ch[k][~valid] = np.nan
        out.append(SensorFrame(t / 60, ("d", "b", "a", "x", "c"), np.r_[valid[[3, 1, 0]], True, valid[2]],
                               {k: np.concatenate([v[[3, 1, 0]], v[:1], v[2:3]]) for k, v in ch.items()}))
    return out


def _old(frame: SensorFrame, channels: tuple[str, ...], last, nan: tuple[str, ...]):
    """The former copies' arithmetic (commit 578713e)."""
    names = list(frame.names)
    idx = [names.index(n) for n in NAMES]
    v = torch.as_tensor(np.asarray(frame.valid)[idx], dtype=torch.bool)
    xs = []
    for c in channels:
        a = np.asarray(frame.channels[c])[idx]
        xs.append(torch.as_tensor(np.nan_to_num(a) if c in nan else a, dtype=torch.float32))
    holds = last if last is not None else tuple(torch.eye(3).expand_as(x) if c == "orientation" else torch.zeros_like(x)
                                                for c, x in zip(channels, xs))
    return tuple(torch.where(v[:, None, None] if c == "orientation" else v[:, None], x, h)
                 for c, x, h in zip(channels, xs, holds)), v


@pytest.mark.parametrize("channels,nan", [(("position", "orientation"), ()),  # EM-POSE, MI-Poser
                                          (("acceleration", "orientation"), ("acceleration",)),  # PIP
                                          (("orientation",), ("orientation",))])  # BiRAE
def test_online_input_equals_the_former_copies(channels, nan) -> None:
    last_old = None
    held = 0
    online = OnlineInput(NAMES, channels, nan_to_zero=nan)
    for f in _frames(40, 7):
        new, v = online(f)
        old, v_old = _old(f, channels, last_old, nan)
        assert torch.equal(v, v_old)
        for x, y in zip(new, old):
            assert x.dtype == torch.float32 and torch.equal(torch.nan_to_num(x, 9.0), torch.nan_to_num(y, 9.0))
            assert not torch.isnan(x).any()  # every dropped sample held or neutral
        held += int((~v).sum())
        last_old = old
    assert held > 20  # the drops were exercised


def test_online_input_neutral_before_any_sample_and_error() -> None:
    f = SensorFrame(0.0, NAMES, np.zeros(4, bool), {"position": np.full((4, 3), np.nan),
                                                   "orientation": np.full((4, 3, 3), np.nan)})
    (p, R), v = OnlineInput(NAMES, ("position", "orientation"))(f)
    assert not v.any() and torch.equal(p, torch.zeros(4, 3)) and torch.equal(R, torch.eye(3).expand(4, 3, 3))
    with pytest.raises(ShapeError, match=r"live frame: no sensors \['c', 'd'\] \(it has \['a', 'b'\]\). "
                                         r"Expected: PIP reads sensors \['a', 'b', 'c', 'd'\]"):
        OnlineInput(NAMES, ("position",), who="PIP")(SensorFrame(0.0, ("a", "b"), np.ones(2, bool), {}))


def test_sensor_map_built_once_per_stream(monkeypatch) -> None:
    """The frame -> estimator column map is built on the first frame and kept while the frame's
    sensor names stay the same (one build for 40 frames); new names rebuild it."""
    frames = _frames(40, 3)
    online = OnlineInput(NAMES, ("position",))
    builds = []
    real = OnlineInput.index

    def counting(self, names):
        before = self._idx
        out = real(self, names)
        builds.append(out is not before)
        return out

    monkeypatch.setattr(OnlineInput, "index", counting)
    for f in frames:
        online(f)
    assert sum(builds) == 1 and len(builds) == 40
    reordered = SensorFrame(1.0, NAMES, np.ones(4, bool), {"position": np.arange(12.0).reshape(4, 3)})
    (p,), _ = online(reordered)
    assert sum(builds) == 2 and torch.equal(p, torch.arange(12.0).reshape(4, 3))
