"""Figures: uncertainty bands (the paper's Figs. 7-10) and the reliability diagram (matplotlib, Agg)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import torch

from wearpose.viewer.figures import pyplot, save_figure


def uncertainty_bands(path: str | Path, fps: float, mean: torch.Tensor, sigma: torch.Tensor, truth: torch.Tensor,
                      joints: Sequence[tuple[str, int]], title: str = "") -> Path:
    """One panel per joint: its three exp-map components (deg) over time, ground truth, mean and +-1 sigma.

    Args:
        mean, sigma, truth: ``(T, 15, 3)`` radians (major-joint order).
        joints: ``(label, position in the 15 major joints)`` per panel.
    """
    plt = pyplot()
    T = mean.shape[0]
    t = torch.arange(T) / fps
    k = 180.0 / math.pi
    fig, axes = plt.subplots(len(joints), 3, figsize=(12, 2.3 * len(joints)), sharex=True, squeeze=False)
    for r, (label, j) in enumerate(joints):
        for c, comp in enumerate("xyz"):
            ax = axes[r][c]
            m, s, y = mean[:, j, c] * k, sigma[:, j, c] * k, truth[:, j, c] * k
            ax.fill_between(t, m - s, m + s, color="tab:blue", alpha=0.25, lw=0, label="+-1 sigma")
            ax.plot(t, m, color="tab:blue", lw=1.2, label="estimate")
            ax.plot(t, y, color="k", lw=1.0, ls="--", label="ground truth")
            ax.set_title(f"{label} exp-map {comp}", fontsize=9)
            ax.tick_params(labelsize=8)
            if c == 0:
                ax.set_ylabel("deg", fontsize=8)
    axes[-1][1].set_xlabel("time (s)")
    axes[0][0].legend(fontsize=7, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def reliability_diagram(path: str | Path, curves: dict[str, dict[str, list[float]]], title: str = "") -> Path:
    """Observed vs expected coverage of Gaussian central intervals, one line per curve."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.8, 4.6))
    ax.plot([0, 1], [0, 1], color="0.6", ls="--", lw=1, label="perfect calibration")
    for name, c in curves.items():
        ax.plot(c["expected"], c["observed"], marker="o", ms=3, lw=1.3, label=name)
    ax.set_xlabel("expected fraction inside interval")
    ax.set_ylabel("observed fraction (test)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize=7, loc="upper left")
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, path, dpi=110)
