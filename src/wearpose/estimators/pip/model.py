"""PIP kinematics networks (PIP Sec. 3.1, appendix Fig. 7).

Five RNNs of one structure (:class:`StageRNN`: dropout -> linear -> ReLU -> 2 LSTM layers ->
linear), chained causally:

- ``P_L``: ``x`` (72) -> leaf joint positions (15), root frame;
- ``P_A``: ``[p_leaf, x]`` (87) -> all non-root joint positions (69), root frame;
- ``R_A``: ``[p, x]`` (141) -> root-relative global rotations of joints 1..23 (138, 6D);
- ``V_A``: ``[p, x]`` (141) -> joint velocities (72, Eq. 14, root frame, / ``vel_scale``);
- ``C_F``: ``[p, x]`` (141) -> foot contact logits (2; sigmoid = probability).

``P_L`` and ``V_A`` carry learned initialisation networks ``I_PL`` / ``I_VA`` (FC-ReLU-FC-ReLU-FC)
mapping the first frame's leaf positions / joint velocities to the hidden and cell states of
both LSTM layers (Sec. 3.1.2). With ``learned_init=False`` every LSTM starts from zeros.

Training (:func:`pip_loss`): each stage is fed the previous stage's *detached* prediction, so
each RNN is trained by its own loss only -- the paper trains the RNNs separately; feeding the
predictions (instead of ground truth with noise, TransPose) trains them on the inputs they see
at run time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from wearpose.estimators.pip.config import PipConfig
from wearpose.estimators.pip.data import INPUT_DIM, LEAF_JOINTS

LEAF_DIM = 3 * len(LEAF_JOINTS)
JOINTS_DIM = 3 * 23
ROT_DIM = 6 * 23
VEL_DIM = 3 * 24
STAGES = ("pl", "pa", "ra", "va", "cf")

State = tuple[torch.Tensor, torch.Tensor]


class StageRNN(nn.Module):
    """One PIP RNN: ``dropout -> Linear(in, H) -> ReLU -> LSTM(H, H, layers) -> Linear(H, out)``;
    with ``init_dim`` also an initialisation FCN ``init_dim -> w1 -> w2 -> 2 * layers * H``."""

    def __init__(self, in_dim: int, out_dim: int, cfg: PipConfig, init_dim: int | None = None) -> None:
        super().__init__()
        H, L = cfg.hidden, cfg.rnn_layers
        self.hidden, self.layers = H, L
        self.dropout = nn.Dropout(cfg.dropout)
        self.linear1 = nn.Linear(in_dim, H)
        self.rnn = nn.LSTM(H, H, L, batch_first=True)
        self.linear2 = nn.Linear(H, out_dim)
        self.init_net = None
        if init_dim is not None:
            w1, w2 = cfg.init_widths
            self.init_net = nn.Sequential(nn.Linear(init_dim, w1), nn.ReLU(), nn.Linear(w1, w2), nn.ReLU(),
                                          nn.Linear(w2, 2 * L * H))

    def init_state(self, v: torch.Tensor) -> State:
        """``v`` ``(B, init_dim)`` -> ``(h, c)`` each ``(layers, B, H)``."""
        assert self.init_net is not None
        s = self.init_net(v).view(v.shape[0], 2, self.layers, self.hidden).permute(1, 2, 0, 3)
        return s[0].contiguous(), s[1].contiguous()

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        """``x`` ``(B, T, in)`` -> ``(B, T, out)`` and the final LSTM state."""
        y, state = self.rnn(F.relu(self.linear1(self.dropout(x))), state)
        return self.linear2(y), state


class PipNet(nn.Module):
    """The five-RNN kinematics chain (module doc)."""

    def __init__(self, cfg: PipConfig) -> None:
        super().__init__()
        self.cfg = cfg
        init = cfg.learned_init
        self.pl = StageRNN(INPUT_DIM, LEAF_DIM, cfg, LEAF_DIM if init else None)
        self.pa = StageRNN(INPUT_DIM + LEAF_DIM, JOINTS_DIM, cfg)
        self.ra = StageRNN(INPUT_DIM + JOINTS_DIM, ROT_DIM, cfg)
        self.va = StageRNN(INPUT_DIM + JOINTS_DIM, VEL_DIM, cfg, VEL_DIM if init else None)
        self.cf = StageRNN(INPUT_DIM + JOINTS_DIM, 2, cfg)

    def initial_states(self, init_leaf: torch.Tensor | None, init_vel: torch.Tensor | None) -> list[State | None]:
        """States before the first frame: learned from ``init_leaf`` ``(B, 15)`` / ``init_vel``
        ``(B, 72)`` (scaled like the targets) when the model has init nets, else zeros (None)."""
        states: list[State | None] = [None] * len(STAGES)
        if self.cfg.learned_init:
            if init_leaf is not None:
                states[0] = self.pl.init_state(init_leaf)
            if init_vel is not None:
                states[3] = self.va.init_state(init_vel)
        return states

    def forward(self, x: torch.Tensor, states: list[State | None] | None = None, detach_stages: bool = False
                ) -> tuple[dict[str, torch.Tensor], list[State | None]]:
        """Run the chain on ``x`` ``(B, T, 72)`` from ``states`` (:meth:`initial_states`, or the
        states a previous call returned, for online use).

        Returns:
            ``{"leaf" (B, T, 15), "joints" (B, T, 69), "rot6" (B, T, 138), "vel" (B, T, 72),
            "contact_logit" (B, T, 2)}`` and the five final states.
        """
        states = list(states) if states is not None else [None] * len(STAGES)
        leaf, states[0] = self.pl(x, states[0])
        leaf_in = leaf.detach() if detach_stages else leaf
        joints, states[1] = self.pa(torch.cat([leaf_in, x], -1), states[1])
        h = torch.cat([joints.detach() if detach_stages else joints, x], -1)
        rot6, states[2] = self.ra(h, states[2])
        vel, states[3] = self.va(h, states[3])
        cl, states[4] = self.cf(h, states[4])
        return {"leaf": leaf, "joints": joints, "rot6": rot6, "vel": vel, "contact_logit": cl}, states


def cumulative_velocity_loss(pred: torch.Tensor, gt: torch.Tensor, windows: tuple[int, ...],
                             mask: torch.Tensor | None = None) -> torch.Tensor:
    """TransPose's cumulative velocity loss: for each window length ``n``, the squared norm of
    the error *summed* over consecutive non-overlapping ``n``-frame windows (a position drift
    over n frames, in units of ``vel_scale / fps`` m), divided by ``n``, averaged over windows and
    joints, summed over ``windows``.

    Args:
        pred, gt: ``(B, T, 3J)`` velocities.
        mask: ``(B, T)`` bool, False on padding (a window that starts on padding is not counted;
            one that runs into it sums its valid frames). None = all valid.
    """
    B, T = pred.shape[:2]
    e = (pred - gt).view(B, T, -1, 3)
    if mask is not None:
        e = e * mask[:, :, None, None]
    total = pred.new_zeros(())
    for n in windows:
        k = T // n
        if k == 0:
            continue
        s = e[:, :k * n].reshape(B, k, n, -1, 3).sum(2)
        sq = (s ** 2).sum(-1)  # (B, k, J)
        if mask is None:
            total = total + sq.mean() / n
        else:
            m = mask[:, :k * n:n].to(sq.dtype)  # (B, k): the chunk's first frame is valid
            total = total + (sq * m[:, :, None]).sum() / (m.sum() * sq.shape[-1]).clamp(min=1) / n
    return total


def pip_loss(out: dict[str, torch.Tensor], b: dict[str, torch.Tensor], cfg: PipConfig
             ) -> tuple[torch.Tensor, dict[str, float]]:
    """Weighted sum of the five losses (L2 for P_L, P_A, R_A as mean squared error per
    coordinate in cm / 6D units, cumulative for V_A, BCE for C_F); returns ``(loss, parts)``.
    A batch with ``mask`` ``(B, T)`` (padded windows) averages over its valid frames only."""
    mask = b.get("mask")
    if mask is not None and bool(mask.all()):
        mask = None  # equal-length windows: the plain means (bitwise as before padding existed)

    def mean(x: torch.Tensor) -> torch.Tensor:  # x (B, T, D)
        if mask is None:
            return x.mean()
        m = mask[:, :, None].to(x.dtype)
        return (x * m).sum() / (m.sum() * x.shape[-1])

    def l2(p: torch.Tensor, g: torch.Tensor, k: float = 1.0) -> torch.Tensor:
        return mean(((p - g) * k).pow(2))

    # Positions in decimetres so the L2 terms have similar magnitudes (each RNN has its own
    # parameters, so the weights only matter for reporting and the shared optimiser's steps).
    parts = {"leaf": l2(out["leaf"], b["leaf"], 10.0), "joints": l2(out["joints"], b["joints"], 10.0),
             "rot": l2(out["rot6"], b["rot6"]),
             "vel": cumulative_velocity_loss(out["vel"], b["vel"], cfg.vel_windows, mask),
             "contact": mean(F.binary_cross_entropy_with_logits(out["contact_logit"], b["contact"], reduction="none"))}
    w = {"leaf": cfg.w_leaf, "joints": cfg.w_joints, "rot": cfg.w_rot, "vel": cfg.w_vel, "contact": cfg.w_contact}
    loss = sum(w[k] * v for k, v in parts.items())
    return loss, {f"loss_{k}": float(v.detach()) for k, v in parts.items()}


def run_windows(net: PipNet, b: dict[str, Any], detach_stages: bool = True
                ) -> tuple[dict[str, torch.Tensor], list[State | None]]:
    """Forward a batch of training windows from learned initial states (first frame's targets)."""
    states = net.initial_states(b["leaf"][:, 0], b["vel"][:, 0])
    return net(b["x"], states, detach_stages=detach_stages)


class NumpyStepper:
    """One-frame inference of a :class:`PipNet` in numpy (float32), for the online path.

    At batch 1 and one frame, torch's per-operator overhead dominates the five LSTMs (~2.5 ms
    per frame on this CPU); the same arithmetic as numpy matrix-vector products costs a tenth
    of that. Weights are copied at construction (dropout is inference-time identity); the LSTM
    states live in :attr:`states` as ``(layers, H)`` arrays ``h``, ``c`` per stage.
    PyTorch's LSTM cell: ``i, f, g, o = split(W_ih x + b_ih + W_hh h + b_hh)``,
    ``c' = sigma(f) c + sigma(i) tanh(g)``, ``h' = sigma(o) tanh(c')``.
    """

    def __init__(self, net: PipNet) -> None:

        self.H, self.L = net.cfg.hidden, net.cfg.rnn_layers
        f32 = lambda t: t.detach().cpu().numpy().astype(np.float32)  # noqa: E731
        self.stages = []
        for name in STAGES:
            m = getattr(net, name)
            layers = []
            for k in range(self.L):
                W = np.concatenate([f32(getattr(m.rnn, f"weight_ih_l{k}")), f32(getattr(m.rnn, f"weight_hh_l{k}"))], 1)
                b = f32(getattr(m.rnn, f"bias_ih_l{k}")) + f32(getattr(m.rnn, f"bias_hh_l{k}"))
                layers.append((np.ascontiguousarray(W), b))
            self.stages.append((f32(m.linear1.weight), f32(m.linear1.bias), layers, f32(m.linear2.weight),
                                f32(m.linear2.bias)))
        self.states: list[tuple[Any, Any]] = []
        self.set_states([None] * len(STAGES))

    def set_states(self, states: list[State | None]) -> None:
        """Start from torch states (:meth:`PipNet.initial_states`, batch 1) or zeros (None)."""

        self.states = []
        for s in states:
            if s is None:
                self.states.append((np.zeros((self.L, self.H), np.float32), np.zeros((self.L, self.H), np.float32)))
            else:
                self.states.append((s[0][:, 0].detach().cpu().numpy().astype(np.float32).copy(),
                                    s[1][:, 0].detach().cpu().numpy().astype(np.float32).copy()))

    def _stage(self, i: int, x: Any) -> Any:

        W1, b1, layers, W2, b2 = self.stages[i]
        h_all, c_all = self.states[i]
        y = np.maximum(W1 @ x + b1, 0.0)
        H = self.H
        for k, (W, b) in enumerate(layers):
            g = W @ np.concatenate([y, h_all[k]]) + b
            sig = 1.0 / (1.0 + np.exp(-g[:2 * H]))  # input and forget gates
            o = 1.0 / (1.0 + np.exp(-g[3 * H:]))
            c = sig[H:] * c_all[k] + sig[:H] * np.tanh(g[2 * H:3 * H])
            y = o * np.tanh(c)
            c_all[k] = c
            h_all[k] = y
        return W2 @ y + b2

    def step(self, x: Any) -> dict[str, Any]:
        """``x`` ``(72,)`` float32 -> the outputs of :meth:`PipNet.forward` for one frame (1-D
        numpy arrays), advancing the states."""

        leaf = self._stage(0, x)
        joints = self._stage(1, np.concatenate([leaf, x]))
        h = np.concatenate([joints, x])
        return {"leaf": leaf, "joints": joints, "rot6": self._stage(2, h), "vel": self._stage(3, h),
                "contact_logit": self._stage(4, h)}
