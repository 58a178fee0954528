"""The AvatarPoser-style IK network of MI-Poser (Sec. 4.2; Jiang et al. 2022) and its loss.

Input (:func:`window_features`): a window of ``W`` frames of the calibrated head and wrist
target-joint poses (SMPL joints 15, 20, 21; a wrist's rotation is its forearm's), re-expressed
in the *heading frame* of the window's last frame: rotated about +Y so that the head faces +Z
and shifted so that the head is above the origin (its height is kept). Per sensor and frame, as
AvatarPoser: the rotation (6D), the rotation change since the previous frame (6D), the position
(m) and the velocity (m/s): 18 numbers, ``18 S`` per frame.

Network (:class:`AvatarPoserNet`): a linear embedding to ``d_model``, a learned positional
embedding, a transformer encoder (``layers`` x ``heads``), and from the last frame's token two
MLP decoders as AvatarPoser: the root orientation (6D, heading frame) and the 21 body joints'
local rotations (6D). The hands (SMPL 22/23) stay at identity. The global translation is not
regressed: as AvatarPoser, the posed body is moved so that its head joint lands on the measured
head position (:func:`head_anchored_translation`).

Loss (:func:`ik_loss`): the local rotations' term (:func:`rotation_term`: L1 on the raw 6D
numbers as AvatarPoser, or the per-joint geodesic angle with the spine weighted up), an optional
hinge on the spine's twist about the bone (:func:`twist_prior`), L1 on the root 6D, L1 on the
head-relative joint positions of the posed body (forward kinematics, m) with extra weight on
the wrists (AvatarPoser's hand term).

Why the geodesic (issue 22, docs/miposer.md): a spine joint turned 180 deg about the bone and
turned back by the joints above it leaves every joint position right, so only the rotation term
can see it. L1 on the raw 6D averaged over 126 numbers let the v1 weights sit there; L1 on the
Gram-Schmidt-normalised 6D would not help either: for a turn ``a`` about one column's axis it is
``1 - cos a + |sin a|``, which has a local minimum at 180 deg. The geodesic angle rises to 180 deg
with slope 1, so the gradient always turns the joint back.
"""

from __future__ import annotations

import torch
from torch import nn

from wearpose.body.skeleton import NUM_JOINTS
from wearpose.estimators.miposer.config import PREDICTED_JOINTS, MiposerConfig
from wearpose.geometry import heading, matrix_to_rot6d, rot6d_to_matrix, rotation_y, smooth_geodesic_angle, twist_angle

#: Numbers per sensor and frame in :func:`window_features`.
FEATURES_PER_SENSOR = 18
HEAD, LEFT_WRIST, RIGHT_WRIST = 15, 20, 21
#: SMPL spine1, spine2, spine3: the joints whose twist about the bone positions cannot tell.
SPINE = (3, 6, 9)
#: The bone axis of a local rotation in SMPL's rest pose (the spine runs along +Y).
BONE_AXIS = (0.0, 1.0, 0.0)


