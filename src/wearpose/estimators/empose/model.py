"""LGD-RNN (EM-POSE, Kaufmann et al. ICCV 2021, Sec. 5.3 and supp. Sec. 2.3).

An RNN (2 LSTM layers) maps the measurements ``x_t`` to an initial estimate ``Omega^(0)``
(root orientation, 19 body-joint rotations, shape). Then N learned gradient-descent updates
(Eq. 5)::

    Omega^(n+1) = Omega^(n) + alpha * N(dL_r/dOmega^(n), Omega^(n), x_t)

with the reconstruction loss (Eq. 6) ``L_r = sum_s ||m_ts - sigma(Omega, o_s)||^2``: the virtual
sensors of the current estimate (skin site frames of the differentiable body,
:meth:`wearpose.body.BodyModel.sites`, with the subject's offsets ``o_s = [R | t]`` applied as
Eq. 4, then expressed relative to the EM source site exactly as the simulator does) against
the measurements: squared position error (m^2) plus squared Frobenius norm of the rotation
difference, summed over sensors. The gradient is taken with ``torch.autograd.grad`` (with
``create_graph=True`` while training, so the update network learns through it).

Joints (Sec. 5.1: "we do not observe hand and foot articulation, i.e. J = 19"): the root
orientation plus the 19 body joints other than the feet (10, 11) and hands (22, 23) are
estimated, :data:`PRED_JOINTS`; the 4 unobserved joints are set to identity.

Frame: inputs are source-relative (DESIGN, EM canonical form); the EM source sits on the
lower back, so the source frame plays the part of the root-normalised frame of supp. Sec. 2.1
and the estimated root orientation is relative to the source frame.
"""

from __future__ import annotations

from typing import Any, Sequence

import torch
from torch import nn

from wearpose.body.skeleton import NUM_JOINTS
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.geometry import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix
from wearpose.estimators.empose.fastgrad import LeanSensorGrad

#: Unobserved joints (feet, hands), identity in the output.
UNOBSERVED_JOINTS: tuple[int, ...] = (10, 11, 22, 23)
#: Estimated joints: root (0) then the 19 observed body joints, SMPL order.
PRED_JOINTS: tuple[int, ...] = tuple(j for j in range(NUM_JOINTS) if j not in UNOBSERVED_JOINTS)
NUM_PRED = len(PRED_JOINTS)  # 20
NUM_BETAS = 10
#: Per-sensor input features: position (3, m) + orientation (9, row-major matrix entries).
SENSOR_FEATURES = 12


def rep_dim(rep: str) -> int:
    return 6 if rep == "rot6d" else 3


def omega_dim(rep: str) -> int:
    """Size of Omega: 20 rotations in ``rep`` + 10 betas."""
    return NUM_PRED * rep_dim(rep) + NUM_BETAS


def encode_pose(local_rot: torch.Tensor, rep: str) -> torch.Tensor:
    """``(..., 24, 3, 3)`` local rotations -> ``(..., 20 * k)`` pose part of Omega."""
    R = local_rot[..., list(PRED_JOINTS), :, :]
    v = matrix_to_rot6d(R) if rep == "rot6d" else matrix_to_axis_angle(R)
    return v.flatten(-2)


def decode_omega(omega: torch.Tensor, rep: str) -> tuple[torch.Tensor, torch.Tensor]:
    """``(..., D)`` Omega -> local rotations ``(..., 24, 3, 3)`` (unobserved = I), betas ``(..., 10)``."""
    k = rep_dim(rep)
    pv = omega[..., :NUM_PRED * k].unflatten(-1, (NUM_PRED, k))
    R = rot6d_to_matrix(pv) if rep == "rot6d" else axis_angle_to_matrix(pv)
    full = torch.eye(3, dtype=omega.dtype, device=omega.device).expand(*omega.shape[:-1], NUM_JOINTS, 3, 3).clone()
    full[..., list(PRED_JOINTS), :, :] = R
    return full, omega[..., NUM_PRED * k:]


def module_version(module: nn.Module) -> tuple[int, ...]:
    """Version counters of a module's parameters and buffers: changes whenever any of them is
    modified in place (optimiser steps, running statistics, ``load_state_dict``)."""
    return tuple(t._version for t in (*module.parameters(), *module.buffers()))


def sensor_features(position: torch.Tensor, orientation: torch.Tensor) -> torch.Tensor:
    """``(..., S, 3)`` m and ``(..., S, 3, 3)`` -> network input ``x_t`` ``(..., S * 12)``."""
    return torch.cat([position, orientation.flatten(-2)], dim=-1).flatten(-2)


