"""``CalibrationResult``: what a calibration procedure found, storable as JSON in a recording.

One type for every procedure; the meaning of the array fields depends on ``method`` (frames and
units below). ``to_dict()`` gives plain JSON (lists of floats) that ``Recording.meta["calibration"]``
can hold and the recording file format writes in its header; ``from_dict()`` reads it back.

| method | ``rotation`` (S, 3, 3) | ``translation`` (S, 3) | ``world_rotation`` (S, 3, 3) | ``world_translation`` (S, 3) | ``scale`` |
| --- | --- | --- | --- | --- | --- |
| ``empose-offsets`` | ``R_off``: sensor -> site frame (EM-POSE Eq. 4) | ``t_off``, site frame, m (+ ``translation_cov`` m^2) | -- | -- | -- |
| ``tpose`` / ``ipose`` | ``R_BS``: sensor -> bone (BiRAE ``R^{B_iS_i}``) | -- | ``R_WM``: sensor world -> wearpose world (BiRAE ``R^{GI_i}``, heading included) | -- | -- |
| ``miposer-tpose`` | ``R_off``: sensor -> target joint frame | ``t_off``: sensor origin -> joint, sensor frame, m (model scale) | ``R_WM`` (same for all sensors) | origin shift, m (same for all) | arm-span scale |
| ``hand-eye`` | ``X`` rotation (1, 3, 3) | ``X`` translation (1, 3), m | ``Y`` rotation (1, 3, 3) | ``Y`` translation (1, 3), m | -- |

``extras`` holds further named arrays (e.g. heading-reset anchors ``heading_times`` (K,) s and
``heading_yaw`` (K, S) rad); ``quality`` holds residual figures (degrees and millimetres, named
so); ``params`` the settings used (window, pose, heading source...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from wearpose.calibration._common import CalibrationError, t64

#: Identifies a serialised calibration; bump :data:`FORMAT_VERSION` on an incompatible change.
FORMAT_NAME = "wearpose.calibration"
FORMAT_VERSION = 1
METHODS: tuple[str, ...] = ("empose-offsets", "tpose", "ipose", "miposer-tpose", "hand-eye")
_ARRAYS: dict[str, tuple[int, ...]] = {
    "rotation": (3, 3), "translation": (3,), "translation_cov": (3, 3),
    "world_rotation": (3, 3), "world_translation": (3,),
}


@dataclass
class CalibrationResult:
    """Result of one calibration (see the module table for each method's frames).

    Attributes:
        method: one of :data:`METHODS`.
        sensors: ``S`` sensor names the per-sensor arrays refer to, in order.
        rotation, translation, translation_cov, world_rotation, world_translation: float64
            tensors with leading dimension ``S`` (or ``None``).
        scale: a scalar (MI-Poser arm-span scale) or ``None``.
        extras: further named float64 tensors.
        quality: residual figures, JSON scalars/lists.
        params: settings used, JSON values.
    """

    method: str
    sensors: tuple[str, ...]
    rotation: torch.Tensor | None = None
    translation: torch.Tensor | None = None
    translation_cov: torch.Tensor | None = None
    world_rotation: torch.Tensor | None = None
    world_translation: torch.Tensor | None = None
    scale: float | None = None
    extras: dict[str, torch.Tensor] = field(default_factory=dict)
    quality: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise CalibrationError(f"CalibrationResult.method: unknown method {self.method!r}; expected one of {list(METHODS)}")
        self.sensors = tuple(str(s) for s in self.sensors)
        S = len(self.sensors)
        for name, tail in _ARRAYS.items():
            v = getattr(self, name)
            if v is None:
                continue
            v = t64(v)
            if tuple(v.shape) != (S, *tail):
                raise CalibrationError(f"CalibrationResult.{name}: shape {tuple(v.shape)}, expected {(S, *tail)} "
                                       f"(one per sensor of {list(self.sensors)})")
            if not torch.isfinite(v).all():
                raise CalibrationError(f"CalibrationResult.{name}: contains NaN or infinite values")
            setattr(self, name, v)
        self.extras = {str(k): t64(v) for k, v in self.extras.items()}
        if self.scale is not None:
            self.scale = float(self.scale)
            if not (math.isfinite(self.scale) and self.scale > 0):
                raise CalibrationError(f"CalibrationResult.scale: {self.scale!r}, expected a positive number")

    def index(self, sensor: str) -> int:
        """Position of ``sensor`` in :attr:`sensors`; :class:`CalibrationError` if absent."""
        try:
            return self.sensors.index(sensor)
        except ValueError:
            raise CalibrationError(f"calibration ({self.method}) has no sensor {sensor!r}; it covers {list(self.sensors)}") from None

    def to_em_offsets(self) -> Any:
        """``empose-offsets`` result -> :class:`wearpose.sensors.EMOffsets` (for ``simulate(offsets=...)``)."""
        from wearpose.sensors import EMOffsets  # start-up: wearpose.sensors adds ~110 ms to import wearpose.calibration

        if self.method != "empose-offsets":
            raise CalibrationError(f"to_em_offsets: needs an 'empose-offsets' calibration, this one is {self.method!r}")
        return EMOffsets(self.rotation.clone(), self.translation.clone(),
                         None if self.translation_cov is None else self.translation_cov.clone())

    def to_subject_offsets(self) -> dict[str, Any]:
        """``empose-offsets`` result -> the ``Recording.subject["offsets"]`` dict that
        :func:`wearpose.recording.from_empose` and ``Recording.from_simulation`` write and the
        EM-POSE estimator reads (``sensors``, ``rotation`` (S, 3, 3), ``translation_mean_m``
        (S, 3), ``translation_cov_m2`` (S, 3, 3), ``origin``)."""
        if self.method != "empose-offsets":
            raise CalibrationError(f"to_subject_offsets: needs an 'empose-offsets' calibration, this one is {self.method!r}")
        d: dict[str, Any] = {"sensors": list(self.sensors), "rotation": self.rotation.tolist(),
                             "translation_mean_m": self.translation.tolist()}
        if self.translation_cov is not None:
            d["translation_cov_m2"] = self.translation_cov.tolist()
        d["origin"] = "calibrated: wearpose.calibration empose-offsets (EM-POSE supp. Eq. 1-3)"
        return d

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (nested lists of floats); inverse of :meth:`from_dict`."""
        d: dict[str, Any] = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "method": self.method,
                             "sensors": list(self.sensors)}
        for name in _ARRAYS:
            v = getattr(self, name)
            d[name] = None if v is None else v.tolist()
        d["scale"] = self.scale
        d["extras"] = {k: v.tolist() for k, v in self.extras.items()}
        d["quality"] = _jsonable(self.quality)
        d["params"] = _jsonable(self.params)
        return d

    @classmethod
    def from_dict(cls, d: Any) -> CalibrationResult:
        """Read :meth:`to_dict` output; errors name the offending key."""
        if not isinstance(d, dict):
            raise CalibrationError(f"calibration: expected a JSON object, got {type(d).__name__}")
        if d.get("format") != FORMAT_NAME:
            raise CalibrationError(f"calibration/format: {d.get('format')!r}, expected {FORMAT_NAME!r}")
        if d.get("version") != FORMAT_VERSION:
            raise CalibrationError(f"calibration/version: {d.get('version')!r}, this wearpose reads version {FORMAT_VERSION}")
        known = {"format", "version", "method", "sensors", "scale", "extras", "quality", "params", *_ARRAYS}
        unknown = sorted(set(d) - known)
        if unknown:
            raise CalibrationError(f"calibration: unknown key(s) {unknown}; expected only {sorted(known)}")
        sensors = d.get("sensors")
        if not isinstance(sensors, list) or not all(isinstance(x, str) for x in sensors):
            raise CalibrationError(f"calibration/sensors: {str(sensors)[:60]!r}, expected a list of sensor names")
        for key in ("extras", "quality", "params"):
            if d.get(key) is not None and not isinstance(d.get(key), dict):
                raise CalibrationError(f"calibration/{key}: expected a JSON object, got {type(d.get(key)).__name__}")
        scale = d.get("scale")
        if scale is not None and (isinstance(scale, bool) or not isinstance(scale, (int, float))):
            raise CalibrationError(f"calibration/scale: {scale!r}, expected a number or null")
        arrays = {}
        for name in list(_ARRAYS) + [f"extras/{k}" for k in (d.get("extras") or {})]:
            v = d["extras"][name[7:]] if name.startswith("extras/") else d.get(name)
            try:
                arrays[name] = None if v is None else torch.as_tensor(np.asarray(v, dtype=np.float64))
            except (TypeError, ValueError, OverflowError) as exc:
                raise CalibrationError(f"calibration/{name}: not a numeric array ({exc})") from None
        extras = {k[7:]: arrays.pop(k) for k in list(arrays) if k.startswith("extras/")}
        if any(v is None for v in extras.values()):
            raise CalibrationError("calibration/extras: values must be numeric arrays, not null")
        return cls(method=d.get("method"), sensors=tuple(sensors), scale=scale, extras=extras,
                   quality=dict(d.get("quality") or {}), params=dict(d.get("params") or {}), **arrays)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().tolist()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return x
