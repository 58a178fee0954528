"""The BiRAE network (Sec. IV-A, Fig. 2) and its loss (Eq. 6).

``x (B, T, D)`` -> FC ``width`` + ReLU + dropout -> ``layers`` stacked Bi-LSTM of ``hidden``
per direction -> two independent linear heads: the mean pose ``mu`` and the log-variance
``log sigma^2`` of the 15 major joints' exponential maps ``(B, T, 45)`` (radians, radians^2).
The ``3param_rate`` variant adds a third linear head reconstructing the angular-rate input
(the auxiliary task of Sec. IV-D).

Dropout sits after the input FC only (the paper's "FC ... with a drop-out of 0.2"); MC-dropout
(Eq. 7) re-enables exactly that layer at inference (:meth:`BiRAE.forward` ``mc=True``).
Variable-length batches go through :func:`torch.nn.utils.rnn.pack_padded_sequence`, so the
backward direction of a short clip starts at its own last frame, never on padding.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence, pad_packed_sequence

from wearpose.estimators.birae.config import BiraeConfig
from wearpose.estimators.birae.representations import OUT_DIM, input_dim


class BiRAE(nn.Module):
    """Bidirectional recurrent autoencoder with mean / log-variance heads."""

    def __init__(self, cfg: BiraeConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.inp = nn.Linear(input_dim(cfg.rep), cfg.width)
        self.drop = nn.Dropout(cfg.dropout)
        self.lstm = nn.LSTM(cfg.width, cfg.hidden, num_layers=cfg.layers, batch_first=True, bidirectional=True)
        self.mu = nn.Linear(2 * cfg.hidden, OUT_DIM)
        self.logvar = nn.Linear(2 * cfg.hidden, OUT_DIM)
        self.aux = nn.Linear(2 * cfg.hidden, 15) if cfg.uses_rate else None

    def forward(self, x: torch.Tensor, lengths: torch.Tensor | None = None, mc: bool = False,
                generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """Run the network.

        Args:
            x: ``(B, T, D)`` input features.
            lengths: ``(B,)`` valid frames per row (``None``: all ``T``).
            mc: keep dropout active (MC-dropout) even in eval mode, with masks drawn from
                ``generator`` (reproducible).

        Returns:
            ``mu`` ``(B, T, 45)`` rad, ``logvar`` ``(B, T, 45)`` (clamped to the config's range),
            and ``aux`` ``(B, T, 15)`` (scaled angular rate) for ``3param_rate``.
        """
        h = torch.relu(self.inp(x))
        p = self.cfg.dropout
        if mc and not self.training and p > 0:
            keep = torch.full_like(h, 1.0 - p)
            h = h * torch.bernoulli(keep, generator=generator) / (1.0 - p)
        else:
            h = nn.functional.dropout(h, p, training=self.training)
        B, T = x.shape[:2]
        if lengths is not None and bool((lengths < T).any()):
            packed = pack_padded_sequence(h, lengths.cpu(), batch_first=True, enforce_sorted=False)
            out, _ = self.lstm(packed)
            out, _ = pad_packed_sequence(out, batch_first=True, total_length=T)
        else:
            out, _ = self.lstm(h)
        res = {"mu": self.mu(out),
               "logvar": self.logvar(out).clamp(self.cfg.logvar_min, self.cfg.logvar_max)}
        if self.aux is not None:
            res["aux"] = self.aux(out)
        return res


def nll_loss(mu: torch.Tensor, logvar: torch.Tensor, y: torch.Tensor, mask: torch.Tensor | None = None
             ) -> torch.Tensor:
    """Eq. 6 per output component, averaged: ``sigma^-2 (y - mu)^2 + ln sigma^2``.

    Args:
        mu, logvar, y: ``(B, T, K)``; mask: ``(B, T)`` bool of real (non-padded) frames.

    Returns:
        scalar (the paper sums; the mean only rescales the gradient, which Adam ignores).
    """
    per = torch.exp(-logvar) * (y - mu) ** 2 + logvar
    if mask is None:
        return per.mean()
    m = mask.unsqueeze(-1).to(per)
    return (per * m).sum() / (m.sum() * per.shape[-1]).clamp_min(1.0)


def masked_mse(a: torch.Tensor, b: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared difference over real frames (auxiliary reconstruction loss)."""
    per = (a - b) ** 2
    if mask is None:
        return per.mean()
    m = mask.unsqueeze(-1).to(per)
    return (per * m).sum() / (m.sum() * per.shape[-1]).clamp_min(1.0)
