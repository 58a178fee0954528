"""EM-POSE two-stage model for dropped sensors (supp. Sec. 9, Fig. 11, Table 10).

Stage 1, the **joint mapper** (:class:`JointMapper`): a 2-layer bidirectional LSTM maps the EM
measurements to the 3D positions and global orientations (source frame) of the 20 estimated
joints (:data:`~wearpose.estimators.empose.model.PRED_JOINTS`). It is trained with random
sensor removal: in most training windows one to three sensors are removed for half of the window
(supp. 9: "we randomly remove one or several sensor measurements from the input for half the
duration of the given sequence"). A removed or dropped sample enters as zeros with a per-sensor
availability flag (so the network knows what is missing instead of seeing a stale value). It also
receives the subject offsets ``O_p`` (per sequence; our choice: the LGD-RNN it is compared with
uses them through L_r, so both know the subject and Table 10 measures the missing sensors).

Stage 2, **LGD IK** (:class:`~wearpose.estimators.empose.model.LGDRNN` with the joints as its
"sensors", :class:`JointSensors`): an LSTM initial estimate from the joint positions and
orientations, then N learned gradient steps on ``L_r = sum_j ||J_j - J^_j||^2 + ||G_j - G^_j||_F^2``
through forward kinematics (no skin). As in the paper it is trained on ground-truth joints and
orientations (from the corpus), here with Gaussian perturbations (``JOINT_NOISE_M`` on positions,
``ROT_NOISE_RAD`` per axis on orientations) so it tolerates the mapper's errors.

Both stages train in one loop on the same batches but independently (no gradient crosses from
stage 2 into stage 1): loss = mapper loss + stage-2 LGD loss
(:func:`~wearpose.estimators.empose.model.lgd_loss`).

Stage 2 alternative, ``EmposeConfig.ik = "closed"`` (ours, not in the paper): the mapper's 20
global orientations already fix the pose, so the local rotations follow in closed form
(:func:`closed_form_pose`: ``R_j = G_parent^T G_j``; feet and hands, not mapped, get identity),
the shape is a ridge least-squares fit of the betas to the mapped joint positions over the whole
sequence (:func:`fit_betas`; joints are linear in the betas for fixed rotations), and an
optional L-BFGS polish (:func:`polish_pose`, :data:`POLISH_ITERS`, off by default) moves the
rotations towards the mapped joint positions. No network in stage 2; the mapper is trained with an extra loss on the joints that forward
kinematics of its orientations gives (:data:`FK_JOINT_WEIGHT`). Why: on 30 val clips the
paper's LGD IK, fed the *ground-truth* joints and orientations, still erred 5.4 mm MPJPE (it is
trained on inputs perturbed by 15 mm, so it smooths), and on the mapper's output 10.1 mm on
frames with every sensor, where the closed form from the same mapper gave 9.3 mm; the closed
form is exact on exact inputs.

Mapper input alternative, ``EmposeConfig.mapper_input = "site"`` (ours): the measurements are
first turned into the skin-site poses the subject offsets imply (:func:`site_poses`, Eq. 4
inverted), so the mapper need not learn the offsets' bilinear effect (it still gets the offsets).

:class:`TwoStageEstimator` (registry ``empose-twostage``) is offline (bidirectional mapper) and
returns a pose for every frame, including those with missing sensors (``valid`` is all True;
``extras["sensors_valid"]`` keeps the input mask).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Mapping

import torch
from torch import nn

from wearpose.body.kinematics import forward_kinematics, global_to_local
from wearpose.body.skeleton import NUM_JOINTS, PARENTS
from wearpose.errors import ConfigError
from wearpose.estimators.base import PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.data import EmposeData
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.method import OptionError, TrainRun
from wearpose.estimators.empose.model import (
    LGDRNN, NUM_BETAS, PRED_JOINTS, SENSOR_FEATURES, lgd_loss, sensor_features,
)
from wearpose.estimators.registry import register_estimator
from wearpose.geometry import axis_angle_to_matrix, matrix_to_rot6d, rot6d_to_matrix
from wearpose.estimators.seeding import init_seed, seeded
from pathlib import Path
from wearpose.body.skeleton import MAJOR_JOINTS
from wearpose.estimators.base import OfflineOnlyError
from wearpose.estimators.checkpoint import CheckpointMismatchError, load_checkpoint
from wearpose.estimators.checkpoint import save_checkpoint
from wearpose.estimators.empose.train import EmposeTask
from wearpose.estimators.empose.train import train_empose
from wearpose.evaluate.metrics import mpjpe
from wearpose.geometry import matrix_to_rot6d
import math
import sys

NUM_MAPPED = len(PRED_JOINTS)  # 20 joints: positions + orientations from the mapper
JOINT_NOISE_M = 0.015  #: std of the position perturbation of stage-2 training inputs, m
ROT_NOISE_RAD = 0.05  #: std per axis of the orientation perturbation of stage-2 training inputs, rad
MAP_JOINT_WEIGHT = 20.0  #: weight of the mapper's joint MSE (m^2) against its 6D orientation MSE
MAX_REMOVED = 3  #: sensors removed per training window: 1..MAX_REMOVED
P_REMOVE = 0.8  #: fraction of training windows with removed sensors
#: ``ik="closed"``: weight of the MSE (m^2) of the joints that forward kinematics of the mapped
#: orientations gives (mean shape of the window), added to the mapper loss; at 100 it is of the
#: order of the 6D orientation term (the metric is on these joints, the 6D MSE is only a proxy).
FK_JOINT_WEIGHT = 100.0
#: ``ik="closed"``: ridge weight of the betas fit (m^2 per frame against |beta|^2, a N(0, I) shape
#: prior). Chosen on val (174 clips, Table 10 protocol, runs/twostage12_site): 1e-2 gave MPJPE
#: 10.85 mm against 11.06 with 1e-4; our corpus has only the mean shape (all betas 0), so a
#: stronger pull to the mean can only help here; real subjects may want a weaker prior.
SHAPE_PRIOR = 1e-2
#: ``ik="closed"``: L-BFGS iterations of the pose polish (0 = closed form only, the default), and
#: the weight of the orientation term (squared Frobenius) against the joint term (m^2). On val the
#: polish (15 iterations) gained 0.3 mm with the first fine-tuned mapper but nothing with the
#: site-input one (10.87 vs 10.85 mm all frames, 11.56 vs 11.47 on frames with missing sensors) at
#: twice the estimate time, so it is off.
POLISH_ITERS = 0
POLISH_ROT_WEIGHT = 1e-2
#: Mapped joint (index into PRED_JOINTS) whose global orientation each of the 24 joints takes in
#: the closed form: itself, or for the unmapped feet / hands their parent (local identity).
_FULL = tuple(PRED_JOINTS.index(j if j in PRED_JOINTS else PARENTS[j]) for j in range(NUM_JOINTS))


def twostage_config(preset: str, sensors: int) -> EmposeConfig:
    """``EmposeConfig.preset(preset, sensors)`` with ``model="twostage"``: ``hidden`` /
    ``rnn_layers`` size the mapper BiLSTM (per direction) and the stage-2 LSTM, ``width`` /
    ``mlp_layers`` / ``iterations`` the stage-2 update network; the cpu preset uses N = 2."""
    base = EmposeConfig.preset(preset, sensors)
    kw: dict[str, Any] = {"model": "twostage"}
    if preset == "cpu":
        kw.update(iterations=2)
    return replace(base, **kw)


def closed_form_pose(rots: torch.Tensor) -> torch.Tensor:
    """Stage 2 in closed form, rotations: mapped global orientations ``(..., 20, 3, 3)`` (source
    frame, :data:`PRED_JOINTS`) -> local rotations ``(..., 24, 3, 3)`` (root in the source frame;
    feet and hands identity). Differentiable."""
    return global_to_local(rots[..., list(_FULL), :, :])


def fit_betas(body: Any, local_rot: torch.Tensor, joints: torch.Tensor, prior: float = SHAPE_PRIOR) -> torch.Tensor:
    """One shape for a sequence: ridge least squares of the betas to mapped joint positions.

    For fixed rotations, forward kinematics is linear in the rest skeleton, which is linear in
    the betas (``J_template + J_shapedirs beta``), so
    ``min_b mean_t sum_j ||FK(R_t, rest(b))_j - joints_tj||^2 + prior ||b||^2`` is a 10x10 solve.

    Args:
        body: the :class:`~wearpose.body.BodyModel`.
        local_rot: ``(T, 24, 3, 3)``; joints: ``(T, 20, 3)`` m (:data:`PRED_JOINTS`, source frame).
        prior: ridge weight (:data:`SHAPE_PRIOR`).

    Returns:
        betas ``(NUM_BETAS,)``.
    """
    pj = list(PRED_JOINTS)
    T = local_rot.shape[0]
    D = body.J_shapedirs[..., :NUM_BETAS].to(local_rot)  # (24, 3, 10)
    _, base = forward_kinematics(local_rot, body.J_template.to(local_rot))
    basis = torch.stack([forward_kinematics(local_rot, D[..., k])[1][:, pj] for k in range(D.shape[-1])], -1)
    A = basis.reshape(-1, D.shape[-1]).double()
    y = (joints - base[:, pj]).reshape(-1).double()
    lhs = A.T @ A / max(T, 1) + prior * torch.eye(D.shape[-1], dtype=A.dtype, device=A.device)
    return torch.linalg.solve(lhs, A.T @ y / max(T, 1)).to(local_rot)


def polish_pose(body: Any, local_rot: torch.Tensor, betas: torch.Tensor, joints: torch.Tensor, rots: torch.Tensor,
                iters: int = POLISH_ITERS, rot_weight: float = POLISH_ROT_WEIGHT) -> tuple[torch.Tensor, torch.Tensor]:
    """L-BFGS (strong Wolfe) on the local rotations (6D) of a whole sequence towards the mapped
    joints and orientations: ``sum_j ||J_j - joints_j||^2 + rot_weight ||G_j - rots_j||_F^2``.

    Args:
        local_rot ``(T, 24, 3, 3)`` start; betas ``(10,)``; joints ``(T, 20, 3)`` m and rots
        ``(T, 20, 3, 3)`` (mapper output, :data:`PRED_JOINTS`).

    Returns:
        local rotations ``(T, 24, 3, 3)`` and the per-frame joint residual ``(T,)`` m^2.
    """

    pj = list(PRED_JOINTS)
    rest = body.rest_joints(betas.to(body.J_template)).to(local_rot)

    def terms(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        G, J = forward_kinematics(rot6d_to_matrix(x), rest)
        return ((J[:, pj] - joints) ** 2).sum((-1, -2)), ((G[:, pj] - rots) ** 2).sum((-1, -2, -3))

    x = matrix_to_rot6d(local_rot).detach().clone()
    if iters > 0:
        x.requires_grad_(True)
        opt = torch.optim.LBFGS([x], lr=1.0, max_iter=iters, line_search_fn="strong_wolfe")

        def closure() -> torch.Tensor:
            opt.zero_grad()
            pe, re = terms(x)
            loss = pe.sum() + rot_weight * re.sum()
            loss.backward()
            return loss

        with torch.enable_grad():
            opt.step(closure)
        x = x.detach()
    with torch.no_grad():
        pe, _ = terms(x)
    return rot6d_to_matrix(x), pe


class JointSensors:
    """Stage-2 "virtual sensors": positions and global orientations of :data:`PRED_JOINTS`
    (drop-in for :class:`~wearpose.estimators.empose.model.VirtualSensors` in
    :meth:`LGDRNN.refine`; the offsets arguments are ignored)."""

    def __init__(self, body: Any) -> None:
        self.body = body
        self.index = list(PRED_JOINTS)

    def __call__(self, local_rot: torch.Tensor, betas: torch.Tensor, off_R: Any = None, off_t: Any = None
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        out = self.body(local_rot, betas, None, return_vertices=False)
        return out.joints[:, self.index], out.global_rot[:, self.index], out.joints


class JointMapper(nn.Module):
    """Stage 1 (module doc). Input per frame: masked sensor features ``(S * 12)``, availability
    ``(S)``, offsets ``(S * 12)``; output joints ``(20, 3)`` m and orientations ``(20, 3, 3)``
    (source frame), predicted around the rest pose of the mean body."""

    def __init__(self, cfg: EmposeConfig, num_sensors: int, rest_joints: torch.Tensor) -> None:
        super().__init__()
        S = num_sensors
        self.rnn = nn.LSTM(S * (2 * SENSOR_FEATURES + 1), cfg.hidden, cfg.rnn_layers, batch_first=True,
                           bidirectional=True)
        self.head = nn.Linear(2 * cfg.hidden, NUM_MAPPED * 9)
        ident = matrix_to_rot6d(torch.eye(3).expand(NUM_MAPPED, 3, 3))
        self.register_buffer("rest", torch.cat([rest_joints[list(PRED_JOINTS)].float(), ident], -1).flatten())

    def forward(self, feats: torch.Tensor, avail: torch.Tensor, offsets: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """feats ``(B, T, S * 12)`` (zeros where unavailable), avail ``(B, T, S)`` float,
        offsets ``(B, S * 12)`` -> joints ``(B, T, 20, 3)``, rot6d ``(B, T, 20, 6)`` (raw),
        rotations ``(B, T, 20, 3, 3)``."""
        B, T = feats.shape[:2]
        x = torch.cat([feats, avail, offsets[:, None].expand(B, T, offsets.shape[-1])], -1)
        h, _ = self.rnn(x)
        y = (self.head(h) + self.rest).unflatten(-1, (NUM_MAPPED, 9))
        return y[..., :3], y[..., 3:], rot6d_to_matrix(y[..., 3:])


class TwoStageNet(nn.Module):
    """The two networks (trained independently, saved together)."""

    def __init__(self, cfg: EmposeConfig, num_sensors: int, rest_joints: torch.Tensor) -> None:
        super().__init__()
        self.cfg = cfg
        self.rep = cfg.rep
        self.mapper = JointMapper(cfg, num_sensors, rest_joints)
        self.ik: LGDRNN | None = None  # ik="closed": no stage-2 network
        if cfg.ik == "lgd":
            self.ik = LGDRNN(cfg, NUM_MAPPED)
            self.ik.lean_inference = False  # the closed-form kernel is for skin sites; IK is FK only


def _offset_features(off_R: torch.Tensor, off_t: torch.Tensor) -> torch.Tensor:
    """``(B, S, 3, 3)``, ``(B, S, 3)`` -> ``(B, S * 12)``."""
    return sensor_features(off_t, off_R)


def site_poses(p: torch.Tensor, R: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Skin-site poses (source frame) implied by measurements and subject offsets, inverting
    EM-POSE Eq. 4 (``R = R_site R_off``, ``p = p_site + R_site t_off``).

    Args:
        p ``(..., S, 3)`` m, R ``(..., S, 3, 3)``: measurements; off_R ``(..., S, 3, 3)``, off_t
        ``(..., S, 3)`` m: offsets, broadcastable against them (e.g. ``(B, 1, S, ...)`` per window).

    Returns:
        ``p_site`` ``(..., S, 3)``, ``R_site`` ``(..., S, 3, 3)``.

    Why (``mapper_input="site"``): the offsets enter the measurement bilinearly (rotation times
    offset), which an LSTM fed measurement and offsets side by side has to learn; the site pose is
    rigid with its bone up to skin sliding, so bone orientations are (nearly) a fixed linear map of it.
    """
    Rs = R @ off_R.transpose(-1, -2)
    return p - (Rs @ off_t.unsqueeze(-1)).squeeze(-1), Rs


