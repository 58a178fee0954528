"""Where an estimate stands: its lowest point against the truth's, once placed in the world.

A body whose joints are right on average can still have its feet under the floor or in the air
(EM-POSE's v6 put a foot 5 cm under it in one frame of a walk: docs/empose.md), and MPJPE, which
is root-relative, never sees it. :func:`floor_placement` runs a model on simulated test clips the
way ``wearpose estimate`` does (:func:`wearpose.estimators.run.estimate_recording`: a marked 1 s
T-pose first for the estimators that calibrate on one, sensors without noise, the world
placement of :func:`~wearpose.estimators.run.place_in_world`) and compares, frame by frame after the T-pose, the height of the estimate's lowest point with the
truth's (m inside, cm in the report):

- ``e = estimate's lowest point - truth's lowest point`` per frame, the truth set on its own floor
  the same way (the median lowest point of its contact frames at 0: the corpus stands its clips
  about 0.5-3 cm above y = 0 by this measure);
- what a user sees as wrong: in the frames where the truth **stands** (its lowest point within
  3 cm of its floor), ``|e|`` over 5 cm (a foot in the floor, ``e < 0``, or over it, ``e > 0``);
  in any frame, the estimate's lowest point more than 5 cm **under the floor** (y < -5 cm). A
  runner's estimate 5 cm higher than the truth in mid-air is neither;
- per clip those shares and extremes, and the median ``|e|``; over clips: the same pooled over
  frames, and how many clips have a standing frame off or a frame under the floor.

Only methods that estimate a translation are placed by a floor rule with a choice to make (the
others put every frame's lowest point on the floor); for them the same clips are also scored
under the other floor rules (``rules``: the median over every frame, the rule before contact
frames, and other contact speeds), each one constant shift of the same estimate.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import torch

from wearpose.body import BodyModel, LowestPoint
from wearpose.errors import ConfigError
from wearpose.estimators.run import (
    CONTACT_SPEED_M_S, EVERY_FRAME_ON_THE_FLOOR, ModelSource, estimate_recording, floor_height,
)
from wearpose.evaluate.conventions import kit_recording
from wearpose.motion import CorpusStore, resample

#: A frame sinks or floats when its lowest point is this far from the truth's, and is under the
#: floor when its lowest point is this far below y = 0 (m): the tolerance of the export floor check.
FLOOR_LIMIT_M = 0.05
#: The truth stands in a frame when its lowest point is within this of its floor (m).
STANDING_TOL_M = 0.03
#: A clip whose truth does not stand on y = 0 (its contact frames' median lowest point further
#: than this, m: uneven terrain, a source under its floor) is left out of the pooled figures
#: and listed: placing on a flat floor cannot be right there. The corpus's flat-floor test clips
#: stand 0.5-3 cm above y = 0 by this measure; CMU's martial-arts clips 7-15 cm under it.
TRUTH_OFF_FLOOR_M = 0.05
#: The contact speeds (m/s) scored beside the shipped one; ``None``: the median over every frame.
DEFAULT_RULES: tuple[float | None, ...] = tuple(dict.fromkeys((None, 0.2, 0.35, 0.5, 0.75, CONTACT_SPEED_M_S)))


def rule_name(speed: float | None) -> str:
    return "every frame" if speed is None else f"contact < {speed:g} m/s"


class FloorFrames(NamedTuple):
    """One clip under one floor rule, per frame after the T-pose."""

    e: torch.Tensor  #: (T,) m: the estimate's lowest point minus the truth's (the truth on its own floor)
    standing: torch.Tensor  #: (T,) bool: the truth's lowest point within STANDING_TOL_M of its floor
    height: torch.Tensor  #: (T,) m: the placed estimate's lowest point (the floor is y = 0)


def clip_floor(source: ModelSource, motion: Any, body: BodyModel, rules: tuple[float | None, ...] = DEFAULT_RULES,
               estimator: Any = None) -> dict[str, Any]:
    """One clip's :class:`FloorFrames` per rule (module doc); ``motion`` is brought to the
    model's rate first."""
    if source.fps and abs(motion.fps - source.fps) > 1e-6:
        motion = resample(motion, source.fps)
    estimator = estimator if estimator is not None else source.make()
    # a T-pose only for estimators that calibrate on one (PIP, BiRAE, MI-Poser): an EM wearer has
    # no reason to stand in one
    calibrates = hasattr(estimator, "calibration_window")
    rec = kit_recording(source.kit, motion, float(motion.fps), 1.0 if calibrates else None)
    run = estimate_recording(source, rec, estimator=estimator)
    track, truth = run.track, rec.ground_truth
    if track.num_frames != truth.num_frames:
        raise ConfigError(f"{source.name}: {track.num_frames} estimated frames for {truth.num_frames} true ones "
                          "(the floor comparison needs the model's own rate)")
    start = track.num_frames - motion.num_frames  # after the T-pose and its blend
    with torch.no_grad():
        est = run.body.lowest_point(track.local_rot.to(body.dtype), track.betas.to(body.dtype), track.trans.to(body.dtype))
        true_low = body.lowest_point(truth.pose.to(body.dtype), truth.betas.to(body.dtype), truth.trans.to(body.dtype))
    clip_truth = LowestPoint(true_low.height[start:], true_low.joint[start:], true_low.joints[start:])
    truth_floor = floor_height(clip_truth, truth.fps)[0]
    true = clip_truth.height - truth_floor  # the truth on its own floor
    placed_by_rule = track.extras.get("floor", "")
    out: dict[str, Any] = {"placement": track.extras.get("placement"), "floor": placed_by_rule, "rules": {},
                           "truth_floor_m": float(truth_floor)}
    translated = placed_by_rule != EVERY_FRAME_ON_THE_FLOOR  # else no floor rule to choose
    for speed in (rules if translated else (None,)):
        shift = floor_height(est, track.fps, speed)[0] if translated else est.height.new_zeros(())
        height = (est.height - shift)[start:]
        name = rule_name(speed) if translated else "every frame on the floor"
        out["rules"][name] = FloorFrames(height - true, true.abs() < STANDING_TOL_M, height)
    return out


