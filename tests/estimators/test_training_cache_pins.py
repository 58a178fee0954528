"""Pinned training caches: the tiny splits EM-POSE, PIP and MI-Poser build from synthetic clips
keep their fingerprint, their tensors bit for bit and their first epoch's batch order.

The expected values were computed on main at d4fe04b, before the method-neutral helpers
(``num_batches``, ``kit_sites``) left ``estimators/empose``: a refactor of the data path (seeds,
clip store, data settings, batching) must not change the data a method trains on. A change that
means to (a new ``DATA_VERSION``, another noise model) updates the pins and says so in its commit.
Bit-identity holds for one torch build on one CPU family; the values are those of the project's
pinned environment (``/work/main/.venv``, torch on x86-64).
"""

from __future__ import annotations

import hashlib
import importlib
from pathlib import Path
from typing import Any

import pytest
import torch

from tests.estimators.test_empose import FakeStore
from wearpose.body import BodyModel
from wearpose.estimators.empose import EmposeConfig
from wearpose.estimators.miposer.config import MiposerConfig
from wearpose.estimators.pip import PipConfig


def tensor_digest(data: Any, names: tuple[str, ...]) -> str:
    """sha256 (hex, first 16) over the named tensors' dtype, shape and bytes, in that order."""
    h = hashlib.sha256()
    for n in names:
        t = getattr(data, n).contiguous()
        h.update(f"{n}:{t.dtype}:{tuple(t.shape)}".encode())
        h.update(t.numpy().tobytes())
    return h.hexdigest()[:16]


def batch_digest(batches: Any) -> str:
    """``"<count>:<sha256 hex, first 16>"`` of the first epoch's batches (every tensor, in order)."""
    h, n = hashlib.sha256(), 0
    for n, b in enumerate(batches, 1):
        for k in sorted(b):
            h.update(k.encode())
            h.update(b[k].contiguous().numpy().tobytes())
    return f"{n}:{h.hexdigest()[:16]}"


#: method -> (its config's tiny preset, the ``(length, stride)`` fields of its training windows,
#: its split's tensors, fingerprint, tensor digest, first-epoch batch digest).
PINS: dict[str, tuple[Any, tuple[str, str], tuple[str, ...], str, str, str]] = {
    "empose": (EmposeConfig.preset("tiny", 12), ("seq_len", "window_stride"),
               ("position", "orientation", "valid", "pose6", "joints", "clip", "betas", "off_R", "off_t", "starts",
                "lengths"),
               "a378120b9f2f97921bb9844e7e3c54a27f4a7dcad070e74d95739870ea91c749",
               "0d812a86ec886485", "3:5db782d0e9e9814d"),
    "pip": (PipConfig.preset("tiny"), ("seq_len", "window_stride"),
            ("x", "leaf", "joints", "rot6", "vel", "contact", "starts", "lengths"),
            "78d28920e48b3f735e97bb9eb7446ca486da0f596d5f75caf161bd73e034a2d9",
            "fd6f190af91eebf7", "7:facbcba7e6df555c"),
    "miposer": (MiposerConfig.preset("tiny"), ("window", "stride"),
                ("R", "p", "valid", "pose6", "in_clip", "clip", "starts", "lengths"),
                "ec1e341b44b380171f87baa0c1b8a4d3593f278c280ec1d7001ccb2d019373d0",
                "d8f3c6e1b9161996", "7:3b4c316ca2b582f2"),
}


def build(method: str, store: FakeStore, body: BodyModel, cache: Path) -> tuple[Any, Any]:
    """``method``'s tiny train split and its first epoch's batches (the seeding of
    :class:`wearpose.estimators.train.WindowTask`, epoch 1)."""
    cfg, (length, stride) = PINS[method][0], PINS[method][1]
    data = importlib.import_module(f"wearpose.estimators.{method}.data").build_split(
        "train", cfg, body, store=store, cache_root=cache)
    g = torch.Generator().manual_seed(cfg.seed * 100_003 + 1)
    return data, data.iter_batches(getattr(cfg, length), getattr(cfg, stride), cfg.batch_size, g)


@pytest.mark.parametrize("method", sorted(PINS))
def test_tiny_training_cache_is_pinned(method: str, tmp_path: Path, body: BodyModel) -> None:
    _, _, names, fp, tensors, batches = PINS[method]
    store = FakeStore(tmp_path, {"train": 3})
    data, first_epoch = build(method, store, body, tmp_path / "cache")
    got = (data.fingerprint, tensor_digest(data, names), batch_digest(first_epoch))
    assert got == (fp, tensors, batches)
    # The cached file gives the same split again (cache hit, nothing re-simulated).
    again, _ = build(method, store, body, tmp_path / "cache")
    assert (again.fingerprint, tensor_digest(again, names)) == got[:2]
