"""``MotionSequence``: one clip of SMPL-24 motion, and its own small npz file format.

Frames: SMPL local joint rotations (joint frame -> parent frame; joint 0 -> world), wearpose world
(Y up, metres; at zero pose the body faces +Z with its left at +X). ``trans`` is SMPL's root
translation: joint positions are ``forward_kinematics(pose, rest_joints(betas)) + trans``, so the
pelvis joint sits at ``rest_joints(betas)[0] + trans`` (not at ``trans``).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wearpose.body.skeleton import NUM_JOINTS
from wearpose.errors import InputFileError, ShapeError
from wearpose.fileio import atomic_savez, npz_problem
from wearpose.geometry import axis_angle_to_matrix, matrix_to_axis_angle

#: Identifies our motion files; bump :data:`FORMAT_VERSION` on any incompatible change.
FORMAT_NAME = "wearpose.motion"
FORMAT_VERSION = 1
NUM_BETAS = 10


def _as_tensor(x: Any, name: str) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        t = x
    elif isinstance(x, np.ndarray):
        t = torch.from_numpy(np.ascontiguousarray(x))
    else:
        try:
            t = torch.as_tensor(x)
        except Exception as exc:  # noqa: BLE001 - any conversion failure is a type problem
            raise ShapeError(f"MotionSequence.{name}: expected a tensor/array, got {type(x).__name__}") from exc
    if not t.is_floating_point():
        t = t.to(torch.float32)
    return t


@dataclass
class MotionSequence:
    """SMPL-24 motion clip.

    Attributes:
        pose: ``(T, 24, 3, 3)`` local joint rotations in SMPL order (joint 0 = global root
            orientation in the Y-up world).
        betas: ``(10,)`` SMPL shape coefficients.
        trans: ``(T, 3)`` root translation, metres, Y-up world (SMPL sense, see module doc).
        fps: frames per second (> 0).
        meta: free-form JSON-serialisable facts: ``source_file``, ``source_format``
            (``"bvh"``/``"amass"``), ``skeleton``, ``licence``, ``subject``, ``clip``, ``split``...

    ``pose``, ``betas`` and ``trans`` share one floating dtype (that of ``pose``); numpy input is
    accepted and converted.
    """

    pose: torch.Tensor
    betas: torch.Tensor
    trans: torch.Tensor
    fps: float
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.pose = _as_tensor(self.pose, "pose")
        dtype = self.pose.dtype
        self.betas = _as_tensor(self.betas, "betas").to(dtype)
        self.trans = _as_tensor(self.trans, "trans").to(dtype)
        p, b, t = self.pose, self.betas, self.trans
        if p.dim() != 4 or tuple(p.shape[1:]) != (NUM_JOINTS, 3, 3):
            raise ShapeError(f"MotionSequence.pose: expected (T, {NUM_JOINTS}, 3, 3) rotation matrices, got {tuple(p.shape)}")
        if tuple(b.shape) != (NUM_BETAS,):
            raise ShapeError(f"MotionSequence.betas: expected ({NUM_BETAS},), got {tuple(b.shape)}")
        if t.dim() != 2 or t.shape[1] != 3:
            raise ShapeError(f"MotionSequence.trans: expected (T, 3) metres, got {tuple(t.shape)}")
        if t.shape[0] != p.shape[0]:
            raise ShapeError(f"MotionSequence: pose has {p.shape[0]} frames but trans has {t.shape[0]}")
        try:
            self.fps = float(self.fps)
        except (TypeError, ValueError) as exc:
            raise ShapeError(f"MotionSequence.fps: expected a positive number, got {self.fps!r}") from exc
        if not np.isfinite(self.fps) or self.fps <= 0:
            raise ShapeError(f"MotionSequence.fps: expected a positive number, got {self.fps!r}")
        if not isinstance(self.meta, dict):
            raise ShapeError(f"MotionSequence.meta: expected a dict, got {type(self.meta).__name__}")

    # ------------------------------------------------------------------ basic facts
    @property
    def num_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.pose.shape[0])

    @property
    def duration(self) -> float:
        """Seconds covered, ``T / fps`` (the last sample is at ``(T - 1) / fps``)."""
        return self.num_frames / self.fps

    @property
    def dtype(self) -> torch.dtype:
        return self.pose.dtype

    def __len__(self) -> int:
        return self.num_frames

    def slice(self, start: int = 0, stop: int | None = None, step: int = 1) -> MotionSequence:
        """Frames ``start:stop:step`` as a new sequence (``fps`` divided by ``step``)."""
        if step < 1:
            raise ShapeError(f"MotionSequence.slice: step must be >= 1, got {step}")
        s = slice(start, stop, step)
        out = MotionSequence(self.pose[s].clone(), self.betas.clone(), self.trans[s].clone(),
                             self.fps / step, copy.deepcopy(self.meta))
        if out.num_frames == 0:
            raise ShapeError(f"MotionSequence.slice({start}, {stop}, {step}) is empty (sequence has {self.num_frames} frames)")
        return out

    def to(self, dtype: torch.dtype) -> MotionSequence:
        """A copy with pose, betas and trans in ``dtype``."""
        return MotionSequence(self.pose.to(dtype), self.betas.to(dtype), self.trans.to(dtype), self.fps,
                              copy.deepcopy(self.meta))

    # ------------------------------------------------------------------ file format
    def save(self, path: str | Path) -> Path:
        """Write our npz format (atomic: a temporary file is renamed into place).

        Keys: ``format`` (str ``"wearpose.motion"``), ``version`` (int), ``pose_aa`` ``(T, 24, 3)``
        float32 axis-angle, radians (compact and exact enough: float32 round trip < 1e-6 rad),
        ``betas`` ``(10,)`` float32, ``trans`` ``(T, 3)`` float32 metres, ``fps`` float64 scalar,
        ``meta`` str (JSON object).
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        aa = matrix_to_axis_angle(self.pose.to(torch.float64)).to(torch.float32).numpy()
        arrays = {
            "format": np.array(FORMAT_NAME), "version": np.array(FORMAT_VERSION, dtype=np.int64),
            "pose_aa": aa, "betas": self.betas.detach().to(torch.float32).numpy(),
            "trans": self.trans.detach().to(torch.float32).numpy(), "fps": np.array(self.fps, dtype=np.float64),
            "meta": np.array(json.dumps(self.meta, sort_keys=True, default=str)),
        }
        return atomic_savez(path, arrays)

    @classmethod
    def load(cls, path: str | Path, dtype: torch.dtype = torch.float32) -> MotionSequence:
        """Read a file written by :meth:`save`; every key is validated.

        Raises:
            InputFileError: missing/unreadable file, wrong format/version, missing key, bad shape.
        """
        path = Path(path)
        expected_file = f"a {FORMAT_NAME} npz written by MotionSequence.save"
        if not path.is_file():
            raise InputFileError(path, "file not found", expected_file)
        try:
            with np.load(path, allow_pickle=False) as data:
                d = {k: data[k] for k in data.files}
        except Exception as exc:  # noqa: BLE001 - zip/npy errors of any kind
            raise InputFileError(path, npz_problem(path, exc), expected_file) from exc

        def need(key: str, expected: str) -> np.ndarray:
            if key not in d:
                raise InputFileError(path, "missing key", expected, field=key)
            return d[key]

        fmt = str(need("format", f"the string {FORMAT_NAME!r}"))
        if fmt != FORMAT_NAME:
            raise InputFileError(path, f"format is {fmt!r}", f"the string {FORMAT_NAME!r}", field="format")
        version = int(need("version", "an integer format version"))
        if version != FORMAT_VERSION:
            raise InputFileError(path, f"format version {version} is not supported", f"version {FORMAT_VERSION}", field="version")
        aa = need("pose_aa", "(T, 24, 3) float axis-angle")
        if aa.ndim != 3 or aa.shape[1:] != (NUM_JOINTS, 3) or not np.issubdtype(aa.dtype, np.floating):
            raise InputFileError(path, f"shape {aa.shape} dtype {aa.dtype}", "(T, 24, 3) float axis-angle, radians", field="pose_aa")
        betas = need("betas", f"({NUM_BETAS},) float")
        if betas.shape != (NUM_BETAS,):
            raise InputFileError(path, f"shape {betas.shape}", f"({NUM_BETAS},) float", field="betas")
        trans = need("trans", "(T, 3) float metres")
        if trans.shape != (aa.shape[0], 3):
            raise InputFileError(path, f"shape {trans.shape} for {aa.shape[0]} frames", "(T, 3) float metres", field="trans")
        fps_arr = need("fps", "a positive float scalar")
        fps = float(fps_arr) if fps_arr.shape == () else float("nan")
        if not np.isfinite(fps) or fps <= 0:
            raise InputFileError(path, f"value {fps_arr!r}", "a positive float scalar", field="fps")
        try:
            meta = json.loads(str(need("meta", "a JSON object string")))
            if not isinstance(meta, dict):
                raise ValueError("not an object")
        except ValueError as exc:
            raise InputFileError(path, f"invalid JSON ({exc})", "a JSON object string", field="meta") from exc
        for key, arr in (("pose_aa", aa), ("trans", trans), ("betas", betas)):
            if not np.all(np.isfinite(arr)):
                raise InputFileError(path, "contains NaN or infinite values", "finite numbers", field=key)
        pose = axis_angle_to_matrix(torch.from_numpy(aa.astype(np.float64))).to(dtype)
        return cls(pose, torch.from_numpy(betas).to(dtype), torch.from_numpy(trans).to(dtype), fps, meta)
