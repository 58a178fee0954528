"""Sensor trajectories from motion: world poses of body sites at the EM rate, and the same poses
relative to an EM source (on the head, as in MI-Poser, or fixed in the room).

These are the interference-free ground truth every other part of :mod:`wearpose.interference`
starts from (the field simulation, the IMU, the N-BEATS training windows).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Sequence

import torch

from wearpose.errors import ConfigError, ShapeError
from wearpose.motion.resample import resample
from wearpose.motion.sequence import MotionSequence
from wearpose.sensors.em import relative_to_source

#: EM tracking rate of MI-Poser's sensors (Sec. 4.1: "We run the tracking at 120 fps").
EM_RATE = 120.0


@dataclass
class SiteTrajectories:
    """World poses of sensor sites and of the EM source, float64.

    Attributes:
        names: sensor site names, in order.
        R: ``(T, S, 3, 3)`` sensor orientation ``R_WS`` (sensor -> world).
        p: ``(T, S, 3)`` sensor position, m, world (Y up).
        src_R: ``(T, 3, 3)`` source orientation (source -> world).
        src_p: ``(T, 3)`` source position, m, world.
        fps: Hz.
    """

    names: tuple[str, ...]
    R: torch.Tensor
    p: torch.Tensor
    src_R: torch.Tensor
    src_p: torch.Tensor
    fps: float

    @property
    def num_frames(self) -> int:
        return int(self.R.shape[0])

    def relative(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Sensor poses in the source frame: ``R (T, S, 3, 3)``, ``p (T, S, 3)``."""
        return relative_to_source(self.R, self.p, self.src_R, self.src_p)


def body_trajectories(motion: MotionSequence, body: Any, sites: Sequence[str], *, source: str = "head",
                      source_pose: tuple[torch.Tensor, torch.Tensor] | None = None,
                      fps: float = EM_RATE) -> SiteTrajectories:
    """Site trajectories of a body performing ``motion``, resampled to ``fps``.

    Args:
        motion: the motion.
        body: a :class:`wearpose.body.BodyModel` with the named sites.
        sites: sensor sites (e.g. ``("left_wrist", "right_wrist")``).
        source: ``"head"`` (source rides on the head site, MI-Poser's glasses) or ``"world"``
            (fixed in the room at ``source_pose``, as in MI-Poser's User Study 2).
        source_pose: ``(R (3, 3), p (3,))`` of a world-fixed source; default: 0.3 m in front of
            the first frame's head, same orientation as the world.
        fps: output rate, Hz.
    """
    if source not in ("head", "world"):
        raise ConfigError(f"body_trajectories: source must be 'head' or 'world', got {source!r}")
    missing = [s for s in sites if s not in body.site_names]
    if missing:
        raise ConfigError(f"body_trajectories: sites {missing} not on the body; available: {list(body.site_names)}")
    if source == "head" and "head" in sites:
        raise ConfigError("body_trajectories: the EM source rides on the head, so 'head' cannot also be an EM sensor "
                          "(its pose in the source frame is constant); use source='world' or drop 'head'")
    m = motion if abs(motion.fps - fps) < 1e-9 else resample(motion, fps)
    names = list(dict.fromkeys([*sites, "head"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        so = body.sites(m.pose, m.betas, m.trans, names)
    P, R = so.positions.to(torch.float64), so.rotations.to(torch.float64)
    idx = [names.index(s) for s in sites]
    T = P.shape[0]
    if source == "head":
        h = names.index("head")
        sR, sp = R[:, h].clone(), P[:, h].clone()
    else:
        if source_pose is None:
            R0 = torch.eye(3, dtype=torch.float64)
            p0 = P[0, names.index("head")] + torch.tensor([0.0, 0.0, 0.3], dtype=torch.float64)
        else:
            R0, p0 = (torch.as_tensor(x, dtype=torch.float64) for x in source_pose)
            if R0.shape != (3, 3) or p0.shape != (3,):
                raise ShapeError(f"body_trajectories: source_pose must be (R (3, 3), p (3,)), got {tuple(R0.shape)}, {tuple(p0.shape)}")
        sR, sp = R0.expand(T, 3, 3).clone(), p0.expand(T, 3).clone()
    return SiteTrajectories(tuple(sites), R[:, idx].contiguous(), P[:, idx].contiguous(), sR, sp, float(fps))
