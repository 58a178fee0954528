"""Declared conventions give the same estimate: a recording and its copies written in a
device's own units and frames (each declared, ``docs/formats.md``) against its canonical form,
through the one estimate path (:func:`wearpose.estimators.run.estimate_recording`).

Issue 21 found two shipped estimators ignoring the declaration (2.88 and 1714 apart); this is the
check that they no longer do, for ``tests/cli/test_cmd_estimate.py`` and
``benchmarks/declared_units.py``.
"""

from __future__ import annotations

import warnings
from typing import Any, Mapping

import numpy as np

from wearpose.estimators.run import ModelSource, estimate_recording

#: Every non-canonical convention of the recording format, with positions in mm and in cm:
#: deg/s, g, sensor-frame acceleration with gravity included, a Z-up world.
_REST = dict(gyro_unit="deg/s", acc_unit="g", acc_frame="sensor", acc_gravity="included", world_up="z_up")
DECLARATIONS: dict[str, dict[str, str]] = {"mm": {"position_unit": "mm", **_REST},
                                           "cm": {"position_unit": "cm", **_REST}}


def kit_recording(kit: str, motion: Any, fps: float, tpose_s: float | None = 1.0, seed: int = 2) -> Any:
    """``motion`` after a marked ``tpose_s`` T-pose (none when None), every sensor of ``kit``
    simulated at ``fps`` without noise (canonical form), the motion as ground truth."""
    # start-up: body, recording and sensors add ~70 ms (26 modules) to import this module
    from wearpose.body import BodyModel
    from wearpose.recording import CALIBRATION_WINDOW_KEY, Recording, prepend_tpose  # start-up: as above
    from wearpose.sensors import simulate  # start-up: as above

    m, window = prepend_tpose(motion, tpose_s) if tpose_s is not None else (motion, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the kit's documented site substitutions warn per call
        res = simulate(m, kit, BodyModel(), seed=seed, noise="none", rate=fps)
    return Recording.from_simulation(res, m, meta={CALIBRATION_WINDOW_KEY: window} if window else {})


def declared_differences(source: ModelSource, recording: Any,
                         declarations: Mapping[str, Mapping[str, str]] = DECLARATIONS) -> dict[str, dict[str, float]]:
    """The estimate of each declared copy of a canonical ``recording`` against the canonical one's.

    Both go through :func:`~wearpose.estimators.run.estimate_recording` (what ``wearpose
    estimate`` exports: in the world, on the floor), each with a fresh estimator.

    Returns:
        ``{declaration: {"local_rot": max |diff|, "trans": max |diff| m, "betas": ...}}`` over
        every frame and element (``trans`` absent when the track has none).
    """
    ref = estimate_recording(source, recording).track
    out = {}
    for name, decl in declarations.items():
        track = estimate_recording(source, recording.declared_as(**decl)).track
        diff = {}
        for field in ("local_rot", "trans", "betas"):
            a, b = getattr(ref, field), getattr(track, field)
            if a is not None and b is not None:
                diff[field] = float(np.abs(a.double().numpy() - b.double().numpy()).max())
        out[name] = diff
    return out