#: Columns of a sensor's 12 features per ``EmposeConfig.inputs`` (the "pos/ori only" ablations),
#: and the weights (position term, rotation term) of L_r that go with them.
INPUT_COLUMNS: dict[str, tuple[int, ...]] = {"both": tuple(range(12)), "position": (0, 1, 2),
                                             "orientation": tuple(range(3, 12))}
REC_WEIGHTS: dict[str, tuple[float, float]] = {"both": (1.0, 1.0), "position": (1.0, 0.0), "orientation": (0.0, 1.0)}


class VirtualSensors:
    """sigma(Omega, o_s): differentiable virtual EM sensors relative to the source (Eq. 3-4).

    Args:
        body: the :class:`~wearpose.body.BodyModel`.
        sites: body site of each sensor (kit order; repeats allowed, e.g. substituted sites).
        source_site: site of the EM source.
    """

    def __init__(self, body: Any, sites: Sequence[str], source_site: str) -> None:
        self.body = body
        self.unique = list(dict.fromkeys([*sites, source_site]))
        self.index = [self.unique.index(s) for s in sites]
        self.src = self.unique.index(source_site)
        self._lean: dict[tuple[str, torch.dtype], Any] = {}

    def lean(self) -> Any:
        """The closed-form L_r / gradient kernel for these sites on the body's current device and
        dtype (:class:`~wearpose.estimators.empose.fastgrad.LeanSensorGrad`, built once)."""

        key = (str(self.body.device), self.body.dtype)
        if key not in self._lean:
            self._lean[key] = LeanSensorGrad(self.body, self.unique, self.index, self.src)
        return self._lean[key]

    def __call__(self, local_rot: torch.Tensor, betas: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Sensors of a flat batch.

        Args:
            local_rot: ``(N, 24, 3, 3)``; betas: ``(N, 10)``.
            off_R: ``(N, S, 3, 3)`` rotation offsets; off_t: ``(N, S, 3)`` translation offsets, m.

        Returns:
            positions ``(N, S, 3)`` m and orientations ``(N, S, 3, 3)`` in the source frame, and
            the posed joints ``(N, 24, 3)`` (m, root at its rest position, no translation).
        """
        so = self.body.sites(local_rot, betas, None, self.unique)
        Rs, ps = so.rotations[:, self.index], so.positions[:, self.index]
        Rv = Rs @ off_R  # Eq. 4: R^v = R~ R
        pv = ps + (Rs @ off_t.unsqueeze(-1)).squeeze(-1)  # p^v = p~ + R~ t
        RsrcT = so.rotations[:, self.src].transpose(-1, -2).unsqueeze(1)
        p = (RsrcT @ (pv - so.positions[:, self.src].unsqueeze(1)).unsqueeze(-1)).squeeze(-1)
        return p, RsrcT @ Rv, so.joints


def reconstruction_loss(p_hat: torch.Tensor, R_hat: torch.Tensor, p: torch.Tensor, R: torch.Tensor,
                        weights: tuple[float, float] = (1.0, 1.0)) -> torch.Tensor:
    """Eq. 6 per frame: ``sum_s ||p - p^||^2 + ||R - R^||_F^2``; ``(N, S, ...)`` -> ``(N,)``.

    ``weights`` scale the position and rotation terms (``(1, 0)`` / ``(0, 1)``: the "pos only" /
    "ori only" ablations, where the other modality is not measured)."""
    wp, wr = weights
    return wp * ((p_hat - p) ** 2).sum((-1, -2)) + wr * ((R_hat - R) ** 2).sum((-1, -2, -3))


class UpdateNet(nn.Module):
    """The update network N of Eq. 5 (supp. 2.3): a dense layer to ``width``, then ``layers``
    blocks of (batch-norm, PReLU, dropout, dense); the last dense maps back to Omega's size."""

    def __init__(self, in_dim: int, width: int, layers: int, out_dim: int, dropout: float) -> None:
        super().__init__()
        mods: list[nn.Module] = [nn.Linear(in_dim, width)]
        for i in range(layers):
            mods += [nn.BatchNorm1d(width), nn.PReLU(), nn.Dropout(dropout),
                     nn.Linear(width, width if i < layers - 1 else out_dim)]
        self.net = nn.Sequential(*mods)

        self._fused: tuple[tuple[int, ...], list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]]] | None = None

    def _fused_layers(self) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]]:
        """Eval-mode layers with each batch norm folded into the dense layer before it:
        ``[(W, b, prelu_weight or None), ...]``; rebuilt whenever a parameter or running
        statistic changed (tensor version counters)."""
        key = module_version(self)
        if self._fused is None or self._fused[0] != key:
            mods = list(self.net)
            layers, i = [], 0
            while i < len(mods):
                lin = mods[i]
                W, b = lin.weight.detach(), lin.bias.detach()
                act = None
                if i + 1 < len(mods):
                    bn, pr = mods[i + 1], mods[i + 2]
                    scale = bn.weight.detach() / torch.sqrt(bn.running_var + bn.eps)
                    W = W * scale[:, None]
                    b = (b - bn.running_mean) * scale + bn.bias.detach()
                    act = pr.weight.detach()
                layers.append((W, b, act))
                i += 4
            self._fused = (key, layers)
        return self._fused[1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.training or torch.is_grad_enabled():
            return self.net(x)
        for W, b, act in self._fused_layers():  # inference: 2 ops per layer, no module calls
            x = torch.nn.functional.linear(x, W, b)
            if act is not None:
                x = torch.nn.functional.prelu(x, act)
        return x


class LGDRNN(nn.Module):
    """The LGD-RNN network.

    Args:
        cfg: :class:`EmposeConfig`.
        num_sensors: S.
    """

    def __init__(self, cfg: EmposeConfig, num_sensors: int) -> None:
        super().__init__()
        self.cfg = cfg
        self.rep = cfg.rep
        self.num_sensors = num_sensors
        #: Inference (``train=False``) with the 6D pose takes the closed-form gradient of
        #: :mod:`~wearpose.estimators.empose.fastgrad` instead of autograd (same numbers, several
        #: times faster); False forces the autograd path (tests compare the two).
        self.lean_inference = True
        cols = INPUT_COLUMNS[cfg.inputs]
        self.rec_weights = REC_WEIGHTS[cfg.inputs]
        # Feature indices into the full (S * 12) x_t; None = all (the full model: no gather).
        self._cols = None if cfg.inputs == "both" else torch.tensor(
            [s * SENSOR_FEATURES + c for s in range(num_sensors) for c in cols])
        F = num_sensors * len(cols)
        D = omega_dim(cfg.rep)
        self.in_dim, self.omega_dim = F, D
        self.input_dropout = nn.Dropout(cfg.dropout_input)
        # Omega of the zero pose / mean shape: the head predicts around it, so training starts at
        # a plausible body instead of degenerate 6D vectors.
        ident = torch.eye(3).expand(NUM_JOINTS, 3, 3)
        self.register_buffer("omega_rest", torch.cat([encode_pose(ident, cfg.rep), torch.zeros(NUM_BETAS)]))
        if cfg.init == "rnn":
            self.rnn = nn.LSTM(F, cfg.hidden, cfg.rnn_layers, batch_first=True)
            self.head = nn.Linear(cfg.hidden, D)
        else:  # "no RNN" ablation: one learned start for every frame (no temporal model at all)
            self.omega_init = nn.Parameter(torch.zeros(D))  # offset from omega_rest; see set_mean_start
        self.update = UpdateNet(2 * D + F, cfg.width, cfg.mlp_layers, D, cfg.dropout_mlp)
        self._lstm_fused: tuple[tuple[int, ...], list[tuple[torch.Tensor, torch.Tensor]]] | None = None

    @torch.no_grad()
    def set_mean_start(self, pose6: torch.Tensor) -> None:
        """"no RNN" (``cfg.init == "mean"``): start LGD at the mean training pose and mean shape.

        Args:
            pose6: ``(F, 24, 6)`` ground-truth local rotations in 6D (root in the source frame),
                e.g. :attr:`EmposeData.pose6`; their mean is projected back to rotations.

        Why: L_r is blind to the root orientation relative to the EM source (the source rides on the
        pelvis), so LGD updates get no gradient for it; from the zero pose the learned constant has
        to travel ~70 degrees at Adam's step size, which a short training cannot do.
        """
        R = rot6d_to_matrix(pose6.reshape(-1, NUM_JOINTS, 6).double().mean(0)).float()
        omega = torch.cat([encode_pose(R, self.rep), torch.zeros(NUM_BETAS)]).to(self.omega_rest)
        self.omega_init.copy_(omega - self.omega_rest)

    def select_inputs(self, x: torch.Tensor) -> torch.Tensor:
        """The measured features this model uses (``cfg.inputs``) from the full ``(..., S * 12)``
        x_t (:func:`sensor_features`); idempotent (an already selected x passes through)."""
        if self._cols is None or x.shape[-1] == self.in_dim:
            return x
        return x.index_select(-1, self._cols.to(x.device))

    def initial(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None
                ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """RNN estimate ``Omega^(0)`` ``(B, T, D)`` from ``x`` ``(B, T, S * 12)`` (and the LSTM state).

        With ``cfg.init == "mean"`` ("no RNN") the learned constant start for every frame; the
        ``state`` passes through unchanged (zeros when None, so the online trace keeps its form)."""
        x = self.select_inputs(x)
        if self.cfg.init == "mean":
            if state is None:
                z = x.new_zeros(self.cfg.rnn_layers, x.shape[0], self.cfg.hidden)
                state = (z, z)
            return (self.omega_init + self.omega_rest).expand(*x.shape[:-1], self.omega_dim), state
        h, state = self.rnn(self.input_dropout(x), state)
        return self.head(h) + self.omega_rest, state

    def _fused_lstm(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Per LSTM layer ``(W, b)``: ``W = [W_ih, W_hh]^T`` ``(F_l + H, 4H)`` and ``b = b_ih + b_hh``
        ``(4H,)``, so one ``addmm`` gives a layer's four gates; rebuilt whenever a weight changed
        (tensor version counters)."""
        key = module_version(self.rnn)
        if self._lstm_fused is None or self._lstm_fused[0] != key:
            r = self.rnn
            layers = [(torch.cat([getattr(r, f"weight_ih_l{k}"), getattr(r, f"weight_hh_l{k}")], 1).detach().t()
                       .contiguous(), (getattr(r, f"bias_ih_l{k}") + getattr(r, f"bias_hh_l{k}")).detach())
                      for k in range(r.num_layers)]
            self._lstm_fused = (key, layers)
        return self._lstm_fused[1]

    def initial_step(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor]
                     ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """:meth:`initial` for one frame in eval mode: ``x`` ``(B, S * 12)``, ``state`` ``(h, c)``
        each ``(rnn_layers, B, hidden)`` -> ``Omega^(0)`` ``(B, D)`` and the new state.

        The LSTM cell written out (one ``addmm`` per layer for the four gates, PyTorch's gate
        order i, f, g, o): equal to ``nn.LSTM`` up to float rounding (the audit of issue 25 found
        ``nn.LSTM``'s oneDNN kernel costing 1.2 ms per layer per frame at batch 1, 20x the
        arithmetic)."""
        x = self.select_inputs(x)
        if self.cfg.init == "mean":
            return (self.omega_init + self.omega_rest).expand(*x.shape[:-1], self.omega_dim), state
        h0, c0 = state
        hs, cs = [], []
        inp = x
        for k, (W, b) in enumerate(self._fused_lstm()):
            i, f, g, o = torch.addmm(b, torch.cat([inp, h0[k]], -1), W).chunk(4, -1)
            c = torch.sigmoid(f) * c0[k] + torch.sigmoid(i) * torch.tanh(g)
            inp = torch.sigmoid(o) * torch.tanh(c)
            hs.append(inp)
            cs.append(c)
        return self.head(inp) + self.omega_rest, (torch.stack(hs), torch.stack(cs))

    def refine(self, omega0: torch.Tensor, x: torch.Tensor, meas_p: torch.Tensor, meas_R: torch.Tensor,
               off_R: torch.Tensor, off_t: torch.Tensor, sensors: VirtualSensors, *, train: bool
               ) -> list[dict[str, torch.Tensor]]:
        """N LGD updates on a flat batch of frames.

        Args:
            omega0: ``(N, D)``; x: ``(N, S * 12)``; meas_p ``(N, S, 3)``, meas_R ``(N, S, 3, 3)``
                the measurements; off_R ``(N, S, 3, 3)``, off_t ``(N, S, 3)`` the subject offsets.
            sensors: sigma.
            train: build the graph through the gradients (``create_graph``) for training.

        Returns:
            N + 1 dicts (n = 0..N) with ``omega`` ``(N, D)``, ``local_rot``, ``betas``, ``joints``
            ``(N, 24, 3)`` and ``rec`` ``(N,)`` = L_r at that estimate.
        """
        if not train and self.lean_inference and self.rep == "rot6d":
            return self._refine_lean(omega0, x, meas_p, meas_R, off_R, off_t, sensors)
        x = self.select_inputs(x)
        out = []
        omega = omega0
        for n in range(self.cfg.iterations + 1):
            with torch.enable_grad():
                if not omega.requires_grad:
                    omega = omega.detach().requires_grad_(True)
                R, b = decode_omega(omega, self.rep)
                p_hat, R_hat, joints = sensors(R, b, off_R, off_t)
                rec = reconstruction_loss(p_hat, R_hat, meas_p, meas_R, self.rec_weights)
                out.append({"omega": omega, "local_rot": R, "betas": b, "joints": joints, "rec": rec})
                if n == self.cfg.iterations:
                    break
                grad, = torch.autograd.grad(rec.sum(), omega, create_graph=train)
            step = self.update(torch.cat([grad, omega, x], dim=-1))
            omega = omega + self.cfg.alpha * step
            if not train:
                omega = omega.detach()
        return out

    @torch.no_grad()
    def _refine_lean(self, omega: torch.Tensor, x: torch.Tensor, meas_p: torch.Tensor, meas_R: torch.Tensor,
                     off_R: torch.Tensor, off_t: torch.Tensor, sensors: VirtualSensors) -> list[dict[str, torch.Tensor]]:
        """:meth:`refine` for inference with the closed-form dL_r/dOmega (no graph)."""
        kernel = sensors.lean()
        x = self.select_inputs(x)
        out = []
        for n in range(self.cfg.iterations + 1):
            ctx = kernel.forward(omega, meas_p, meas_R, off_R, off_t, self.rec_weights)
            out.append({"omega": omega, "local_rot": ctx["local_rot"], "betas": ctx["betas"], "joints": ctx["joints"],
                        "rec": ctx["rec"]})
            if n == self.cfg.iterations:
                break
            grad = kernel.backward(ctx)
            omega = omega + self.cfg.alpha * self.update(torch.cat([grad, omega, x], dim=-1))
        return out

    def forward(self, x: torch.Tensor, meas_p: torch.Tensor, meas_R: torch.Tensor, off_R: torch.Tensor,
                off_t: torch.Tensor, sensors: VirtualSensors, *, train: bool = True,
                state: tuple[torch.Tensor, torch.Tensor] | None = None
                ) -> tuple[list[dict[str, torch.Tensor]], tuple[torch.Tensor, torch.Tensor]]:
        """Sequence batch: x ``(B, T, F)``, meas ``(B, T, S, ...)``, offsets ``(B, S, ...)``.

        Returns the per-iteration outputs with a leading ``(B, T)`` reshaped back, and the LSTM state.
        """
        B, T = x.shape[:2]
        omega0, state = self.initial(x, state)
        S = self.num_sensors
        oR = off_R[:, None].expand(B, T, S, 3, 3).reshape(B * T, S, 3, 3)
        ot = off_t[:, None].expand(B, T, S, 3).reshape(B * T, S, 3)
        outs = self.refine(omega0.reshape(B * T, -1), x.reshape(B * T, -1), meas_p.reshape(B * T, S, 3),
                           meas_R.reshape(B * T, S, 3, 3), oR, ot, sensors, train=train)
        return [{k: v.reshape(B, T, *v.shape[1:]) for k, v in o.items()} for o in outs], state


def lgd_loss(outs: list[dict[str, torch.Tensor]], gt_pose: torch.Tensor, gt_betas: torch.Tensor,
             gt_joints: torch.Tensor, cfg: EmposeConfig) -> tuple[torch.Tensor, dict[str, float]]:
    """The training loss of Sec. 5.3, averaged over iterations n = 1..N (and n = 0 if
    ``cfg.supervise_initial`` or N = 0) and frames.

    Args:
        outs: :meth:`LGDRNN.forward` outputs, ``(B, T, ...)``.
        gt_pose: ``(B, T, 24, 3, 3)`` local rotations; gt_betas ``(B, 10)``; gt_joints
            ``(B, T, 24, 3)`` m (same frame and zero translation as the model's joints).

    Returns:
        the loss and its parts (floats, last iteration) for logging.
    """
    target = encode_pose(gt_pose, cfg.rep)
    sel = outs[1:] if (cfg.iterations > 0 and not cfg.supervise_initial) else outs
    total = torch.zeros((), dtype=gt_joints.dtype, device=gt_joints.device)
    parts: dict[str, float] = {}
    for o in sel:
        k = rep_dim(cfg.rep)
        l_pose = ((o["omega"][..., :NUM_PRED * k] - target) ** 2).mean()
        l_shape = ((o["betas"].mean(1) - gt_betas) ** 2).mean()  # shape averaged per sequence
        l_joints = ((o["joints"] - gt_joints) ** 2).mean()
        l_rec = o["rec"].mean()
        total = total + cfg.lambda_pose * l_pose + cfg.lambda_shape * l_shape + cfg.lambda_joints * l_joints \
            + cfg.lambda_rec * l_rec
        parts = {"pose": float(l_pose.detach()), "shape": float(l_shape.detach()), "joints": float(l_joints.detach()),
                 "rec": float(l_rec.detach())}
    return total / len(sel), parts
