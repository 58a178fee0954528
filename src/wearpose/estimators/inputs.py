"""The one place a recording becomes estimator input.

Every estimator states what it reads as an :class:`InputSpec` (its kit's sensors, the kinds it
accepts, the channels it needs, the rates it was trained at) and calls :func:`canonical_input`
or :func:`prepare`. In order, they:

1. check that the recording has every kit sensor, of an accepted kind and reference frame,
   carrying every needed channel, at the trained rate -- one :class:`~wearpose.errors.ShapeError`
   naming the sensor, the field and the expected form;
2. convert every declared convention to canonical form (:meth:`Recording.to_canonical`:
   mm/cm, deg/s, g, sensor-frame acceleration with gravity, Z-up world), so that a recording
   written in a device's own units gives the same estimate as its canonical copy;
3. (:func:`prepare`) stack the kit's sensors on their common time grid and treat masked samples
   as the method says: held at the sensor's last valid sample (:func:`hold_last_valid`) or left
   NaN. A dropped sample is never interpolated.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch

from wearpose.errors import ShapeError
from wearpose.recording import Recording, SensorStream
from wearpose.sensors import get_kit

#: Rates agree when within this fraction of the trained rate.
RATE_TOLERANCE = 1e-3


@dataclass(frozen=True)
class InputSpec:
    """What an estimator reads from a recording.

    Attributes:
        method: the method's name, for messages (``"EM-POSE"``).
        kit: the kit name (``"em12"``), or ``None`` for sensors named by the recording (any kit);
            then ``kinds["any"]`` lists the accepted kinds.
        sensor_names: the kit sensors read, in input (column) order.
        kinds: sensor kind -> the recording kinds accepted for it (default: the kit kind only).
        channels: channels every kit sensor must carry, after canonical conversion.
        rates: sensor kind -> the rate (Hz) the weights were trained at; kinds not listed may run
            at any rate.
        reference: EM sensors' required reference frame (``"source"``), or ``None`` for either.
    """

    method: str
    kit: str | None
    sensor_names: tuple[str, ...]
    channels: tuple[str, ...]
    kinds: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    rates: Mapping[str, float] = field(default_factory=dict)
    reference: str | None = None

    @classmethod
    def from_kit(cls, method: str, kit: str, channels: tuple[str, ...], *,
                 sensor_names: tuple[str, ...] | None = None, kinds: Mapping[str, tuple[str, ...]] | None = None,
                 rates: Mapping[str, float] | None = None, reference: str | None = None) -> InputSpec:
        """The spec of ``kit``'s sensors (all of them unless ``sensor_names``)."""
        k = get_kit(kit)
        names = tuple(sensor_names) if sensor_names is not None else tuple(k.sensor_names)
        return cls(method, kit, names, tuple(channels), dict(kinds or {}), dict(rates or {}), reference)

    def kit_kind(self, name: str) -> str:
        """The kind kit sensor ``name`` has in the kit (``"any"`` without a kit)."""
        if self.kit is None:
            return "any"
        for s in get_kit(self.kit).sensors:
            if s.name == name:
                return s.kind
        raise ShapeError(f"{self.method} reads sensor {name!r}, which kit {self.kit!r} does not have")


@dataclass
class PreparedInput:
    """Kit sensors of a canonical recording on their common grid.

    Attributes:
        recording: the whole recording in canonical form (other sensors included).
        names: ``S`` sensor names, input order.
        timestamps: ``(T,)`` s.
        valid: ``(T, S)`` bool.
        channels: the spec's channels, ``(T, S, ...)`` float32 tensors in canonical units;
            masked samples held at the last valid one (``hold=True``) or NaN.
    """

    recording: Recording
    names: tuple[str, ...]
    timestamps: np.ndarray
    valid: torch.Tensor
    channels: dict[str, torch.Tensor]


