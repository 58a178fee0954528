"""An estimate in wearpose's world: upright, facing +Z, feet on the floor (Y up, floor y = 0).

Estimators return poses in the frame their sensors give: EM-POSE relative to the EM source
(``extras["frame"] == "em_source"``), PIP and BiRAE in the calibrated IMU world with a root
translation that starts at the origin (or none), MI-Poser in the headset's calibrated world.
:func:`place_in_world` is the one step that puts any of them where a user expects a body to
stand before it is exported or drawn; ``extras["placement"]`` says how it was placed.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import torch

from wearpose.body import BodyModel
from wearpose.estimators.base import PoseTrack
from wearpose.geometry import quat_to_matrix
from wearpose.recording import Recording

#: Seconds from the start over which a track with its own translation is set on the floor.
FLOOR_WINDOW_S = 1.0


def place_in_world(est: Any, track: PoseTrack, recording: Recording, body: BodyModel | None = None) -> PoseTrack:
    """``track`` upright in the world with its feet on the floor (module doc).

    EM estimates (source frame) go through the recording's EM source pose
    (``meta["em_source"]``, as simulation stores it) when it has one; else the source is taken
    as oriented as at rest on the body, so an upright subject stands upright (its heading and
    travel are then unknown: the body turns and moves with the source). Then the track is set on
    the floor (:func:`on_the_floor`).

    Args:
        est: the estimator that made ``track`` (its ``sites`` name the EM source site).
        track: its estimate of ``recording``.
        body: the body the track plays on (default: ``est.body``, else the default body).
    """
    body = body if body is not None else (getattr(est, "body", None) or BodyModel())
    if track.extras.get("frame") == "em_source":
        track = _em_source_to_world(est, track, recording, body)
    return on_the_floor(track, body)


def on_the_floor(track: PoseTrack, body: BodyModel) -> PoseTrack:
    """``track`` moved vertically so that the body stands on the floor (y = 0).

    With a translation (the method estimates travel), one shift for the whole track: the lowest
    point of the first :data:`FLOOR_WINDOW_S` (a calibration stance when there is one) at 0, so
    jumps and stairs keep their heights. Without one, each frame's lowest point at 0.
    Lowest points: :meth:`BodyModel.lowest_height`.
    """
    rot, betas = track.local_rot.to(body.dtype), track.betas.to(body.dtype)
    if track.trans is not None:
        n = max(1, min(track.num_frames, int(round(FLOOR_WINDOW_S * track.fps))))
        with torch.no_grad():
            low = body.lowest_height(rot[:n], betas, track.trans[:n].to(body.dtype)).min()
        trans = track.trans.clone()
        trans[:, 1] -= low.to(trans.dtype)
        return replace(track, trans=trans, extras={**track.extras, "floor": "first second on y = 0"})
    with torch.no_grad():
        low = body.lowest_height(rot, betas, None)
    trans = torch.zeros(track.num_frames, 3, dtype=track.local_rot.dtype)
    trans[:, 1] = -low.to(trans.dtype)
    return replace(track, trans=trans, extras={**track.extras, "floor": "every frame on y = 0 (no translation estimated)"})


def _em_source_to_world(est: Any, track: PoseTrack, rec: Recording, body: BodyModel) -> PoseTrack:
    src = ((rec.meta or {}).get("em_source") or {}).get("rates", {}).get(f"{float(track.fps):g}")
    if src is not None and hasattr(est, "to_world") and len(src["position_m"]) == track.num_frames:
        R = quat_to_matrix(torch.as_tensor(np.asarray(src["orientation_wxyz"], np.float32)))
        out = est.to_world(track, R, torch.as_tensor(np.asarray(src["position_m"], np.float32)))
        return replace(out, extras={**out.extras, "placement": "world, via the recorded EM source pose"})
    site = (getattr(est, "sites", None) or {}).get("<em_source>")
    if site is None:
        return track
    with torch.no_grad():
        R_rest = body.sites(None, track.betas.to(body.dtype), None, [site]).rotations[0]
    rot = track.local_rot.clone()
    rot[:, 0] = R_rest.to(rot.dtype) @ rot[:, 0]
    return replace(track, local_rot=rot, extras={**track.extras, "frame": "world",
                                                 "placement": "upright: EM source as at rest on the body"})
