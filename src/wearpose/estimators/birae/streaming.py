"""BiRAE's online mode computed incrementally (``online="stream"``), one deterministic pass.

The sliding-window mode (:meth:`BiraeEstimator.step` with ``online="window"``) re-runs both
Bi-LSTM layers over ``past + 1 + future`` frames for every output frame (322 + 322 LSTM steps
at [130, 30], times M MC samples). Streaming keeps what does not need the future:

- layer 1 forward: its state is carried from frame to frame (one LSTM step per frame), from the
  start of the stream instead of from the window's first frame;
- layer 1 backward: run over the ``future + 1`` newest frames ``k .. t`` from a zero state at
  ``t`` (as in the window), giving its outputs at ``k .. t``;
- layer 2 forward: carried state, one step per output frame ``k``, fed with layer 1's outputs
  at ``k`` as they were when ``k`` was the output frame (layer 1 backward from ``k + future``);
- layer 2 backward: over ``k .. t`` from ``t``, fed with this step's layer 1 outputs.

So an output frame sees the same future as in the window mode and an unbounded past (the
window mode sees ``past`` frames; benchmarks/results/birae_window.md: past 30, 130 and 250 give
MPJAE within 0.2 deg of each other). It is a different computation from the window mode (the
first output frame is the same), measured on the test split by :func:`evaluate` in
``mode="stream"``. Cost per frame: 2 + 2 (future + 1) LSTM steps (64 at future = 30) instead
of 4 (past + future + 1) (644), and no MC-dropout: sigma is the aleatoric head
``exp(logvar / 2)`` times the checkpoint's calibration scale.

:func:`stream_predict` computes the same outputs for a whole sequence in batches (evaluation).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import torch

from wearpose.estimators.birae.model import BiRAE


def _params(lstm: torch.nn.LSTM, layer: int, reverse: bool) -> list[torch.Tensor]:
    sfx = f"_l{layer}" + ("_reverse" if reverse else "")
    return [getattr(lstm, f"{k}{sfx}") for k in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")]


def _lstm(x: torch.Tensor, params: list[torch.Tensor], hc: tuple[torch.Tensor, torch.Tensor] | None = None
          ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """One direction of one layer: ``x`` ``(B, L, D)`` -> outputs ``(B, L, H)`` and the final state."""
    if hc is None:
        z = x.new_zeros(1, x.shape[0], params[1].shape[1])
        hc = (z, z)
    out, h, c = torch.lstm(x, hc, params, True, 1, 0.0, False, False, True)
    return out, (h, c)


def _heads(model: BiRAE, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    return model.mu(out), model.logvar(out).clamp(model.cfg.logvar_min, model.cfg.logvar_max)


def _check(model: BiRAE) -> None:
    if model.lstm.num_layers != 2 or not model.lstm.bidirectional:
        raise ValueError(f"BiRAE streaming needs the 2-layer Bi-LSTM, got {model.lstm.num_layers} layers")


@dataclass
class StreamState:
    """What :func:`stream_step` carries between frames (one stream; ``reset`` = a new one)."""

    future: int
    l1: tuple[torch.Tensor, torch.Tensor] | None = None  # layer 1 forward (h, c)
    l2: tuple[torch.Tensor, torch.Tensor] | None = None  # layer 2 forward (h, c)
    h: deque = field(default_factory=deque)  # input-FC outputs of the newest future + 1 frames
    f1: deque = field(default_factory=deque)  # layer 1 forward outputs of the same frames


@torch.no_grad()
def stream_step(model: BiRAE, x: torch.Tensor, state: StreamState) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Feed one frame's features ``x`` ``(D,)``; returns ``mu``, ``logvar`` ``(45,)`` of the frame
    ``future`` steps back, or ``None`` while fewer than ``future + 1`` frames were seen."""
    _check(model)
    lstm = model.lstm
    h = torch.relu(model.inp(x))[None, None]  # (1, 1, W): eval, no dropout
    f1, state.l1 = _lstm(h, _params(lstm, 0, False), state.l1)
    state.h.append(h[0, 0])
    state.f1.append(f1[0, 0])
    while len(state.h) > state.future + 1:
        state.h.popleft()
        state.f1.popleft()
    if len(state.h) < state.future + 1:
        return None
    hw = torch.stack(tuple(state.h))  # (L, W), frames k .. t
    b1 = _lstm(hw.flip(0)[None], _params(lstm, 0, True))[0][0].flip(0)  # (L, H), frames k .. t
    in2 = torch.cat([torch.stack(tuple(state.f1)), b1], dim=-1)  # (L, 2H)
    f2, state.l2 = _lstm(in2[None, :1], _params(lstm, 1, False), state.l2)
    b2 = _lstm(in2.flip(0)[None], _params(lstm, 1, True))[0][0, -1]  # frame k
    return _heads(model, torch.cat([f2[0, 0], b2]))


@torch.no_grad()
def stream_predict(model: BiRAE, x: torch.Tensor, future: int, frames: torch.Tensor | None = None,
                   batch: int = 256) -> tuple[torch.Tensor, torch.Tensor]:
    """What :func:`stream_step` outputs for every frame of a sequence, in batches.

    Args:
        x: ``(T, D)`` features of the whole sequence.
        future: look-ahead frames.
        frames: frame indices to output (default all). Frames within ``future`` of the end get
            the future that exists (a stream that ends never outputs them).

    Returns:
        ``mu``, ``logvar`` ``(len(frames), 45)``.
    """
    _check(model)
    lstm = model.lstm
    T, L = x.shape[0], future + 1
    h = torch.relu(model.inp(x))  # (T, W)
    f1 = _lstm(h[None], _params(lstm, 0, False))[0][0]  # (T, H)
    ks = torch.arange(T)
    hi = (ks + future).clamp_max(T - 1)
    last = hi - ks  # reversed position of frame k in its window
    # Window k reversed: frames hi_k, hi_k - 1, ..., k, then padding (clamped ids) that only
    # follows the outputs read, so it cannot change them.
    rev = torch.maximum(hi[:, None] - torch.arange(L)[None], ks[:, None])  # (T, L)

    def layer1_back(sel: torch.Tensor) -> torch.Tensor:
        return _lstm(h[rev[sel]], _params(lstm, 0, True))[0]  # (n, L, H), reversed order

    b1_self = torch.empty_like(f1)
    for a in range(0, T, batch):
        sel = ks[a:a + batch]
        b1_self[sel] = layer1_back(sel)[torch.arange(len(sel)), last[sel]]
    f2 = _lstm(torch.cat([f1, b1_self], -1)[None], _params(lstm, 1, False))[0][0]  # (T, H)
    out_ids = ks if frames is None else torch.as_tensor(frames, dtype=torch.long)
    mus, lvs = [], []
    for a in range(0, len(out_ids), batch):
        sel = out_ids[a:a + batch]
        in2 = torch.cat([f1[rev[sel]], layer1_back(sel)], dim=-1)  # (n, L, 2H), reversed order
        b2 = _lstm(in2, _params(lstm, 1, True))[0][torch.arange(len(sel)), last[sel]]
        mu, lv = _heads(model, torch.cat([f2[sel], b2], dim=-1))
        mus.append(mu)
        lvs.append(lv)
    if not mus:
        return x.new_zeros(0, 45), x.new_zeros(0, 45)
    return torch.cat(mus), torch.cat(lvs)
