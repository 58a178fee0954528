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
3. (:func:`prepare`) run the method's own step on the canonical recording, if it has one (PIP:
   T-pose calibration to bone orientations; MI-Poser: metal-interference mitigation);
4. stack the kit's sensors on one time grid (:attr:`InputSpec.align`: the grid they share, or the
   first sensor's instants for kits whose sensors run at different rates) and treat masked
   samples as the method says: held at the sensor's last valid sample (:func:`hold_last_valid`)
   or left as recorded. A dropped sample is never interpolated.

Online, :class:`OnlineInput` does step 4 per frame: it maps the frame's sensors to the
estimator's order once per stream (not per frame) and holds dropped samples.

Every error names the recording (:func:`recording_label`), the sensor, the field and the
expected form.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch

from wearpose.errors import RecordingInputError, ShapeError
from wearpose.recording import Recording, SensorStream
from wearpose.sensors import get_kit

#: Rates agree when within this fraction of the trained rate.
RATE_TOLERANCE = 1e-3
#: ``align="first"``: a sample further than this from a grid instant is not used there, s.
ALIGN_TOLERANCE_S = 1e-3
#: The grids :attr:`InputSpec.align` names.
ALIGNMENTS = ("shared", "first")


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
        align: the time grid :func:`prepare` stacks the sensors on: ``"shared"`` (they must share
            one, :meth:`Recording.on_common_grid`) or ``"first"`` (the first sensor's instants;
            each other sensor contributes its nearest sample within :data:`ALIGN_TOLERANCE_S`,
            else that instant is masked: kits whose sensors run at integer multiples of one rate,
            e.g. a 60 Hz headset with 120 Hz EM sensors). Nothing is interpolated either way.
    """

    method: str
    kit: str | None
    sensor_names: tuple[str, ...]
    channels: tuple[str, ...]
    kinds: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    rates: Mapping[str, float] = field(default_factory=dict)
    reference: str | None = None
    align: str = "shared"

    def __post_init__(self) -> None:
        if self.align not in ALIGNMENTS:
            raise ShapeError(f"InputSpec of {self.method}: align {self.align!r}; expected one of {list(ALIGNMENTS)}")

    @classmethod
    def from_kit(cls, method: str, kit: str, channels: tuple[str, ...], *,
                 sensor_names: tuple[str, ...] | None = None, kinds: Mapping[str, tuple[str, ...]] | None = None,
                 rates: Mapping[str, float] | None = None, reference: str | None = None,
                 align: str = "shared") -> InputSpec:
        """The spec of ``kit``'s sensors (all of them unless ``sensor_names``)."""
        k = get_kit(kit)
        names = tuple(sensor_names) if sensor_names is not None else tuple(k.sensor_names)
        return cls(method, kit, names, tuple(channels), dict(kinds or {}), dict(rates or {}), reference, align)

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
        recording: the whole recording in canonical form (other sensors included), after the
            method's own step (``before_grid``), at its own rates (before the grid).
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


def recording_label(recording: Recording) -> str:
    """How an error names ``recording``: its file (``Recording.origin``, set by
    :func:`~wearpose.recording.load_recording`), or a note that it was made in memory."""
    origin = getattr(recording, "origin", None)
    return f"recording {origin}" if origin else "a recording not loaded from a file (made in memory)"


def _input_error(recording: Recording, problem: str, expected: str) -> RecordingInputError:
    """The one form of a bad-input error: the recording, the problem (sensor and field in it),
    the expected form."""
    return RecordingInputError(recording_label(recording), problem, expected)


def check_input(recording: Recording, spec: InputSpec) -> None:
    """Raise :class:`ShapeError` unless ``recording`` carries what ``spec`` reads (module doc, 1)."""
    missing = [n for n in spec.sensor_names if n not in recording.names]
    if missing:
        raise _input_error(recording, f"no sensors {missing} (it has {list(recording.names)})",
                           f"{spec.method} reads sensors {list(spec.sensor_names)} of kit {spec.kit!r}")
    for name in spec.sensor_names:
        _check_sensor(recording, spec, recording.sensor(name))


