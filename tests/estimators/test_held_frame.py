"""The online hold-last-valid every estimator's step shares (wearpose.estimators.inputs.held_frame):
the same tensors as the three former per-method copies (EM-POSE's frame_measurements, PIP's and
BiRAE's step), frame by frame, with drops, NaNs and sensors in another order."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from wearpose.errors import ShapeError
from wearpose.estimators.base import SensorFrame
from wearpose.estimators.inputs import held_frame

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
def test_held_frame_equals_the_former_copies(channels, nan) -> None:
    last_new = last_old = None
    held = 0
    for f in _frames(40, 7):
        new, v = held_frame(f, NAMES, channels, last_new, nan_to_zero=nan)
        old, v_old = _old(f, channels, last_old, nan)
        assert torch.equal(v, v_old)
        for x, y in zip(new, old):
            assert x.dtype == torch.float32 and torch.equal(torch.nan_to_num(x, 9.0), torch.nan_to_num(y, 9.0))
            assert not torch.isnan(x).any()  # every dropped sample held or neutral
        held += int((~v).sum())
        last_new, last_old = new, old
    assert held > 20  # the drops were exercised


def test_held_frame_neutral_before_any_sample_and_error() -> None:
    f = SensorFrame(0.0, NAMES, np.zeros(4, bool), {"position": np.full((4, 3), np.nan),
                                                   "orientation": np.full((4, 3, 3), np.nan)})
    (p, R), v = held_frame(f, NAMES, ("position", "orientation"), None)
    assert not v.any() and torch.equal(p, torch.zeros(4, 3)) and torch.equal(R, torch.eye(3).expand(4, 3, 3))
    with pytest.raises(ShapeError, match=r"frame has sensors \['a', 'b'\]; PIP needs \['a', 'b', 'c', 'd'\]"):
        held_frame(SensorFrame(0.0, ("a", "b"), np.ones(2, bool), {}), NAMES, ("position",), None, who="PIP")
