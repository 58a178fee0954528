"""stance_foot_speed on synthetic gaits with a known planted-foot slide."""

from __future__ import annotations

import math

import pytest
import torch

from wearpose.evaluate import stance_foot_speed

FPS = 60.0


def gait(slide: float, steps: int = 6, period: float = 1.0) -> torch.Tensor:
    """Two feet alternating: each foot is planted half the period (sliding at ``slide`` m/s along
    +z) and swings the other half (lifted 10 cm on a sine, moving 2.5 m/s). ``(T, 2, 3)`` m."""
    T = int(steps * period * FPS)
    t = torch.arange(T, dtype=torch.float64) / FPS
    feet = torch.zeros(T, 2, 3, dtype=torch.float64)
    for f in range(2):
        z, phase = 0.0, (t / period + 0.5 * f) % 1.0
        for i in range(T):
            if i:
                z += (slide if phase[i] < 0.5 else 2.5) / FPS
            feet[i, f, 2] = z
            feet[i, f, 1] = 0.0 if phase[i] < 0.5 else 0.10 * math.sin(math.pi * (phase[i] - 0.5) / 0.5)
        feet[:, f, 0] = 0.1 * (1 - 2 * f)
    return feet


@pytest.mark.parametrize("slide", [0.0, 0.05, 0.2])
def test_measures_the_planted_foot_slide(slide: float) -> None:
    r = stance_foot_speed(gait(slide), FPS)
    assert r.stances >= 10
    assert r.median == pytest.approx(slide, abs=1e-6)
    # over a whole stance (0.5 s) the foot moves slide * 0.5 s
    assert float(r.stance_travel.median()) == pytest.approx(slide * 0.5, abs=slide * 0.1 + 1e-6)


def test_no_stance_and_bad_input() -> None:
    flying = gait(0.0) + torch.tensor([0.0, 0.0, 0.0])
    flying[:, :, 1] = torch.linspace(0, 3, flying.shape[0], dtype=torch.float64)[:, None]  # always rising
    r = stance_foot_speed(flying, FPS)
    assert r.stances == 0 and math.isnan(r.median)
    with pytest.raises(Exception, match="feet"):
        stance_foot_speed(torch.zeros(10, 3), FPS)
    with pytest.raises(Exception, match="fps"):
        stance_foot_speed(torch.zeros(10, 2, 3), 0.0)