def heading_frame(R_head: torch.Tensor, p_head: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(C (..., 3, 3), o (..., 3))``: world -> heading frame rotation (about +Y) and origin (the
    head's floor projection, y = 0) for head poses ``R_head`` ``(..., 3, 3)``, ``p_head`` ``(..., 3)``."""
    C = rotation_y(-heading(R_head))
    o = p_head.clone()
    o[..., 1] = 0.0
    return C.to(R_head.dtype), o


def window_features(R: torch.Tensor, p: torch.Tensor, fps: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Network input of windows (module doc).

    Args:
        R: ``(B, W, S, 3, 3)`` calibrated rotations, head first. p: ``(B, W, S, 3)`` m.
        fps: frame rate, Hz (velocities in per-second units).

    Returns:
        ``(x (B, W, 18 S), C (B, 3, 3), o (B, 3))``: features, and the heading frame of each
        window's last frame (world -> heading rotation, origin).
    """
    C, o = heading_frame(R[:, -1, 0], p[:, -1, 0])
    Rc = C[:, None, None] @ R
    pc = ((p - o[:, None, None]).unsqueeze(-1).transpose(-1, -2) @ C[:, None, None].transpose(-1, -2)).squeeze(-2)
    dR = Rc[:, :-1].transpose(-1, -2) @ Rc[:, 1:]
    dR = torch.cat([torch.eye(3, dtype=R.dtype, device=R.device).expand_as(Rc[:, :1]), dR], 1)
    v = torch.cat([torch.zeros_like(pc[:, :1]), (pc[:, 1:] - pc[:, :-1]) * fps], 1)
    x = torch.cat([matrix_to_rot6d(Rc), matrix_to_rot6d(dR), pc, v], -1)
    return x.flatten(2), C, o


def _mlp(d_in: int, d_hidden: int, d_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d_in, d_hidden), nn.LeakyReLU(0.1), nn.Linear(d_hidden, d_out))


class AvatarPoserNet(nn.Module):
    """Transformer encoder over the window, decoders on the last frame (module doc).

    ``forward(x (B, W, F)) -> (root6 (B, 6), local6 (B, 21, 6))``; with ``cfg.dense`` the
    encoder is causally masked and ``forward(x, every_frame=True)`` decodes every frame,
    ``(root6 (B, W, 6), local6 (B, W, 21, 6))``.
    """

    def __init__(self, cfg: MiposerConfig, sensors: int) -> None:
        super().__init__()
        d = cfg.d_model
        self.embed = nn.Linear(FEATURES_PER_SENSOR * sensors, d)
        self.pos = nn.Parameter(torch.zeros(1, cfg.window, d))
        layer = nn.TransformerEncoderLayer(d, cfg.heads, cfg.ff, cfg.dropout, batch_first=True)
        self.encoder = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.root = _mlp(d, d, 6)
        self.joints = _mlp(d, d, 6 * (PREDICTED_JOINTS - 1))
        self.dense = cfg.dense

    def forward(self, x: torch.Tensor, every_frame: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        W = x.shape[1]
        mask = nn.Transformer.generate_square_subsequent_mask(W, device=x.device, dtype=x.dtype) if self.dense else None
        h = self.encoder(self.embed(x) + self.pos[:, -W:], mask=mask, is_causal=self.dense)
        h = h if every_frame else h[:, -1]
        return self.root(h), self.joints(h).reshape(*h.shape[:-1], PREDICTED_JOINTS - 1, 6)


def decode_pose(root6: torch.Tensor, local6: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
    """``(B, 24, 3, 3)`` local rotations: root from the heading frame back to the world
    (``C^T R``), 21 body joints, identity hands."""
    B = root6.shape[0]
    out = torch.eye(3, dtype=root6.dtype, device=root6.device).repeat(B, NUM_JOINTS, 1, 1)
    out[:, 0] = C.transpose(-1, -2) @ rot6d_to_matrix(root6)
    out[:, 1:PREDICTED_JOINTS] = rot6d_to_matrix(local6)
    return out


def head_anchored_translation(body: object, pose: torch.Tensor, p_head: torch.Tensor) -> torch.Tensor:
    """Root translation ``(..., 3)`` that puts the posed body's head joint (SMPL 15, mean shape)
    on the measured head position ``p_head`` ``(..., 3)`` m (AvatarPoser)."""
    J = body(pose, None, None, return_vertices=False).joints  # type: ignore[operator]
    return p_head - J[..., HEAD, :]


def rotation_term(local6: torch.Tensor, gt6: torch.Tensor, cfg: MiposerConfig) -> torch.Tensor:
    """The local rotations' loss of ``local6`` against ``gt6``, both ``(N, 21, 6)`` (SMPL joints 1..21).

    ``cfg.rot_loss == "l1_6d"``: mean absolute difference of the raw numbers (AvatarPoser, the v1
    weights). ``"geodesic"``: per joint the angle (rad) between the Gram-Schmidt rotations
    (:func:`~wearpose.geometry.smooth_geodesic_angle`), the :data:`SPINE` joints weighted by
    ``cfg.spine_rot_weight``, summed over joints / 21 and averaged over ``N``.
    """
    if cfg.rot_loss == "l1_6d":
        return (local6 - gt6).abs().mean()
    ang = smooth_geodesic_angle(rot6d_to_matrix(local6), rot6d_to_matrix(gt6))  # (N, 21) rad
    w = torch.ones(ang.shape[-1], dtype=ang.dtype, device=ang.device)
    w[[j - 1 for j in SPINE]] = cfg.spine_rot_weight
    return (ang * w).sum(-1).mean() / ang.shape[-1]


def twist_prior(local6: torch.Tensor, cfg: MiposerConfig) -> torch.Tensor:
    """Hinge on the :data:`SPINE` joints' twist about the bone beyond ``cfg.twist_limit_deg``
    (rad, mean over joints and ``N``) of the predicted ``local6`` ``(N, 21, 6)``: a prior where
    the joint positions cannot tell (the training targets stay within ~40 deg)."""
    R = rot6d_to_matrix(local6[:, [j - 1 for j in SPINE]])
    tw = twist_angle(R, torch.tensor(BONE_AXIS))
    return torch.relu(tw - torch.deg2rad(torch.tensor(cfg.twist_limit_deg, dtype=tw.dtype))).mean()


def ik_loss(net_out: tuple[torch.Tensor, torch.Tensor], C: torch.Tensor, gt_pose6: torch.Tensor, body: object,
            cfg: MiposerConfig) -> tuple[torch.Tensor, dict[str, float], torch.Tensor, torch.Tensor]:
    """Loss of one batch (module doc).

    Args:
        net_out: ``(root6 (B, 6), local6 (B, 21, 6))``, or per frame ``(B, K, 6)`` /
            ``(B, K, 21, 6)``; C: ``(B, 3, 3)`` heading frames;
        gt_pose6: ``(B, 22, 6)`` (or ``(B, K, 22, 6)``) ground truth (root in the world);
        body: the body model.

    Returns:
        ``(loss, parts, pred_joints (N, 24, 3), gt_joints (N, 24, 3))``, ``N`` = ``B`` or ``B K``;
        joints at zero translation in the world (for metrics).
    """
    root6, local6 = net_out
    if root6.dim() == 3:  # every frame: flatten (B, K) with the window's heading frame repeated
        K = root6.shape[1]
        C = C[:, None].expand(-1, K, 3, 3).reshape(-1, 3, 3)
        root6, local6, gt_pose6 = root6.reshape(-1, 6), local6.reshape(-1, *local6.shape[2:]), gt_pose6.reshape(-1, *gt_pose6.shape[2:])
    gt_R = rot6d_to_matrix(gt_pose6)
    gt_root_c = matrix_to_rot6d(C @ gt_R[:, 0])
    l_rot = rotation_term(local6, gt_pose6[:, 1:], cfg)
    l_root = (root6 - gt_root_c).abs().mean()
    pose = decode_pose(root6, local6, C)
    gt = torch.eye(3, dtype=gt_R.dtype, device=gt_R.device).repeat(gt_R.shape[0], NUM_JOINTS, 1, 1)
    gt[:, :PREDICTED_JOINTS] = gt_R
    J = body(pose, None, None, return_vertices=False).joints  # type: ignore[operator]
    with torch.no_grad():
        Jg = body(gt, None, None, return_vertices=False).joints  # type: ignore[operator]
    d = ((J - J[:, HEAD:HEAD + 1]) - (Jg - Jg[:, HEAD:HEAD + 1])).abs()
    l_pos = d[:, :PREDICTED_JOINTS].mean()
    l_hand = d[:, [LEFT_WRIST, RIGHT_WRIST]].mean()
    loss = cfg.lambda_rot * l_rot + cfg.lambda_root * l_root + cfg.lambda_pos * l_pos + cfg.lambda_hand * l_hand
    terms = [("l_rot", l_rot), ("l_root", l_root), ("l_pos", l_pos), ("l_hand", l_hand)]
    if cfg.lambda_twist:
        l_twist = twist_prior(local6, cfg)
        loss = loss + cfg.lambda_twist * l_twist
        terms.append(("l_twist", l_twist))
    parts = {k: float(v.detach()) for k, v in terms}
    return loss, parts, J, Jg