def mapper_inputs(cfg: EmposeConfig, p: torch.Tensor, R: torch.Tensor, avail: torch.Tensor, off_R: torch.Tensor,
                  off_t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The joint mapper's three inputs for ``cfg.mapper_input``: p ``(B, T, S, 3)``, R
    ``(B, T, S, 3, 3)``, avail ``(B, T, S)`` bool, offsets ``(B, S, 3, 3)`` / ``(B, S, 3)`` ->
    masked features ``(B, T, S * 12)``, availability ``(B, T, S)`` float, offset features ``(B, S * 12)``."""
    if cfg.mapper_input == "site":
        p, R = site_poses(p, R, off_R[:, None], off_t[:, None])
    return masked_features(p, R, avail), avail.to(p.dtype), _offset_features(off_R, off_t)


def masked_features(p: torch.Tensor, R: torch.Tensor, avail: torch.Tensor) -> torch.Tensor:
    """Sensor features with unavailable samples zeroed: p ``(..., S, 3)``, R ``(..., S, 3, 3)``,
    avail ``(..., S)`` bool -> ``(..., S * 12)``."""
    m = avail[..., None].to(p.dtype)
    return sensor_features(torch.nan_to_num(p) * m, torch.nan_to_num(R) * m[..., None])


def removal_mask(B: int, T: int, S: int, g: torch.Generator) -> torch.Tensor:
    """``(B, T, S)`` bool, False where a sensor is removed: in a fraction :data:`P_REMOVE` of the
    windows, 1..:data:`MAX_REMOVED` random sensors for a random span of half the window."""
    keep = torch.ones(B, T, S, dtype=torch.bool)
    half = max(1, T // 2)
    for b in range(B):
        if float(torch.rand((), generator=g)) >= P_REMOVE:
            continue
        k = int(torch.randint(1, MAX_REMOVED + 1, (), generator=g))
        sens = torch.randperm(S, generator=g)[:k]
        a = int(torch.randint(0, T - half + 1, (), generator=g))
        keep[b, a:a + half, sens] = False
    return keep


def _perturb(joints: torch.Tensor, rots: torch.Tensor, g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Stage-2 training input noise (module doc); shapes ``(..., 20, 3)`` and ``(..., 20, 3, 3)``."""
    nj = JOINT_NOISE_M * torch.randn(joints.shape, generator=g).to(joints)
    nr = axis_angle_to_matrix(ROT_NOISE_RAD * torch.randn(joints.shape, generator=g).to(joints))
    return joints + nj, rots @ nr


def _make_task(est: TwoStageEstimator, train_data: EmposeData, val_data: EmposeData | None) -> Any:


    class TwoStageTask(EmposeTask):
        """:class:`EmposeTask` batches with the two-stage losses and validation."""

        def __init__(self, *a: Any) -> None:
            super().__init__(*a)
            self.gen = torch.Generator().manual_seed(self.cfg.seed * 7919 + 17)

        def _outputs(self, b: dict[str, torch.Tensor], device: torch.device, train: bool, g: torch.Generator):
            b = {k: v.to(device) for k, v in b.items()}
            net: TwoStageNet = self.model
            B, T, S = b["valid"].shape
            avail = b["valid"] & removal_mask(B, T, S, g).to(device)
            mj, m6, mR = net.mapper(*mapper_inputs(self.cfg, b["position"], b["orientation"], avail, b["off_R"],
                                                   b["off_t"]))
            with torch.no_grad():
                body = self.est.body(b["pose"].reshape(B * T, NUM_JOINTS, 3, 3),
                                     b["betas"][:, None].expand(B, T, NUM_BETAS).reshape(B * T, -1), None,
                                     return_vertices=False)
                gj = body.joints.reshape(B, T, NUM_JOINTS, 3)[:, :, list(PRED_JOINTS)]
                gR = body.global_rot.reshape(B, T, NUM_JOINTS, 3, 3)[:, :, list(PRED_JOINTS)]
            if net.ik is None:  # closed form: joints of the mapped orientations on the window's shape
                rest = self.est.body.rest_joints(b["betas"] if train else None)
                _, fj = forward_kinematics(closed_form_pose(mR), rest[:, None] if train else rest)
                return mj, m6, gj, gR, fj, b
            if train:
                ij, iR = _perturb(gj, gR, g)  # stage 2 learns from perturbed ground truth
            else:
                ij, iR = mj.detach(), mR.detach()  # validation: the whole pipeline
            outs = _ik(net, self.est.joint_sensors, ij, iR, train)
            return mj, m6, gj, gR, outs, b

        def loss(self, batch: dict[str, torch.Tensor], device: torch.device):
            mj, m6, gj, gR, outs, b = self._outputs(batch, device, True, self.gen)
            l_map_j = ((mj - gj) ** 2).mean()
            l_map_r = ((m6 - matrix_to_rot6d(gR)) ** 2).mean()
            if self.model.ik is None:
                l_fk = ((outs[..., list(PRED_JOINTS), :] - gj) ** 2).mean()
                parts = {"map_joints": float(l_map_j.detach()), "map_rot": float(l_map_r.detach()),
                         "fk_joints": float(l_fk.detach())}
                return MAP_JOINT_WEIGHT * l_map_j + l_map_r + FK_JOINT_WEIGHT * l_fk, parts
            l_ik, parts = lgd_loss(outs, b["pose"], b["betas"], b["joints"], self.cfg)
            parts.update(map_joints=float(l_map_j.detach()), map_rot=float(l_map_r.detach()))
            return MAP_JOINT_WEIGHT * l_map_j + l_map_r + l_ik, parts

        @torch.no_grad()
        def validate(self, device: torch.device) -> dict[str, float]:
            if self.val_data is None:
                return {}
            self.model.eval()
            g = torch.Generator().manual_seed(12345)  # the same removals every epoch
            pe, pm = [], []
            for b in self.val_data.iter_batches(self.cfg.seq_len, self.cfg.seq_len, max(self.cfg.batch_size, 32),
                                                shuffle=False):
                mj, _, gj, _, outs, b = self._outputs(b, device, False, g)
                # ik="closed": the closed form on the mean shape (no betas fit / polish: cheap, per window)
                final = outs if self.model.ik is None else outs[-1]["joints"]
                pe.append(mpjpe(final, b["joints"], MAJOR_JOINTS).flatten())
                pm.append(((mj - gj).norm(dim=-1).mean(-1)).flatten())
            self.model.train()
            cat = lambda xs: torch.cat(xs) if xs else torch.zeros(0)  # noqa: E731
            mpe = float(cat(pe).mean()) * 1000
            return {"val_mpjpe_mm": mpe if math.isfinite(mpe) else math.inf,
                    "val_mapper_joint_err_mm": float(cat(pm).mean()) * 1000}

    return TwoStageTask(est, train_data, val_data)


def _ik(net: TwoStageNet, sensors: JointSensors, joints: torch.Tensor, rots: torch.Tensor, train: bool
        ) -> list[dict[str, torch.Tensor]]:
    """Stage 2 on ``(B, T, 20, 3)`` joints and ``(B, T, 20, 3, 3)`` orientations."""
    B, T = joints.shape[:2]
    x = sensor_features(joints, rots)
    eye = torch.eye(3, dtype=joints.dtype, device=joints.device).expand(B, NUM_MAPPED, 3, 3)
    zero = joints.new_zeros(B, NUM_MAPPED, 3)
    outs, _ = net.ik(x, joints, rots, eye, zero, sensors, train=train)
    return outs


@register_estimator("empose-twostage")
class TwoStageEstimator(EmposeEstimator):
    """The two-stage EM-POSE model behind the Estimator protocol (module doc). Offline only."""

    name = "empose-twostage"
    causal = False
    lookahead = 0

    def __init__(self, config: EmposeConfig | None = None, body: Any = None, device: str | torch.device = "cpu") -> None:
        config = config or twostage_config("cpu", 12)
        if config.model != "twostage":
            raise ConfigError(f"TwoStageEstimator needs EmposeConfig.model='twostage', got {config.model!r}")
        super().__init__(config, body=body, device=device)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = TwoStageNet(self.config, len(self.sensor_names), self.body.rest_joints().cpu()).to(self.device)
        self.joint_sensors = JointSensors(self.body)

    def make_task(self, train_data: EmposeData, val_data: EmposeData | None) -> Any:
        """The training task for :func:`~wearpose.estimators.empose.train.train_empose`."""
        return _make_task(self, train_data, val_data)

    @torch.no_grad()
    def estimate(self, recording: Any, chunk: int = 4096) -> PoseTrack:
        """Offline estimate; every frame gets a pose, missing sensors included.

        Returns a :class:`PoseTrack`: ``local_rot`` ``(T, 24, 3, 3)`` (root in the EM source
        frame), ``betas`` ``(10,)`` (mean over frames; ``ik="closed"``: the sequence fit),
        ``trans=None``, ``valid`` all True; ``extras``: ``frame="em_source"``, ``method``,
        ``sensors_valid`` ``(T, S)``, ``mapper_joints`` ``(T, 20, 3)``, ``rec_loss`` ``(T,)``
        (stage-2 L_r; ``ik="closed"``: squared joint residual to the mapper, m^2), ``ik``.
        """
        p, R, valid = self._measurements(recording, hold=False)
        offR, offt = self._offsets_from(recording)
        dev = self.device
        self.model.eval()
        mj, _, mR = self.model.mapper(*mapper_inputs(self.config, p[None].to(dev), R[None].to(dev), valid[None].to(dev),
                                                     offR[None].to(dev), offt[None].to(dev)))
        T = p.shape[0]
        extras = {"frame": "em_source", "method": self.name, "sensors_valid": valid, "mapper_joints": mj[0].cpu(),
                  "ik": self.config.ik}
        if self.model.ik is None:
            local = closed_form_pose(mR[0])
            beta = fit_betas(self.body, local, mj[0], SHAPE_PRIOR)
            local, res = polish_pose(self.body, local, beta, mj[0], mR[0], POLISH_ITERS, POLISH_ROT_WEIGHT)
            return PoseTrack(local.cpu(), beta.cpu(), None, torch.ones(T, dtype=torch.bool), self.fps,
                             extras={**extras, "rec_loss": res.cpu(), "betas_per_frame": beta.cpu().expand(T, -1)})
        x = sensor_features(mj, mR)
        omega0, _ = self.model.ik.initial(x)
        rots, betas, rec = [], [], []
        for a in range(0, T, chunk):
            b = min(T, a + chunk)
            n = b - a
            eye = torch.eye(3, device=dev).expand(n, NUM_MAPPED, 3, 3)
            outs = self.model.ik.refine(omega0[0, a:b], x[0, a:b], mj[0, a:b], mR[0, a:b], eye,
                                        torch.zeros(n, NUM_MAPPED, 3, device=dev), self.joint_sensors, train=False)
            rots.append(outs[-1]["local_rot"].detach())
            betas.append(outs[-1]["betas"].detach())
            rec.append(outs[-1]["rec"].detach())
        local_rot, b_all = torch.cat(rots).cpu(), torch.cat(betas).cpu()
        return PoseTrack(local_rot, b_all.mean(0), None, torch.ones(T, dtype=torch.bool), self.fps,
                         extras={**extras, "rec_loss": torch.cat(rec).cpu(), "betas_per_frame": b_all})

    def step(self, frame: SensorFrame) -> PoseFrame:

        raise OfflineOnlyError("empose-twostage has a bidirectional joint mapper (non-causal): use "
                               "estimate(recording) on a whole sequence; for streaming use empose (LGD-RNN)")


def warm_start(est: TwoStageEstimator, path: Any) -> dict[str, Any] | None:
    """Initialise ``est`` from another two-stage checkpoint (e.g. an ``ik="lgd"`` run warm-starting
    an ``ik="closed"`` one): every tensor whose name and shape match is copied (the mapper; the LGD
    IK when both have one). Kit and body asset must match.

    Returns the checkpoint's Adam state restricted to ``est``'s parameters when it has one for all
    of them (a ``last.pt``), else None. Why: a fresh Adam's first step moves *every* weight by
    ``lr`` (m / sqrt(v) = +-1), which on val took the warm mapper from 12 to 45 mm in one step at
    lr 2e-4; the old moments keep the steps the size they were.
    """

    ck = load_checkpoint(path)
    ck.check(method=est.name, kit=est.kit_name, body_asset=est.body_asset_id, path=path)
    own = est.model.state_dict()
    copied = [k for k, v in ck.weights.items() if k in own and own[k].shape == v.shape]
    lacking = sorted(k for k in own if k.startswith("mapper.") and k not in copied)
    if lacking:
        raise CheckpointMismatchError(f"{path}: joint-mapper tensors {lacking} missing or of another shape "
                                      f"(hidden there {ck.config.get('hidden')}, here {est.config.hidden})")
    est.model.load_state_dict({**own, **{k: ck.weights[k] for k in copied}})
    est.meta["warm_start"] = {"checkpoint": str(path), "tensors": len(copied), "epoch": ck.meta.get("epoch"),
                              "val_mpjpe_mm": ck.meta.get("val_mpjpe_mm")}
    opt = (ck.train_state or {}).get("optimizer")
    if not opt:
        return None
    # Rebuild the source model to map its optimizer indices (parameters() order) to names.
    src = TwoStageNet(EmposeConfig.from_dict(ck.config), len(est.sensor_names), est.body.rest_joints().cpu())
    src_idx = {n: i for i, (n, _) in enumerate(src.named_parameters())}
    state = {}
    for i, (n, prm) in enumerate(est.model.named_parameters()):
        st = opt["state"].get(src_idx.get(n, -1))
        if st is None or st["exp_avg"].shape != prm.shape:
            return None
        state[i] = st
    group = {**opt["param_groups"][0], "params": list(range(len(state)))}
    est.meta["warm_start"]["optimizer"] = True
    return {"state": state, "param_groups": [group]}


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """``wearpose train empose-twostage``: train a two-stage model for ``--sensors`` sensors with
    stage 2 ``--ik`` and mapper input ``--mapper-input``, optionally warm-started from ``--init``
    (:func:`warm_start`; a ``last.pt`` there carries its Adam moments into the new run, which
    then starts as a resume at step 0). ``wearpose train empose --model twostage`` trains the
    default (``ik="lgd"``) from scratch.

    Returns:
        :func:`~wearpose.estimators.empose.train.train_empose`'s result with ``method``,
        ``sensors`` and ``config``.
    """


    if run.out is None:
        raise OptionError("--out", "the run directory is required (a warm start writes its last.pt there)")
    if opts["ik"] not in ("lgd", "closed"):
        raise OptionError("--ik", f"expected lgd or closed, got {opts['ik']!r}")
    if opts["mapper_input"] not in ("raw", "site"):
        raise OptionError("--mapper-input", f"expected raw or site, got {opts['mapper_input']!r}")
    mod = sys.modules[__name__]
    fk_was = mod.FK_JOINT_WEIGHT
    if opts["fk_weight"] is not None:
        mod.FK_JOINT_WEIGHT = opts["fk_weight"]  # read by the task's loss at every step; restored below
    try:
        cfg = twostage_config(run.config, opts["sensors"]).override(
            ik=opts["ik"], mapper_input=opts["mapper_input"], lr=opts["lr"],
            **run.config_overrides())
        est = TwoStageEstimator(cfg)
        est.meta["fk_joint_weight"] = mod.FK_JOINT_WEIGHT
        loop = {**run.loop(), "limit_val": opts["limit_val"], "max_steps": opts["max_steps"]}
        out = Path(run.out)
        if opts["init"] and not (run.resume and (out / "last.pt").is_file()):
            opt = warm_start(est, opts["init"])
            if run.console is not None:
                run.console.print(f"warm start from {opts['init']}: {est.meta['warm_start']}")
            if opt is not None:
                # Start the run as a resume at step 0 carrying the old Adam moments (warm_start doc).
                est.train_command = run.train_command
                out.mkdir(parents=True, exist_ok=True)
                save_checkpoint(est.checkpoint({}, {"epoch": 0, "step_in_epoch": 0, "global_step": 0, "optimizer": opt,
                                                    "best": math.inf, "history": []}), out / "last.pt")
                loop["resume"] = True
        res = train_empose(est, out, **loop)
    finally:
        mod.FK_JOINT_WEIGHT = fk_was
    return {"method": est.name, "sensors": opts["sensors"], "config": cfg.to_dict(), **res}