def _check_sensor(recording: Recording, spec: InputSpec, s: SensorStream) -> None:
    name, kit_kind = s.name, spec.kit_kind(s.name)
    accepted = spec.kinds.get(kit_kind, (kit_kind,) if spec.kit is not None else (s.kind,))
    if s.kind not in accepted:
        raise _input_error(recording, f"sensor {name!r} [kind] is {s.kind!r}",
                           f"kind {' or '.join(repr(k) for k in accepted)} ({spec.method}, kit {spec.kit!r})")
    if s.kind == "em6dof" and spec.reference is not None and s.info.reference != spec.reference:
        raise _input_error(recording, f"sensor {name!r} [reference] is {s.info.reference!r}",
                           f"EM poses relative to the {spec.reference!r} ({spec.method})")
    lacking = [c for c in spec.channels if getattr(s, c) is None]
    if lacking:
        raise _input_error(recording, f"sensor {name!r} has no {lacking} channel",
                           f"channels {list(spec.channels)} for every sensor {spec.method} reads")
    rate = spec.rates.get(kit_kind)
    if rate is not None and abs(float(s.info.rate) - rate) > RATE_TOLERANCE * rate:
        raise _input_error(recording, f"sensor {name!r} [rate] is {s.info.rate:g} Hz",
                           f"{rate:g} Hz, the rate {spec.method} was trained at (resample the recording "
                           "first, e.g. wearpose estimate does)")


def canonical_input(recording: Recording, spec: InputSpec) -> Recording:
    """``recording`` checked against ``spec`` and in canonical form (module doc, steps 1-2).

    A recording that is canonical already is returned as it is (no copy)."""
    check_input(recording, spec)
    return recording if recording.is_canonical else recording.to_canonical()


def prepare(recording: Recording, spec: InputSpec, hold: bool = True, *,
            before_grid: Callable[[Recording], Recording] | None = None, dtype: torch.dtype = torch.float32,
            nan_to_zero: Sequence[str] = ()) -> PreparedInput:
    """Steps 1-4 of the module doc: the kit sensors' channels as ``(T, S, ...)`` tensors.

    Args:
        recording: any recording (declared conventions are converted).
        spec: what the estimator reads.
        hold: hold masked samples at the sensor's last valid one (False: as recorded; the
            method treats them itself).
        before_grid: the method's own step on the checked, canonical recording (step 3).
        dtype: the tensors' dtype (the recording's float32 samples are exact in float64 too).
        nan_to_zero: channels whose NaNs become 0 before the hold.
    """
    rec = canonical_input(recording, spec)
    if before_grid is not None:
        rec = before_grid(rec)
    on_grid = on_first_grid(rec, spec.sensor_names) if spec.align == "first" else rec
    grid = on_grid.on_common_grid(spec.sensor_names)
    valid = torch.as_tensor(grid.valid)
    chans = {c: torch.as_tensor(np.nan_to_num(grid.channels[c]) if c in nan_to_zero else grid.channels[c], dtype=dtype)
             for c in spec.channels}
    if hold:
        chans = {c: hold_last_valid(x, valid) for c, x in chans.items()}
    return PreparedInput(rec, tuple(grid.names), grid.timestamps, valid, chans)


def nearest_samples(ts: np.ndarray, instants: np.ndarray,
                    tolerance: float = ALIGN_TOLERANCE_S) -> tuple[np.ndarray, np.ndarray]:
    """The sample of ``ts`` nearest each of ``instants`` (the earlier one on a tie) and whether it
    is within ``tolerance`` s of it.

    Args:
        ts: ``(N,)`` increasing sample times, s. instants: ``(T,)`` s.

    Returns:
        ``(index (T,) int, within (T,) bool)``.
    """
    i = np.clip(np.searchsorted(ts, instants), 1, max(1, len(ts) - 1))
    i = np.where(np.abs(ts[i - 1] - instants) <= np.abs(ts[np.minimum(i, len(ts) - 1)] - instants), i - 1, i)
    i = np.clip(i, 0, len(ts) - 1)
    return i, np.abs(ts[i] - instants) <= tolerance


