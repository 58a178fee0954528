"""Foot skate of retargeted motion: do planted feet stay planted after retargeting?

Used by ``benchmarks/foot_skate.py`` (per corpus source, before and after the root-travel fix of
issue 23) and by the body-shape tests (``tests/sensors/test_body_shapes.py``).

For one retargeted clip (:class:`wearpose.motion.Retargeted`) :func:`clip_foot_skate` measures,
with :func:`wearpose.evaluate.metrics.stance_foot_speed` (stance from heights only, middle half
of each stance):

- the source's own floor points (its toe joints, else ankles: the joints SMPL's ``left_foot`` /
  ``right_foot``, else ``left_ankle`` / ``right_ankle``, are mapped to), in the source's metres;
- the same SMPL joints of the retargeted motion, with the root path of every requested
  ``travel`` mode of :func:`wearpose.motion.retarget.root_path` (``"height"`` = the converter
  before motion-4);
- PIP's contact labels on that motion (:func:`wearpose.estimators.pip.data.root_frame_targets`
  at PIP's 60 Hz, default :class:`~wearpose.estimators.pip.config.PipConfig`): the fraction of
  frames whose *lower* foot is labelled "not in contact" (docs/pip.md: 44 % on CMU walks).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from dataclasses import replace

import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.evaluate.metrics import stance_foot_speed
from wearpose.motion.resample import resample
from wearpose.motion.retarget import TRAVEL_MODES, Retargeted, foot_joint_pairs, root_path
from wearpose.motion.sequence import MotionSequence


def lower_foot_contact_misses(pose: torch.Tensor, trans: torch.Tensor, rest_joints: torch.Tensor, fps: float
                              ) -> dict[str, float]:
    """How often PIP's contact rule calls the lower SMPL foot joint "not in contact".

    Args:
        pose: ``(T, 24, 3, 3)``; trans: ``(T, 3)`` m; rest_joints: ``(24, 3)`` m; fps: Hz. The
            motion is resampled to PIP's rate first, as its training data are.

    Returns:
        ``{"miss": fraction of frames whose lower foot is labelled not in contact, "speed": ...
        failing the speed test alone, "height": ... failing the height test alone}``.
    """
    # start-up: PIP's config/data and physics.reference add ~194 ms (43 modules) to import this module
    from wearpose.estimators.pip.config import PipConfig  # noqa: PLC0415 - only for this check
    from wearpose.estimators.pip.data import root_frame_targets  # noqa: PLC0415 - start-up: as above
    from wearpose.physics.reference import FOOT_JOINTS  # noqa: PLC0415 - start-up: as above

    cfg = PipConfig()
    seq = MotionSequence(pose.float(), torch.zeros(10), trans.float(), fps)
    if abs(fps - cfg.rate) > 1e-9:
        seq = resample(seq, cfg.rate)
    _, J = forward_kinematics(seq.pose.double(), rest_joints.double())
    J = (J + seq.trans.double()[:, None]).float()
    lower = J[:, list(FOOT_JOINTS), 1].argmin(-1)[:, None]
    out = {}
    for key, c in (("miss", cfg), ("speed", replace(cfg, contact_height=float("inf"))),
                   ("height", replace(cfg, contact_speed=float("inf")))):
        contact = root_frame_targets(seq.pose.float(), J, c.rate, c)["contact"]  # (T, 2)
        out[key] = float((contact.gather(1, lower) < 0.5).float().mean())
    return out


def clip_foot_skate(res: Retargeted, rest_joints: torch.Tensor, skip_first: bool = False,
                    modes: Sequence[str] = TRAVEL_MODES, contacts: bool = True) -> dict[str, Any]:
    """Stance-foot mid-stance horizontal speed of one retargeted clip, source and SMPL per mode.

    Args:
        res: :func:`wearpose.motion.retarget_bvh` result (also ``import_motion(...).retargeted``).
        rest_joints: ``(24, 3)`` the SMPL rest joints it was retargeted to, m.
        skip_first: leave frame 0 out (the corpus' CMU T-pose frame).
        modes: root travel modes to measure (:data:`wearpose.motion.retarget.TRAVEL_MODES`).
        contacts: also :func:`lower_foot_contact_misses` per mode.

    Returns:
        ``{"fps", "frames", "source": {"median_ms", "stances"}, "<mode>": {"median_ms",
        "stances", "stance_travel_cm", "contact_miss", "contact_miss_speed",
        "contact_miss_height"}}`` (NaN medians when no stance is found).
    """
    seq = res.sequence
    pairs = foot_joint_pairs(res.smap, res.bvh_names)
    k = 1 if skip_first and seq.num_frames > 1 else 0
    src = stance_foot_speed(res.bvh_world_pos.double()[k:, [b for _, b in pairs]], seq.fps)
    out: dict[str, Any] = {"fps": seq.fps, "frames": seq.num_frames - k, "foot_joints": [res.bvh_names[b] for _, b in pairs],
                           "source": {"median_ms": src.median, "stances": src.stances}}
    _, J = forward_kinematics(seq.pose.double(), rest_joints.double())
    for mode in modes:
        tr = root_path(seq.pose, res.bvh_world_pos, res.bvh_names, res.smap, res.tpose, rest_joints, seq.fps, mode)  # type: ignore[arg-type]
        st = stance_foot_speed((J + tr[:, None])[k:, [a for a, _ in pairs]], seq.fps)
        row: dict[str, Any] = {"median_ms": st.median, "stances": st.stances,
                               "stance_travel_cm": float(st.stance_travel.median()) * 100 if st.stances else float("nan")}
        if contacts:
            cm = lower_foot_contact_misses(seq.pose[k:], tr[k:], rest_joints, seq.fps)
            row.update(contact_miss=cm["miss"], contact_miss_speed=cm["speed"], contact_miss_height=cm["height"])
        out[mode] = row
    return out


__all__ = ["clip_foot_skate", "lower_foot_contact_misses"]
