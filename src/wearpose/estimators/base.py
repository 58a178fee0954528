"""The estimator protocol shared by every method (DESIGN.md, "The estimator protocol").

- :class:`PoseTrack`: the offline result (whole sequence).
- :class:`PoseFrame`: the online result (one frame).
- :class:`SensorFrame`: one time step of sensor input for :meth:`Estimator.step`, and
  :func:`iter_frames` to replay a :class:`~wearpose.recording.Recording` frame by frame.
- :class:`Estimator`: the abstract base every method implements.

Frames: rotations are SMPL *local* joint rotations (joint 0 = root orientation). The frame the
root orientation / translation refer to is method-specific and stated in ``extras["frame"]``
(EM methods that only see source-relative measurements report the root in the EM source
frame; see :mod:`wearpose.estimators.empose`).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Iterator, Mapping, Sequence

import numpy as np
import torch

from wearpose.body.skeleton import NUM_JOINTS
from wearpose.errors import ShapeError, WearposeError
from wearpose.estimators.checkpoint import load_checkpoint



class OfflineOnlyError(WearposeError, RuntimeError):
    """:meth:`Estimator.step` called on an offline-only (non-causal) estimator."""

@dataclass
class PoseTrack:
    """An estimated motion (offline result).

    Attributes:
        local_rot: ``(T, 24, 3, 3)`` SMPL local joint rotations; joint 0 is the root
            orientation in the frame named by ``extras.get("frame", "world")``.
        betas: ``(10,)`` shape coefficients (one per sequence).
        trans: ``(T, 3)`` root translation, m, or ``None`` when the method does not estimate it.
        valid: ``(T,)`` bool; False where the estimate rests on invalid (dropped) input.
        fps: frame rate, Hz.
        uncertainty: optional ``(T, 24)`` per-joint uncertainty (method-defined units, stated
            in ``extras["uncertainty_unit"]``).
        extras: method extras (``frame``, contacts, torques, interference state ...).
    """

    local_rot: torch.Tensor
    betas: torch.Tensor
    trans: torch.Tensor | None
    valid: torch.Tensor
    fps: float
    uncertainty: torch.Tensor | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        R = self.local_rot
        if not isinstance(R, torch.Tensor) or R.dim() != 4 or tuple(R.shape[1:]) != (NUM_JOINTS, 3, 3):
            raise ShapeError(f"PoseTrack.local_rot: expected (T, 24, 3, 3), got {tuple(getattr(R, 'shape', ()))}")
        T = R.shape[0]
        if tuple(self.betas.shape) != (10,):
            raise ShapeError(f"PoseTrack.betas: expected (10,), got {tuple(self.betas.shape)}")
        if self.trans is not None and tuple(self.trans.shape) != (T, 3):
            raise ShapeError(f"PoseTrack.trans: expected ({T}, 3) or None, got {tuple(self.trans.shape)}")
        self.valid = torch.as_tensor(self.valid, dtype=torch.bool)
        if tuple(self.valid.shape) != (T,):
            raise ShapeError(f"PoseTrack.valid: expected ({T},) bool, got {tuple(self.valid.shape)}")
        if self.uncertainty is not None and tuple(self.uncertainty.shape) != (T, NUM_JOINTS):
            raise ShapeError(f"PoseTrack.uncertainty: expected ({T}, 24), got {tuple(self.uncertainty.shape)}")
        if not (float(self.fps) > 0):
            raise ShapeError(f"PoseTrack.fps: expected a positive rate in Hz, got {self.fps!r}")
        self.fps = float(self.fps)

    @property
    def num_frames(self) -> int:
        return int(self.local_rot.shape[0])

    def to_motion(self) -> Any:
        """As a :class:`wearpose.motion.MotionSequence` (zero translation when not estimated)."""
        from wearpose.motion import MotionSequence  # start-up: motion adds ~48 ms to import this module

        trans = self.trans if self.trans is not None else torch.zeros(self.num_frames, 3, dtype=self.local_rot.dtype)
        return MotionSequence(self.local_rot.detach().clone(), self.betas.detach().clone(), trans.detach().clone(),
                              self.fps, {"estimated": True, **{k: v for k, v in self.extras.items() if isinstance(v, (str, int, float))}})


@dataclass
class PoseFrame:
    """One online estimate. Shapes as :class:`PoseTrack` without the time axis."""

    local_rot: torch.Tensor  #: (24, 3, 3)
    betas: torch.Tensor  #: (10,)
    trans: torch.Tensor | None  #: (3,) m or None
    valid: bool
    timestamp: float  #: s, the input frame's timestamp
    uncertainty: torch.Tensor | None = None  #: (24,)
    extras: dict[str, Any] = field(default_factory=dict)


@dataclass
class SensorFrame:
    """One time step of stacked sensor input (the columns of ``Recording.on_common_grid``).

    Attributes:
        timestamp: s.
        names: ``S`` sensor names, column order.
        valid: ``(S,)`` bool.
        channels: channel name -> ``(S, ...)`` array (``position`` ``(S, 3)`` m,
            ``orientation`` ``(S, 3, 3)``, ...), NaN where a sensor lacks the channel or dropped.
    """

    timestamp: float
    names: tuple[str, ...]
    valid: np.ndarray
    channels: dict[str, np.ndarray]


def iter_frames(recording: Any, names: Sequence[str] | None = None) -> Iterator[SensorFrame]:
    """Replay a recording (sensors on one grid) as :class:`SensorFrame` s, in time order, in
    canonical form (declared units and frames converted, as offline input is)."""
    if not recording.is_canonical:
        recording = recording.to_canonical()
    grid = recording.on_common_grid(names)
    for t in range(len(grid.timestamps)):
        yield SensorFrame(float(grid.timestamps[t]), grid.names, grid.valid[t],
                          {c: a[t] for c, a in grid.channels.items()})


class Estimator(abc.ABC):
    """Base class of every pose estimator.

    Class attributes:
        name: registry name (``wearpose.estimators.get_estimator(name)``).
        causal: True when :meth:`step` uses only past and present input.
        lookahead: frames of future input :meth:`step` waits for (0 for causal methods).

    Instance attributes every implementation sets: ``kit_name``, ``sensor_names`` (input
    order), ``body_asset_id``, ``fps`` (the input rate it was trained for).
    """

    name: ClassVar[str] = "?"
    #: False for estimators without weights (``--model segments``): built with no arguments.
    has_weights: ClassVar[bool] = True
    causal: ClassVar[bool] = True
    lookahead: ClassVar[int] = 0

    kit_name: str
    sensor_names: tuple[str, ...]
    body_asset_id: str
    fps: float

    @abc.abstractmethod
    def fit(self, *args: Any, **kwargs: Any) -> Any:
        """Train on the corpus (methods document their arguments); returns a training summary."""

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """One sentence for the weights card saying how this method's training inputs were made
        from the corpus train split (simulation, augmentation, synthetic clips, windows),
        derived from a checkpoint's ``config`` dict (the method config's ``to_dict()``) so cards
        are not patched by hand. None when the method does not say (``tools/ship_weights.py``
        then needs ``--simulation``)."""
        return None

    @abc.abstractmethod
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint (:mod:`wearpose.estimators.checkpoint`)."""

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu") -> Estimator:
        """Read a checkpoint; ``kit`` / ``body`` (if given) must match the checkpoint's, else
        :class:`~wearpose.estimators.checkpoint.CheckpointMismatchError`. The file is read once
        and handed to :meth:`from_checkpoint`."""
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, body=body, device=map_location,
                                   path=path)

    @classmethod
    def from_checkpoint(cls, ckpt: Any, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>") -> Estimator:
        """The estimator of an already-read :class:`~wearpose.estimators.checkpoint.Checkpoint`
        (``path`` only names it in errors): what :func:`wearpose.estimators.run.open_model` calls,
        so one estimate reads its checkpoint once. Every method with weights implements it."""
        raise NotImplementedError(f"{cls.__name__} has no weights to load (a checkpoint of method {ckpt.method!r})")

    @abc.abstractmethod
    def estimate(self, recording: Any) -> PoseTrack:
        """Offline estimate of a whole :class:`~wearpose.recording.Recording`."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Forget the online state (start of a new stream)."""

    @abc.abstractmethod
    def step(self, frame: SensorFrame) -> PoseFrame:
        """Online estimate for one input frame (after :meth:`reset`)."""
