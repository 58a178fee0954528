"""Checkpoints: weights + everything needed to know what they were trained for.

A checkpoint is one ``torch.save`` file (a plain dict, loaded with ``weights_only=True``)::

    format: "wearpose.checkpoint", version: 1
    method: registry name ("empose")
    config: dict (the method's config dataclass as a dict)
    kit: sensor kit name; sensors: list of sensor names in input order
    body_asset: body asset id the model's differentiable body / training data used
    data_fingerprint: sha256 of the training clip ids + simulation settings (:func:`fingerprint`)
    train_command: the command line that trained it
    weights: state_dict
    meta: epoch, metrics, timestamps ...
    train_state: optional optimiser / scheduler / progress state (resume only)

Loading on a different kit or body asset fails with :class:`CheckpointMismatchError` naming both.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import torch

from wearpose.errors import InputFileError, WearposeError
from wearpose.fileio import atomic_torch_save
import zipfile

FORMAT = "wearpose.checkpoint"
VERSION = 1


class CheckpointMismatchError(WearposeError, ValueError):
    """A checkpoint is used with a sensor kit / sensor list / body asset it was not trained for."""


def fingerprint(clip_ids: Sequence[str], settings: dict[str, Any]) -> str:
    """sha256 (hex) of the sorted clip ids and the simulation settings (canonical JSON)."""
    blob = json.dumps({"clips": sorted(clip_ids), "settings": settings}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


@dataclass
class Checkpoint:
    """In-memory checkpoint (see module doc for the fields)."""

    method: str
    config: dict[str, Any]
    kit: str
    sensors: list[str]
    body_asset: str
    weights: dict[str, torch.Tensor]
    data_fingerprint: str = ""
    train_command: str = ""
    meta: dict[str, Any] = field(default_factory=dict)
    train_state: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, "method": self.method, "config": self.config, "kit": self.kit,
                "sensors": list(self.sensors), "body_asset": self.body_asset, "data_fingerprint": self.data_fingerprint,
                "train_command": self.train_command, "weights": self.weights, "meta": self.meta,
                "train_state": self.train_state}

    def check(self, *, method: str | None = None, kit: str | None = None, sensors: Sequence[str] | None = None,
              body_asset: str | None = None, path: str | Path = "<checkpoint>") -> None:
        """Raise :class:`CheckpointMismatchError` naming both sides of the first mismatch."""
        if method is not None and method != self.method:
            raise CheckpointMismatchError(f"{path}: checkpoint is for method {self.method!r}, not {method!r}")
        if kit is not None and kit != self.kit:
            raise CheckpointMismatchError(f"{path}: checkpoint was trained for sensor kit {self.kit!r} "
                                          f"({len(self.sensors)} sensors) but kit {kit!r} was requested")
        if sensors is not None and list(sensors) != list(self.sensors):
            raise CheckpointMismatchError(f"{path}: checkpoint expects sensors {list(self.sensors)} (kit {self.kit!r}) "
                                          f"but got {list(sensors)}")
        if body_asset is not None and body_asset != self.body_asset:
            raise CheckpointMismatchError(f"{path}: checkpoint was trained with body asset {self.body_asset!r} "
                                          f"but body asset {body_asset!r} was given")


def save_checkpoint(ckpt: Checkpoint, path: str | Path) -> Path:
    """Write atomically (temp file + rename) so a killed run never leaves a torn checkpoint."""
    return atomic_torch_save(path, ckpt.to_dict())


#: What a checkpoint file is, for error messages.
EXPECTED_FILE = (f"a .pt checkpoint written by `wearpose train` or Estimator.save (a torch zip archive holding a dict "
                 f"with format={FORMAT!r}), or the name of shipped weights (`wearpose doctor` lists them)")


def _unreadable_problem(path: Path, exc: Exception) -> str:
    """One short sentence for a file torch cannot load (torch's own messages run to several
    lines of zip/pickle internals and advice that does not apply)."""

    size = path.stat().st_size
    if size == 0:
        return "empty file (0 bytes)"
    with open(path, "rb") as f:
        head = f.read(8)
    if not zipfile.is_zipfile(path):
        if head.startswith(b"PK\x03\x04"):
            return (f"truncated or damaged torch archive ({size:,} bytes; the zip archive has no end record: an "
                    "interrupted download, copy or save?)")
        if head[:1] == b"\x80":  # a pickle protocol marker: torch's legacy (pre-1.6) format or a plain pickle
            return "a pickle / legacy torch file, not a torch zip archive (re-save it with torch.save in torch >= 1.6)"
        return f"not a torch checkpoint (no zip archive; the file starts with {head!r})"
    if isinstance(exc, __import__("pickle").UnpicklingError):
        first = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else type(exc).__name__
        return f"holds Python objects wearpose does not load (weights_only: {first})"
    first = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else ""
    return f"damaged torch archive ({type(exc).__name__}{': ' + first if first else ''})"


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> Checkpoint:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Raises:
        InputFileError: missing file, not a torch file, or not a wearpose checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "no such checkpoint file", EXPECTED_FILE)
    try:
        d = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises several types for corrupt files
        raise InputFileError(path, _unreadable_problem(path, exc), EXPECTED_FILE) from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise InputFileError(path, f"not a wearpose checkpoint (a torch file holding a {type(d).__name__}"
                             f"{' with format=' + repr(d.get('format')) if isinstance(d, dict) else ''})", EXPECTED_FILE,
                             field="format")
    if d.get("version") != VERSION:
        raise InputFileError(path, f"checkpoint version {d.get('version')!r}", f"version {VERSION}", field="version")
    return Checkpoint(method=d["method"], config=d["config"], kit=d["kit"], sensors=list(d["sensors"]),
                      body_asset=d["body_asset"], weights=d["weights"], data_fingerprint=d.get("data_fingerprint", ""),
                      train_command=d.get("train_command", ""), meta=d.get("meta") or {}, train_state=d.get("train_state"))


class NetworkCheckpointing:
    """Mixin of an estimator whose trained state is one network ``self.model``: :meth:`to`,
    :meth:`checkpoint`, :meth:`save`, and for ``load``: :meth:`check_checkpoint` and :meth:`restore`.

    Uses the estimator's ``name``, ``config`` (``to_dict()``), ``kit_name``, ``sensor_names``,
    ``body_asset_id``, ``model``, ``body`` (moved by :meth:`to` with the network),
    ``data_fingerprint``, ``train_command`` and ``meta``.
    """

    def init_state(self, config: Any, body: Any, device: str | torch.device, kit: str | None = None) -> None:
        """The state every such estimator starts with (before it builds ``self.model``):
        ``config``, ``device``, ``body`` moved there (the embedded
        :class:`~wearpose.body.BodyModel` when None), ``kit_name`` (``kit`` or ``config.kit``)
        and its ``sensor_names``, ``body_asset_id`` of ``body``, ``fps`` = ``config.rate`` (Hz),
        and empty provenance (``data_fingerprint``, ``train_command``, ``meta``)."""
        from wearpose.body import BodyModel  # deferred like check_checkpoint's: the body stack loads on use - start-up: body adds ~57 ms to import this module
        from wearpose.sensors import get_kit  # start-up: sensors adds ~304 ms to import this module

        self.config = config
        self.device = torch.device(device)
        self.body = (body or BodyModel()).to(self.device)
        self.kit_name = kit or config.kit
        self.sensor_names = get_kit(self.kit_name).sensor_names
        self.body_asset_id = self.body.asset_id
        self.fps = float(config.rate)
        self.data_fingerprint, self.train_command = "", ""
        self.meta: dict[str, Any] = {}

    def to(self, device: str | torch.device) -> Any:
        """Move the network and the body model to ``device``; returns the estimator."""
        self.device = torch.device(device)
        self.model.to(self.device)
        self.body.to(self.device)
        return self

    def checkpoint(self, meta: dict[str, Any] | None = None, train_state: dict[str, Any] | None = None) -> Checkpoint:
        """The estimator as a :class:`Checkpoint` (weights on the CPU); ``meta`` is added to ``self.meta``."""
        return Checkpoint(method=self.name, config=self.config.to_dict(), kit=self.kit_name,
                          sensors=list(self.sensor_names), body_asset=self.body_asset_id,
                          weights={k: v.detach().cpu() for k, v in self.model.state_dict().items()},
                          data_fingerprint=self.data_fingerprint, train_command=self.train_command,
                          meta={**self.meta, **(meta or {})}, train_state=train_state)

    def save(self, path: str | Path) -> Path:
        return save_checkpoint(self.checkpoint(), path)

    @classmethod
    def check_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None, body: Any, path: str | Path) -> Any:
        """Check that ``ckpt`` is this method's, for ``kit`` (if given) and ``body``'s asset.

        Returns:
            ``body``, or when None the embedded :class:`~wearpose.body.BodyModel` (checked too).

        Raises:
            CheckpointMismatchError: naming the checkpoint's and the requested method / kit / asset.
        """
        ckpt.check(method=cls.name, kit=kit, body_asset=getattr(body, "asset_id", None), path=path)
        if body is None:
            from wearpose.body import BodyModel  # start-up: body adds ~57 ms to import this module

            body = BodyModel()
            ckpt.check(body_asset=body.asset_id, path=path)
        return body

    def warm_start(self, path: str | Path, same: Sequence[str] = ()) -> Any:
        """Start training from the weights of checkpoint ``path`` (fine-tuning): the same method,
        kit and body asset, the same value of every config field in ``same`` (BiRAE: ``rep``,
        which the tensor shapes do not always tell apart), every tensor of the same shape; the
        provenance stays this run's, with ``meta["init_from"]`` = ``path``. Returns the estimator.

        Raises:
            CheckpointMismatchError: another method / kit / asset / ``same`` field, or a weight
                whose shape or name differs (both sides named).
        """
        ckpt = load_checkpoint(path)
        ckpt.check(method=self.name, kit=self.kit_name, body_asset=self.body_asset_id, path=path)
        for k in same:
            if ckpt.config.get(k) != getattr(self.config, k):
                raise CheckpointMismatchError(f"{path}: --init-from checkpoint has {k} {ckpt.config.get(k)!r}, "
                                              f"this run trains {getattr(self.config, k)!r}")
        own = self.model.state_dict()
        missing, extra = sorted(set(own) - set(ckpt.weights)), sorted(set(ckpt.weights) - set(own))
        if missing or extra:
            raise CheckpointMismatchError(f"{path}: --init-from weights do not match this {self.name} network: "
                                          f"missing {missing[:5]}, unexpected {extra[:5]}; train with the same sizes "
                                          "as the checkpoint's config")
        for k, v in own.items():
            if tuple(ckpt.weights[k].shape) != tuple(v.shape):
                raise CheckpointMismatchError(f"{path}: --init-from weight {k!r} is {tuple(ckpt.weights[k].shape)}, "
                                              f"this network's is {tuple(v.shape)}; train with the same sizes as the "
                                              "checkpoint's config")
        self.model.load_state_dict(ckpt.weights)
        self.meta["init_from"] = str(path)
        return self

    def restore(self, ckpt: Checkpoint) -> Any:
        """Load ``ckpt``'s weights and provenance (data fingerprint, train command, meta); returns the estimator."""
        self.model.load_state_dict(ckpt.weights)
        self.data_fingerprint, self.train_command, self.meta = ckpt.data_fingerprint, ckpt.train_command, dict(ckpt.meta)
        return self