def check_input(recording: Recording, spec: InputSpec) -> None:
    """Raise :class:`ShapeError` unless ``recording`` carries what ``spec`` reads (module doc, 1)."""
    missing = [n for n in spec.sensor_names if n not in recording.names]
    if missing:
        raise ShapeError(f"recording lacks sensors {missing} of kit {spec.kit!r}: {spec.method} reads "
                         f"{list(spec.sensor_names)}; the recording has {list(recording.names)}")
    for name in spec.sensor_names:
        s = recording.sensor(name)
        kit_kind = spec.kit_kind(name)
        accepted = spec.kinds.get(kit_kind, (kit_kind,) if spec.kit is not None else (s.kind,))
        if s.kind not in accepted:
            raise ShapeError(f"sensor {name!r}: kind {s.kind!r}; {spec.method} (kit {spec.kit!r}) needs "
                             f"kind {' or '.join(repr(k) for k in accepted)}")
        if s.kind == "em6dof" and spec.reference is not None and s.info.reference != spec.reference:
            raise ShapeError(f"sensor {name!r}: reference {s.info.reference!r}; {spec.method} needs EM poses "
                             f"relative to the {spec.reference!r}")
        lacking = [c for c in spec.channels if getattr(s, c) is None]
        if lacking:
            raise ShapeError(f"sensor {name!r}: no {lacking} channel; {spec.method} needs "
                             f"{list(spec.channels)} for every kit sensor")
        rate = spec.rates.get(kit_kind)
        if rate is not None and abs(float(s.info.rate) - rate) > RATE_TOLERANCE * rate:
            raise ShapeError(f"sensor {name!r} runs at {s.info.rate:g} Hz; {spec.method} was trained at "
                             f"{rate:g} Hz (resample the recording first, e.g. wearpose estimate does)")


def canonical_input(recording: Recording, spec: InputSpec) -> Recording:
    """``recording`` checked against ``spec`` and in canonical form (module doc, steps 1-2).

    A recording that is canonical already is returned as it is (no copy)."""
    check_input(recording, spec)
    return recording if recording.is_canonical else recording.to_canonical()


def prepare(recording: Recording, spec: InputSpec, hold: bool = True) -> PreparedInput:
    """Steps 1-3 of the module doc: the kit sensors' channels as ``(T, S, ...)`` float32 tensors."""
    rec = canonical_input(recording, spec)
    grid = rec.on_common_grid(spec.sensor_names)
    valid = torch.as_tensor(grid.valid)
    chans = {c: torch.as_tensor(grid.channels[c], dtype=torch.float32) for c in spec.channels}
    if hold:
        chans = {c: hold_last_valid(x, valid) for c, x in chans.items()}
    return PreparedInput(rec, tuple(grid.names), grid.timestamps, valid, chans)