def _summary(f: FloorFrames) -> dict[str, float]:
    st, lim = f.standing, FLOOR_LIMIT_M
    e_st = f.e[st] if bool(st.any()) else f.e.new_zeros(1)
    return {"median_abs_cm": float(f.e.abs().median()) * 100,
            "standing_sink_pct": float((st & (f.e < -lim)).double().mean()) * 100,
            "standing_float_pct": float((st & (f.e > lim)).double().mean()) * 100,
            "worst_standing_sink_cm": float(e_st.min()) * 100, "worst_standing_float_cm": float(e_st.max()) * 100,
            "under_floor_pct": float((f.height < -lim).double().mean()) * 100, "lowest_cm": float(f.height.min()) * 100}


def _cat(frames: list[FloorFrames]) -> FloorFrames:
    return FloorFrames(*(torch.cat([getattr(f, k) for f in frames]) for k in FloorFrames._fields))


def floor_placement(source: ModelSource, store: CorpusStore, split: str = "test", clips: list[str] | None = None,
                    rules: tuple[float | None, ...] = DEFAULT_RULES,
                    progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """``source``'s floor figures on ``clips`` of ``split`` (all when None), per floor rule.

    Returns:
        ``{"model", "kit", "split", "clip_ids", "excluded" (clips whose truth is off y = 0 by more
        than :data:`TRUTH_OFF_FLOOR_M`: not pooled), "frames" (pooled), "rules": {rule: {pooled
        :func:`_summary` figures, "clips_standing_off" (a standing frame more than 5 cm off),
        "clips_under" (a frame more than 5 cm under the floor)}}, "per_clip": [{"clip", "rules":
        {rule: figures}, "truth_floor_cm"}]}``, cm and % of frames.
    """
    if source.kit is None:
        raise ConfigError(f"{source.name}: no sensor kit (a weight-free estimator); the floor comparison simulates one")
    ids = clips if clips is not None else store.clips(split=split)
    if not ids:
        raise ConfigError(f"corpus store {store.root}: no {split!r} clips to place")
    body = BodyModel()
    pooled: dict[str, list[FloorFrames]] = {}
    per_clip, excluded = [], []
    for i, cid in enumerate(ids):
        res = clip_floor(source, store.load(cid), body, rules, estimator=source.make())  # a fresh state per clip
        per_clip.append({"clip": cid, "rules": {name: _summary(f) for name, f in res["rules"].items()},
                         "floor": res["floor"], "truth_floor_cm": res["truth_floor_m"] * 100})
        if abs(res["truth_floor_m"]) > TRUTH_OFF_FLOOR_M:
            excluded.append(cid)
        else:
            for name, f in res["rules"].items():
                pooled.setdefault(name, []).append(f)
        if progress:
            progress(i + 1, len(ids))
    if not pooled:
        raise ConfigError(f"{source.name}: every clip's truth is off the floor (by > {TRUTH_OFF_FLOOR_M * 100:g} cm)")
    lim = FLOOR_LIMIT_M
    summary = {name: {**_summary(_cat(fs)),
                      "clips_standing_off": sum(bool((f.standing & (f.e.abs() > lim)).any()) for f in fs),
                      "clips_under": sum(bool((f.height < -lim).any()) for f in fs)}
               for name, fs in pooled.items()}
    return {"model": source.name, "kit": source.kit, "split": split, "clip_ids": list(ids), "excluded": excluded,
            "frames": int(sum(len(f.e) for f in next(iter(pooled.values())))), "rules": summary, "per_clip": per_clip}
