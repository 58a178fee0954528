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

:class:`TwoStageEstimator` (registry ``empose-twostage``) is offline (bidirectional mapper) and
returns a pose for every frame, including those with missing sensors (``valid`` is all True;
``extras["sensors_valid"]`` keeps the input mask).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch
from torch import nn

from wearpose.body.skeleton import NUM_JOINTS
from wearpose.errors import ConfigError
from wearpose.estimators.base import PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.data import EmposeData
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.empose.model import (
    LGDRNN, NUM_BETAS, PRED_JOINTS, SENSOR_FEATURES, lgd_loss, sensor_features,
)
from wearpose.estimators.registry import register_estimator
from wearpose.geometry import axis_angle_to_matrix, matrix_to_rot6d, rot6d_to_matrix

NUM_MAPPED = len(PRED_JOINTS)  # 20 joints: positions + orientations from the mapper
JOINT_NOISE_M = 0.015  #: std of the position perturbation of stage-2 training inputs, m
ROT_NOISE_RAD = 0.05  #: std per axis of the orientation perturbation of stage-2 training inputs, rad
MAP_JOINT_WEIGHT = 20.0  #: weight of the mapper's joint MSE (m^2) against its 6D orientation MSE
MAX_REMOVED = 3  #: sensors removed per training window: 1..MAX_REMOVED
P_REMOVE = 0.8  #: fraction of training windows with removed sensors


def twostage_config(preset: str, sensors: int) -> EmposeConfig:
    """``EmposeConfig.preset(preset, sensors)`` with ``model="twostage"``: ``hidden`` /
    ``rnn_layers`` size the mapper BiLSTM (per direction) and the stage-2 LSTM, ``width`` /
    ``mlp_layers`` / ``iterations`` the stage-2 update network; the cpu preset uses N = 2."""
    base = EmposeConfig.preset(preset, sensors)
    kw: dict[str, Any] = {"model": "twostage"}
    if preset == "cpu":
        kw.update(iterations=2)
    return replace(base, **kw)


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
        self.ik = LGDRNN(cfg, NUM_MAPPED)
        self.ik.lean_inference = False  # the closed-form kernel is for skin sites; IK is FK only


def _offset_features(off_R: torch.Tensor, off_t: torch.Tensor) -> torch.Tensor:
    """``(B, S, 3, 3)``, ``(B, S, 3)`` -> ``(B, S * 12)``."""
    return sensor_features(off_t, off_R)


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
    import math

    from wearpose.body.skeleton import MAJOR_JOINTS
    from wearpose.estimators.empose.train import EmposeTask
    from wearpose.evaluate import mpjpe

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
            feats = masked_features(b["position"], b["orientation"], avail)
            mj, m6, mR = net.mapper(feats, avail.float(), _offset_features(b["off_R"], b["off_t"]))
            with torch.no_grad():
                body = self.est.body(b["pose"].reshape(B * T, NUM_JOINTS, 3, 3),
                                     b["betas"][:, None].expand(B, T, NUM_BETAS).reshape(B * T, -1), None,
                                     return_vertices=False)
                gj = body.joints.reshape(B, T, NUM_JOINTS, 3)[:, :, list(PRED_JOINTS)]
                gR = body.global_rot.reshape(B, T, NUM_JOINTS, 3, 3)[:, :, list(PRED_JOINTS)]
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
                pe.append(mpjpe(outs[-1]["joints"], b["joints"], MAJOR_JOINTS).flatten())
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
        self.model = TwoStageNet(self.config, len(self.sensor_names), self.body.rest_joints().cpu()).to(self.device)
        self.joint_sensors = JointSensors(self.body)

    def make_task(self, train_data: EmposeData, val_data: EmposeData | None) -> Any:
        """The training task for :func:`~wearpose.estimators.empose.train.train_empose`."""
        return _make_task(self, train_data, val_data)

    @torch.no_grad()
    def estimate(self, recording: Any, chunk: int = 4096) -> PoseTrack:
        """Offline estimate; every frame gets a pose, missing sensors included.

        Returns a :class:`PoseTrack`: ``local_rot`` ``(T, 24, 3, 3)`` (root in the EM source
        frame), ``betas`` ``(10,)`` (mean over frames), ``trans=None``, ``valid`` all True;
        ``extras``: ``frame="em_source"``, ``method``, ``sensors_valid`` ``(T, S)``,
        ``mapper_joints`` ``(T, 20, 3)``, ``rec_loss`` ``(T,)`` (stage-2 L_r).
        """
        p, R, valid = self._measurements(recording, hold=False)
        offR, offt = self._offsets_from(recording)
        dev = self.device
        self.model.eval()
        feats = masked_features(p, R, valid).to(dev)
        mj, _, mR = self.model.mapper(feats[None], valid.float()[None].to(dev), _offset_features(offR[None], offt[None]).to(dev))
        T = p.shape[0]
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
                         extras={"frame": "em_source", "method": self.name, "sensors_valid": valid,
                                 "mapper_joints": mj[0].cpu(), "rec_loss": torch.cat(rec).cpu(),
                                 "betas_per_frame": b_all})

    def step(self, frame: SensorFrame) -> PoseFrame:
        from wearpose.estimators.empose.baselines import OfflineOnlyError

        raise OfflineOnlyError("empose-twostage has a bidirectional joint mapper (non-causal): use "
                               "estimate(recording) on a whole sequence; for streaming use empose (LGD-RNN)")