def hold_last_valid(x: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Replace masked samples by the sensor's last valid one (its first valid one before any).

    Args:
        x: ``(T, S, ...)`` samples (masked ones may be NaN).
        valid: ``(T, S)`` bool.

    Returns:
        a filled copy; a sensor never valid gets identity rotations for ``(..., 3, 3)`` input and
        zeros otherwise.
    """
    T, S = valid.shape
    if bool(valid.all()):
        return x.clone()
    idx = torch.arange(T).unsqueeze(1).expand(T, S)
    last = torch.where(valid, idx, torch.full_like(idx, -1)).cummax(0).values  # last valid index so far
    first = torch.where(valid.any(0), valid.float().argmax(0), torch.zeros(S, dtype=torch.long))
    src = torch.where(last >= 0, last, first.unsqueeze(0).expand(T, S))
    out = x[src, torch.arange(S).unsqueeze(0).expand(T, S)].clone()
    never = ~valid.any(0)
    if bool(never.any()):
        rot = x.shape[2:] == (3, 3)
        out[:, never] = torch.eye(3, dtype=x.dtype) if rot else torch.zeros(x.shape[2:], dtype=x.dtype)
    return out


def held_frame(frame: Any, sensor_names: Sequence[str], channels: Sequence[str],
               last: Sequence[torch.Tensor] | None, *, who: str = "estimator",
               nan_to_zero: Sequence[str] = ()) -> tuple[tuple[torch.Tensor, ...], torch.Tensor]:
    """One :class:`~wearpose.estimators.base.SensorFrame` as input in ``sensor_names`` order,
    online: the per-frame twin of :func:`hold_last_valid`.

    Args:
        frame: the newest frame (its ``names``, ``valid`` and ``channels``).
        sensor_names: the estimator's ``S`` sensors, in its order.
        channels: the channels to return (``"position"``, ``"acceleration"``, ``"orientation"``, ...).
        last: the previous call's returned tensors (one per channel), or None at the start.
        who: the estimator named in the error.
        nan_to_zero: channels whose NaNs (dropped samples) become 0 before the hold.

    Returns:
        ``(tensors, valid)``: one float32 ``(S, ...)`` tensor per channel, dropped samples held
        at ``last``, or neutral before any (identity for ``(3, 3)`` rotations, zeros otherwise);
        ``valid`` ``(S,)`` bool.

    Raises:
        ShapeError: the frame lacks one of ``sensor_names``.
    """
    names = list(frame.names)
    try:
        idx = [names.index(n) for n in sensor_names]
    except ValueError:
        raise ShapeError(f"frame has sensors {names}; {who} needs {list(sensor_names)}") from None
    valid = torch.as_tensor(np.asarray(frame.valid)[idx], dtype=torch.bool)
    out = []
    for i, ch in enumerate(channels):
        a = np.asarray(frame.channels[ch])[idx]
        x = torch.as_tensor(np.nan_to_num(a) if ch in nan_to_zero else a, dtype=torch.float32)
        if last is not None:
            hold = last[i]
        else:
            hold = torch.eye(3).expand_as(x) if x.shape[1:] == (3, 3) else torch.zeros_like(x)
        out.append(torch.where(valid.reshape(-1, *([1] * (x.dim() - 1))), x, hold))
    return tuple(out), valid


def nearest_sample_grid(recording: Recording, names: tuple[str, ...], rate: float | None = None) -> Recording:
    """The named sensors on one shared time grid, each grid instant taking the sensor's nearest
    sample: for devices that stamp their own samples (x-IMU3, phones), whose grids differ by
    milliseconds and drift apart by their clock rates.

    Nothing is interpolated: a grid instant whose nearest sample is further than half that
    sensor's period, is masked, or is nearer to another instant (a sample is used once) is
    masked. The grid runs at ``rate`` (default: the median of the sensors' rates) over the span
    every sensor covers.

    Returns:
        a recording of the named sensors sharing one ``timestamps`` array (``rate`` declared);
        ``meta["grid"]`` says how it was made and how many instants each sensor lost to it.
    """
    streams = [recording.sensor(n) for n in names]
    rate = float(rate or np.median([s.info.rate for s in streams]))
    t0 = max(float(s.timestamps[0]) for s in streams)
    t1 = min(float(s.timestamps[-1]) for s in streams)
    if t1 <= t0:
        raise ShapeError(f"sensors {list(names)} share no time span (latest start {t0:g} s, earliest end {t1:g} s)")
    grid = t0 + np.arange(int(np.floor((t1 - t0) * rate + 1e-9)) + 1) / rate
    out, lost = [], {}
    for s in streams:
        ts = np.asarray(s.timestamps, dtype=np.float64)
        i = np.clip(np.searchsorted(ts, grid), 1, len(ts) - 1)
        i = np.where(np.abs(ts[i - 1] - grid) <= np.abs(ts[i] - grid), i - 1, i)
        dist = np.abs(ts[i] - grid)
        ok = (dist <= 0.5 / float(s.info.rate)) & s.valid[i]
        again = np.r_[False, i[1:] == i[:-1]]  # the same sample nearest to two instants: keep the closer
        ok &= ~(again & (dist >= np.r_[np.inf, dist[:-1]]))
        ok &= ~(np.r_[i[1:] == i[:-1], False] & (dist > np.r_[dist[1:], np.inf]))
        ch = {c: np.where(ok.reshape(-1, *([1] * (x.ndim - 1))), x[i], np.nan).astype(x.dtype)
              for c, x in s.channels().items()}
        out.append(SensorStream(replace(s.info, rate=rate), grid.copy(), ok, **ch))
        lost[s.info.name] = int((s.valid[i] & ~ok).sum())  # valid samples the grid could not use
    meta = {**copy.deepcopy(recording.meta), "grid": {
        "rule": f"nearest sample at {rate:.4g} Hz, within half a sensor period, each sample once",
        "instants": int(len(grid)), "masked_by_grid": lost}}
    return Recording(out, recording.ground_truth, recording.ground_truth_start, copy.deepcopy(recording.subject), meta)