def on_first_grid(recording: Recording, names: Sequence[str]) -> Recording:
    """The named sensors on the first one's time grid (:attr:`InputSpec.align` ``"first"``).

    Each other sensor contributes, at every instant of the first, its nearest sample
    (:func:`nearest_samples`); an instant with no sample within :data:`ALIGN_TOLERANCE_S` is
    masked and its channels NaN. Nothing is interpolated. Other sensors are left as they are.

    Returns:
        a recording whose named sensors share the first's ``timestamps`` (rate declared as the
        first's); ``meta["grid"]`` says how, and how many instants each sensor lost to it.
    """
    ref = recording.sensor(names[0])
    ts = np.asarray(ref.timestamps, dtype=np.float64)
    out, lost = [], {}
    for s in recording.sensors:
        if s.name not in names[1:]:
            out.append(s)
            continue
        i, ok = nearest_samples(np.asarray(s.timestamps, dtype=np.float64), ts)
        ch = {c: np.where(ok.reshape(-1, *([1] * (x.ndim - 1))), x[i], np.nan).astype(x.dtype)
              for c, x in s.channels().items()}
        out.append(SensorStream(replace(s.info, rate=ref.info.rate), ts.copy(), np.asarray(s.valid)[i] & ok, **ch))
        lost[s.name] = int((np.asarray(s.valid)[i] & ~ok).sum())
    meta = {**copy.deepcopy(recording.meta), "grid": {
        "rule": f"{names[0]!r}'s instants; other sensors' nearest sample within {ALIGN_TOLERANCE_S:g} s",
        "instants": int(len(ts)), "masked_by_grid": lost}}
    return _like(recording, out, meta)


def _like(recording: Recording, sensors: list[SensorStream], meta: dict[str, Any]) -> Recording:
    """A recording of ``sensors`` with ``recording``'s ground truth, subject and origin."""
    return replace(recording, sensors=sensors, subject=copy.deepcopy(recording.subject), meta=meta)


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


class OnlineInput:
    """The online twin of :func:`prepare`'s step 4: one :class:`~wearpose.estimators.base.SensorFrame`
    at a time as input in the estimator's sensor order, dropped samples held.

    An estimator makes one at ``reset()``. The map from a frame's sensor columns to the
    estimator's order is built on the first frame and reused for every later one with the same
    sensor names (rebuilt only when they change), so a step does no name look-ups.

    Args:
        sensor_names: the estimator's ``S`` sensors, in its order.
        channels: the channels to return (``"position"``, ``"acceleration"``, ``"orientation"``, ...).
        who: the estimator named in the error.
        nan_to_zero: channels whose NaNs (dropped samples) become 0 before the hold.
    """

    def __init__(self, sensor_names: Sequence[str], channels: Sequence[str], *, who: str = "estimator",
                 nan_to_zero: Sequence[str] = ()) -> None:
        self.sensor_names = tuple(sensor_names)
        self.channels = tuple(channels)
        self.who = who
        self.nan_to_zero = frozenset(nan_to_zero)
        #: the previous frame's returned tensors (one per channel), None before the first
        self.last: tuple[torch.Tensor, ...] | None = None
        self._names: tuple[str, ...] | None = None
        self._idx: np.ndarray | None = None

    def index(self, names: Sequence[str]) -> np.ndarray:
        """``(S,)`` column of each of :attr:`sensor_names` in a frame with sensors ``names``
        (the kept map when ``names`` are those of the previous frame)."""
        if self._idx is None or (names is not self._names and tuple(names) != self._names):
            cols = {n: i for i, n in enumerate(names)}
            missing = [n for n in self.sensor_names if n not in cols]
            if missing:
                raise ShapeError(f"live frame: no sensors {missing} (it has {list(names)}). Expected: "
                                 f"{self.who} reads sensors {list(self.sensor_names)}")
            self._names, self._idx = tuple(names), np.array([cols[n] for n in self.sensor_names])
        return self._idx

    def __call__(self, frame: Any) -> tuple[tuple[torch.Tensor, ...], torch.Tensor]:
        """``(tensors, valid)`` of ``frame``: one float32 ``(S, ...)`` tensor per channel, dropped
        samples held at the previous frame's, or neutral before any (identity for ``(3, 3)``
        rotations, zeros otherwise); ``valid`` ``(S,)`` bool."""
        idx = self.index(frame.names)
        valid = torch.as_tensor(np.asarray(frame.valid)[idx], dtype=torch.bool)
        out = []
        for i, ch in enumerate(self.channels):
            a = np.asarray(frame.channels[ch])[idx]
            x = torch.as_tensor(np.nan_to_num(a) if ch in self.nan_to_zero else a, dtype=torch.float32)
            if self.last is not None:
                hold = self.last[i]
            else:
                hold = torch.eye(3).expand_as(x) if x.shape[1:] == (3, 3) else torch.zeros_like(x)
            out.append(torch.where(valid.reshape(-1, *([1] * (x.dim() - 1))), x, hold))
        self.last = tuple(out)
        return self.last, valid


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
    return _like(recording, out, meta)
